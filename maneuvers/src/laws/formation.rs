//! Leader-follower formation: line or wedge behind the leader.
//!
//! Each follower computes its slot in the leader's frame from the leader's latest broadcast
//! pose (advanced by its velocity over the broadcast's age) and drives towards it with the
//! leader's velocity as feed-forward plus a proportional correction. The leader itself drives
//! to the latest waypoint ([`LawInput::waypoint`]) at the cruise speed, and holds once within
//! its arrival radius (until the next waypoint). A follower without a fresh leader stops
//! ([`Phase::NoReference`]).

use crate::fixed::{from_mrad, fx, IVec2};
use crate::law::{error_units_fx, Guidance, Law, LawInput, Plan, Waypoint};
use crate::param::{Param, Values};
use crate::safety::travel;
use crate::{CarPose, Neighbour, Phase};

/// Formation geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Shape {
    /// Single file behind the leader: slot `k` is `(k + 1) * spacing` behind.
    #[default]
    Line = 0,
    /// V opening backwards at 45 degrees each side: slot `k` is in row `k / 2 + 1`, on the
    /// left for even `k`, `row * spacing` from the leader along its arm.
    Wedge = 1,
}

/// Gain of the position correction: 1.2/s, which is 3 mm/s per tracking unit of error.
const POSITION_GAIN_MM_S_PER_UNIT: i32 = 3;
/// Slot error below which a follower counts as in formation, tracking units (30 mm).
pub const TOLERANCE_UNITS: i32 = 12;
/// A leader slower than this (mm/s) counts as standing still.
const LEADER_STILL_MM_S: i16 = 15;
/// 1/sqrt(2) in Q14.
const FRAC_1_SQRT_2_Q14: i32 = 11_585;

const SHAPE: usize = 0;
const LEADER: usize = 1;
const SLOT: usize = 2;
const SPACING: usize = 3;
const SPEED: usize = 4;

/// The formation law.
#[derive(Debug, Clone, PartialEq)]
pub struct Formation {
    shape: Shape,
    leader: u8,
    slot: Option<u8>,
    spacing_units: u16,
    speed_mm_s: u16,
    /// Index of the last waypoint the leader reached.
    reached: Option<u16>,
    holding: bool,
}

impl Law for Formation {
    const NAME: &'static str = "formation";
    const SUMMARY: &'static str = "Leader-follower formation: the followers keep slots of a line or a wedge in the leader's frame; the leader drives through the waypoints.";
    const PARAMS: &'static [Param] = &[
        Param::choice("shape", &["line", "wedge"])
            .doc("line: single file behind the leader; wedge: a V opening backwards at 45 degrees (slot 0 front left, 1 front right, ...)"),
        Param::int("leader", "car ID", 1, 126).doc("the leader's car ID"),
        Param::int("slot", "", -1, 14)
            .default(-1)
            .doc("this car's slot; -1: its rank among the followers' IDs"),
        Param::int("spacing_units", "units", 1, 511)
            .default(100)
            .doc("distance between neighbouring slots; at least 100 keeps the slots out of the avoidance band"),
        Param::int("speed_mm_s", "mm/s", 0, 2047)
            .default(150)
            .doc("the leader's cruise speed towards its waypoint"),
    ];

    fn new(p: &Values) -> Self {
        Self::with(
            if p.get(SHAPE) == 1 {
                Shape::Wedge
            } else {
                Shape::Line
            },
            p.u8(LEADER),
            u8::try_from(p.get(SLOT)).ok(),
            p.u16(SPACING),
            p.u16(SPEED),
        )
    }

    fn step(&mut self, input: &LawInput<'_>) -> Plan {
        self.plan(
            input.id,
            &input.own,
            input.neighbours,
            input.waypoint,
            input.options.arrival_units,
        )
    }

    fn leads(&self, id: u8) -> bool {
        id == self.leader
    }
}

impl Formation {
    /// A formation behind car `leader`; `slot` `None` takes this car's rank among the
    /// followers' IDs; spacing in tracking units; leader cruise speed in mm/s.
    pub fn with(
        shape: Shape,
        leader: u8,
        slot: Option<u8>,
        spacing_units: u16,
        speed_mm_s: u16,
    ) -> Self {
        Self {
            shape,
            leader,
            slot,
            spacing_units,
            speed_mm_s,
            reached: None,
            holding: false,
        }
    }

