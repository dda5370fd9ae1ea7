//! Acceptance: a group maneuver on one car, the firmware in QEMU against the emulated LBC. A
//! go-to started with the console's GroupStart is driven by the maneuver controller with
//! MOVE_SV commands at a bounded rate, its status shows in the status reply, it arrives, and
//! ManeuverStop ends it.

use std::time::{Duration, Instant};

use lbc_link::Command;
use ubc_app::program::console::{flags, Refusal, Reply, Request};

mod program_common;

/// Bound on the whole test.
const DEADLINE: Duration = Duration::from_secs(120);
/// The go-to target, tracking units; the emulated car starts at (300, 400) facing +Y.
const TARGET: (u16, u16) = (400, 560);
/// The go-to law's ID in the registration list.
const KIND_GOTO: u8 = 4;
/// `maneuvers::Phase::Hold`.
const PHASE_HOLD: u8 = 3;

fn moves(cmds: &[Command]) -> usize {
    cmds.iter()
        .filter(|c| matches!(c, Command::MoveSv(_) | Command::MoveXy(_)))
        .count()
}

#[test]
fn group_goto_arrives_and_stops() {
    let Some(mut rig) = program_common::boot("group_goto_arrives_and_stops") else {
        return;
    };
    let start = Instant::now();
    let g = &mut rig.ground;
    g.wait_status(Duration::from_secs(20), |s| {
        s.phase == 2 && s.flags & flags::STREAMING != 0
    });

    // A waypoint without a formation is refused.
    assert_eq!(
        g.request(
            &Request::GroupWaypoint { x: 300, y: 300 },
            Duration::from_secs(10)
        ),
        Reply::Refused(Refusal::NoGroup)
    );

    let lbc = rig.lbc.as_ref().expect("lbc running");
    let before = moves(&lbc.commands());
    let params = maneuvers::GoTo::params(TARGET.0, TARGET.1, 200).unwrap();
    let t0 = Instant::now();
    assert_eq!(
        g.request(&Request::GroupStart(params), Duration::from_secs(10)),
        Reply::GroupStarted
    );
    let moving = g.wait_status(Duration::from_secs(10), |s| {
        s.group_kind == KIND_GOTO && s.flags & flags::MANEUVER != 0 && s.velocity_mm_s > 50
    });
    eprintln!("moving: {moving:?}");

    // It arrives and holds there.
    let s = g.wait_status(Duration::from_secs(30), |s| {
        s.group_converged && s.group_phase == PHASE_HOLD
    });
    let elapsed = t0.elapsed();
    eprintln!("arrived: {s:?} after {elapsed:?}");
    let d = (f64::from(s.x) - f64::from(TARGET.0)).hypot(f64::from(s.y) - f64::from(TARGET.1));
    assert!(d <= 15.0, "{d} units from the target: {s:?}");
    assert!(s.group_error_units <= 24, "{s:?}");

    // The controller's commands reached the LBC, but not one per 30 Hz sample.
    let sent = moves(&lbc.commands()) - before;
    let per_s = sent as f64 / elapsed.as_secs_f64();
    eprintln!("{sent} motion commands in {elapsed:?} ({per_s:.1}/s)");
    assert!(sent >= 2, "{sent} motion commands");
    assert!(per_s <= 12.0, "{per_s:.1} motion commands per second");

    // The car stands still at the goal.
    let s = g.wait_status(Duration::from_secs(5), |s| s.velocity_mm_s.abs() < 10);
    assert_eq!(s.group_kind, KIND_GOTO);

    // ManeuverStop ends the group maneuver.
    let stops = |cmds: Vec<Command>| cmds.iter().filter(|c| **c == Command::Stop).count();
    let stops_before = stops(lbc.commands());
    assert_eq!(
        g.request(&Request::ManeuverStop, Duration::from_secs(10)),
        Reply::ManeuverStopped
    );
    let s = g.status();
    assert_eq!(s.group_kind, 0, "{s:?}");
    assert_eq!(s.flags & flags::MANEUVER, 0, "{s:?}");
    g.run_for(Duration::from_millis(300));
    assert!(stops(lbc.commands()) > stops_before, "STOP reached the LBC");
    assert!(
        rig.qemu.try_wait().expect("qemu state").is_none(),
        "firmware died"
    );
    assert!(start.elapsed() < DEADLINE, "took {:?}", start.elapsed());
    rig.shutdown();
}
