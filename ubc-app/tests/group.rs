//! Properties of the group maneuver's command gate over random pose sequences: commands to the
//! LBC are rate-limited (except a change to STOP), unchanged commands are refreshed, and every
//! command is within the LBC's ranges.

use maneuvers::{
    CarPose, Circle, Command as Motion, Formation, GoTo, ManeuverParams, Rendezvous, Shape,
};
use proptest::prelude::*;
use radio_mac::NeighbourTable;
use ubc_app::program::group::{lbc_command, Group, MIN_INTERVAL_US, REFRESH_US};

const NO_RADIO: Option<&NeighbourTable<4>> = None;

fn any_params() -> impl Strategy<Value = ManeuverParams> {
    prop_oneof![
        (0u16..640, 0u16..960, 1u16..800)
            .prop_map(|(x, y, speed_mm_s)| GoTo::params(x, y, speed_mm_s).unwrap()),
        (50u16..550, 50u16..750, 60u16..300, -400i16..400).prop_map(
            |(cx, cy, radius_units, speed_mm_s)| {
                Circle::params(cx, cy, radius_units, speed_mm_s).unwrap()
            }
        ),
        (1u16..200, 1u16..600).prop_map(|(radius_units, speed_mm_s)| {
            Rendezvous::params(radius_units, speed_mm_s).unwrap()
        }),
    ]
}

fn any_start() -> impl Strategy<Value = (ManeuverParams, Option<(u16, u16)>)> {
    prop_oneof![
        any_params().prop_map(|p| (p, None)),
        (any::<bool>(), 0u16..640, 0u16..960, 1u16..600).prop_map(|(w, x, y, speed_mm_s)| {
            (
                Formation::params(
                    if w { Shape::Wedge } else { Shape::Line },
                    1,
                    None,
                    100,
                    speed_mm_s,
                )
                .unwrap(),
                Some((x, y)),
            )
        }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn commands_are_rate_limited_refreshed_and_in_range(
        start in any_start(),
        samples in proptest::collection::vec(
            (20_000u64..50_000, 0u16..=640, 0u16..=960, 0u16..=6283, -600i16..600, any::<bool>()),
            10..150,
        ),
    ) {
        let (params, waypoint) = start;
        let mut g = Group::default();
        g.start(params);
        if let Some((x, y)) = waypoint {
            prop_assert!(g.set_waypoint(x, y));
        }
        let mut now = 0u64;
        let mut last: Option<(Motion, u64)> = None;
        for (dt, x, y, heading_mrad, velocity_mm_s, may_send) in samples {
            now += dt;
            let own = CarPose { x, y, heading_mrad, velocity_mm_s };
            let sent = g.step(now, 1, own, NO_RADIO, may_send);
            if !may_send {
                prop_assert_eq!(sent, None);
                continue;
            }
            match (sent, last) {
                (Some(m), Some((prev, at))) => {
                    let gap = now - at;
                    let to_stop = m == Motion::Stop && prev != Motion::Stop;
                    prop_assert!(
                        to_stop || gap >= MIN_INTERVAL_US,
                        "{:?} {} us after {:?}", m, gap, prev
                    );
                }
                (None, Some((_, at))) => {
                    // Nothing new: the last command is younger than the refresh period.
                    prop_assert!(now - at < REFRESH_US, "no refresh after {} us", now - at);
                }
                _ => {}
            }
            if let Some(m) = sent {
                last = Some((m, now));
                if let Motion::MoveSv { steering_mrad, velocity_mm_s } = m {
                    prop_assert!(steering_mrad.abs() <= 523 && velocity_mm_s.abs() <= 2000);
                    prop_assert_ne!(lbc_command(m), lbc_link::Command::Stop);
                }
            }
        }
    }
}