    /// The group command for this formation (`slot` `None`: by rank).
    pub fn params(
        shape: Shape,
        leader: u8,
        slot: Option<u8>,
        spacing_units: u16,
        speed_mm_s: u16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[
                shape as i32,
                i32::from(leader),
                slot.map_or(-1, i32::from),
                i32::from(spacing_units),
                i32::from(speed_mm_s),
            ],
        )
    }

    /// Offset of slot `k` in the leader's frame (forward, left), 1/16 tracking unit.
    pub fn slot_offset(&self, k: u8) -> IVec2 {
        let s = fx(i32::from(self.spacing_units));
        match self.shape {
            Shape::Line => IVec2::new(-(i32::from(k) + 1) * s, 0),
            Shape::Wedge => {
                let row = i32::from(k / 2 + 1);
                let d = IVec2::new(row * s, 0).scale_q14(FRAC_1_SQRT_2_Q14).x;
                IVec2::new(-d, if k.is_multiple_of(2) { d } else { -d })
            }
        }
    }

    fn my_slot(&self, id: u8, fresh: &[Neighbour]) -> u8 {
        self.slot.unwrap_or_else(|| {
            let rank = fresh
                .iter()
                .filter(|n| n.id != self.leader && n.id < id)
                .count();
            u8::try_from(rank).unwrap_or(u8::MAX)
        })
    }

    fn plan_leader(&mut self, own: &CarPose, waypoint: Option<Waypoint>, arrival_units: u8) -> Plan {
        match waypoint.filter(|w| Some(w.index) != self.reached) {
            Some(w) => {
                let d2 = crate::imath::dist2(
                    i32::from(w.x) - i32::from(own.x),
                    i32::from(w.y) - i32::from(own.y),
                );
                // At most 65 535 (the root of a u32): fits.
                let e = crate::imath::isqrt(d2) as u16;
                if d2 <= u32::from(arrival_units).pow(2) {
                    self.reached = Some(w.index);
                    return Plan::hold(Phase::Hold, true, e);
                }
                Plan {
                    guidance: Guidance::Point {
                        x: w.x,
                        y: w.y,
                        speed_mm_s: self.speed_mm_s,
                    },
                    phase: Phase::Approach,
                    converged: false,
                    error_units: e,
                }
            }
            None => Plan::hold(Phase::Hold, true, 0),
        }
    }

    /// One period for car `id` at `own` with its fresh neighbours, the latest waypoint and
    /// the arrival radius.
    fn plan(
        &mut self,
        id: u8,
        own: &CarPose,
        fresh: &[Neighbour],
        waypoint: Option<Waypoint>,
        arrival_units: u8,
    ) -> Plan {
        if id == self.leader {
            return self.plan_leader(own, waypoint, arrival_units);
        }
        let Some(leader) = fresh.iter().find(|n| n.id == self.leader) else {
            self.holding = false;
            return Plan::hold(Phase::NoReference, false, 0);
        };
        // Unit vector of the leader's heading, Q14.
        let fwd = IVec2::from_angle(from_mrad(i32::from(leader.pose.heading_mrad)));
        // The leader's velocity, 1/16 mm/s, and where it is now (advanced over the age of
        // its broadcast), 1/16 unit.
        let v_leader = fwd.along(fx(i32::from(leader.pose.velocity_mm_s)));
        let leader_pos = IVec2::from_units(i32::from(leader.pose.x), i32::from(leader.pose.y))
            + travel(v_leader, leader.age_us);
        let off = self.slot_offset(self.my_slot(id, fresh));
        let target = leader_pos + fwd.along(off.x) + fwd.perp().along(off.y);
        let err = target - IVec2::from_units(i32::from(own.x), i32::from(own.y));
        let e = err.norm();
        let tolerance = fx(TOLERANCE_UNITS);
        let leader_still = leader.pose.velocity_mm_s.abs() < LEADER_STILL_MM_S;
        // Hold once in the slot behind a standing leader; move again when pushed out of it.
        if leader_still && (e < tolerance || (self.holding && 2 * e < 3 * tolerance)) {
            self.holding = true;
            return Plan::hold(Phase::Hold, true, error_units_fx(e));
        }
        self.holding = false;
        let v = v_leader + err.times(POSITION_GAIN_MM_S_PER_UNIT);
        let max = fx((2 * i32::from(self.speed_mm_s)).max(300));
        Plan {
            guidance: Guidance::velocity(v.clamp_norm(max)),
            phase: if e < tolerance {
                Phase::Track
            } else {
                Phase::Approach
            },
            converged: e < tolerance,
            error_units: error_units_fx(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leader_at(x: u16, y: u16, heading_mrad: u16, v: i16) -> Neighbour {
        Neighbour {
            id: 1,
            pose: CarPose {
                x,
                y,
                heading_mrad,
                velocity_mm_s: v,
            },
            age_us: 0,
        }
    }

    fn at(x: u16, y: u16) -> CarPose {
        CarPose {
            x,
            y,
            ..CarPose::default()
        }
    }

    #[test]
    fn slot_offsets() {
        let line = Formation::with(Shape::Line, 1, None, 50, 100);
        assert_eq!(line.slot_offset(0), IVec2::from_units(-50, 0));
        assert_eq!(line.slot_offset(2), IVec2::from_units(-150, 0));
        let wedge = Formation::with(Shape::Wedge, 1, None, 50, 100);
        // 50 / sqrt(2) = 35.355 units = 565.7 sixteenths.
        assert_eq!(wedge.slot_offset(0), IVec2::new(-566, 566));
        assert_eq!(wedge.slot_offset(1), IVec2::new(-566, -566));
        let o2 = wedge.slot_offset(2);
        assert!((o2.norm() - fx(100)).abs() <= 1 && o2.y > 0, "{o2:?}");
    }

    #[test]
    fn follower_targets_slot_in_leader_frame() {
        // Leader at (300, 400) heading +Y (1571 mrad), standing. Slot 0 of a line is 50 below.
        let mut f = Formation::with(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 1571, 0)];
        let p = f.plan(2, &at(300, 300), &n, None, 8);
        assert_eq!(p.phase, Phase::Approach);
        assert!(p.error_units.abs_diff(50) <= 1, "{p:?}");
        match p.guidance {
            Guidance::Velocity { vx_mm_s, vy_mm_s } => {
                assert!(vy_mm_s > 50 && vx_mm_s.abs() < 1, "{p:?}")
            }
            other => panic!("{other:?}"),
        }
        // In the slot: hold.
        let p = f.plan(2, &at(300, 350), &n, None, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        assert!(p.converged);
    }

    #[test]
    fn follower_matches_leader_velocity() {
        let mut f = Formation::with(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 0, 200)];
        let p = f.plan(2, &at(250, 400), &n, None, 8);
        assert_eq!(
            p.guidance,
            Guidance::Velocity {
                vx_mm_s: 200,
                vy_mm_s: 0
            }
        );
        assert_eq!(p.phase, Phase::Track);
    }

    #[test]
    fn follower_uses_the_age_of_the_broadcast() {
        // The leader drove on for 0.5 s at 200 mm/s since it was heard: 40 units further.
        let mut f = Formation::with(Shape::Line, 1, Some(0), 50, 100);
        let mut n = [leader_at(300, 400, 0, 200)];
        n[0].age_us = 500_000;
        let p = f.plan(2, &at(290, 400), &n, None, 8);
        assert_eq!(p.error_units, 0, "{p:?}");
    }

    #[test]
    fn slot_by_rank_among_followers() {
        let mut f = Formation::with(Shape::Line, 1, None, 40, 100);
        let mut n = [leader_at(300, 400, 1571, 0); 3];
        n[1].id = 3;
        n[2].id = 7;
        // Car 5 is behind car 3 only: slot 1, 80 units behind the leader.
        let p = f.plan(5, &at(300, 320), &n, None, 8);
        assert!(p.converged, "{p:?}");
        let p = f.plan(2, &at(300, 320), &n, None, 8);
        assert!(!p.converged);
    }

    #[test]
    fn missing_leader_stops() {
        let mut f = Formation::with(Shape::Wedge, 1, None, 40, 100);
        let p = f.plan(2, &at(300, 320), &[], None, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        assert_eq!(p.phase, Phase::NoReference);
    }

    #[test]
    fn leader_drives_to_waypoint_then_holds() {
        let mut f = Formation::with(Shape::Line, 1, None, 40, 150);
        assert_eq!(f.plan(1, &at(100, 100), &[], None, 8).guidance, Guidance::Hold);
        let w = Some(Waypoint {
            x: 100,
            y: 500,
            index: 0,
        });
        let p = f.plan(1, &at(100, 100), &[], w, 8);
        assert_eq!(
            p.guidance,
            Guidance::Point {
                x: 100,
                y: 500,
                speed_mm_s: 150
            }
        );
        let p = f.plan(1, &at(100, 495), &[], w, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        // Reached: it holds there even when pushed away, until the next waypoint.
        let p = f.plan(1, &at(100, 400), &[], w, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        let next = Waypoint {
            x: 100,
            y: 500,
            index: 1,
        };
        assert!(matches!(
            f.plan(1, &at(100, 400), &[], Some(next), 8).guidance,
            Guidance::Point { .. }
        ));
        // A wider arrival radius counts it as there sooner.
        let third = Waypoint { index: 2, ..next };
        assert_eq!(
            f.plan(1, &at(100, 480), &[], Some(third), 30).guidance,
            Guidance::Hold
        );
    }
}
