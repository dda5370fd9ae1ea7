//! Acceptance: killing the emulated LBC and starting a fresh one mid-run is recovered from
//! without user action: the firmware notices the silent stream, stops, brings the new LBC up
//! again and tells the ground station.

use std::time::{Duration, Instant};

use lbc_link::{Command, Position};
use ubc_app::program::console::{flags, LbcOutcome, Notice, Reply, Request};

mod program_common;

const DEADLINE: Duration = Duration::from_secs(90);

#[test]
fn killed_and_restarted_lbc_is_brought_up_again() {
    let Some(mut rig) = program_common::boot("killed_and_restarted_lbc_is_brought_up_again") else {
        return;
    };
    let start = Instant::now();
    let first = rig.ground.wait_status(Duration::from_secs(20), |s| {
        s.phase == 2 && s.flags & flags::STREAMING != 0
    });
    assert_eq!(first.bringups, 1);

    // Kill the emulator, leave the wire dead for a second, then start a new one.
    if let Some(old) = rig.lbc.take() {
        old.kill();
    }
    rig.ground.run_for(Duration::from_secs(1));
    let down = rig.ground.status();
    assert_ne!(down.phase, 2, "still running with no LBC: {down:?}");
    rig.restart_lbc();

    let s = rig.ground.wait_status(Duration::from_secs(20), |s| {
        s.phase == 2 && s.flags & flags::STREAMING != 0 && s.bringups >= 2
    });
    assert!(s.lbc_failures >= 1, "{s:?}");
    assert_ne!(s.flags & flags::DRIVE_ENABLED, 0);
    let lbc = rig.lbc.as_ref().expect("new lbc");
    let cmds = lbc.commands();
    for c in [Command::Init, Command::ReadId, Command::Sten, Command::Dren] {
        assert!(cmds.contains(&c), "{c:?} not sent to the new LBC: {cmds:?}");
    }
    rig.ground.run_for(Duration::from_millis(500));
    assert!(
        rig.ground.notices.contains(&Notice::LbcLost),
        "{:?}",
        rig.ground.notices
    );
    assert!(
        rig.ground.notices.contains(&Notice::LbcRecovered),
        "{:?}",
        rig.ground.notices
    );

    // The new LBC takes motion commands.
    match rig.ground.request(
        &Request::Lbc(Command::MoveXy(Position::new(310, 440).unwrap())),
        Duration::from_secs(10),
    ) {
        Reply::Lbc(LbcOutcome::Answer(_)) => {}
        other => panic!("{other:?}"),
    }
    assert!(
        rig.qemu.try_wait().expect("qemu state").is_none(),
        "firmware died"
    );
    assert!(start.elapsed() < DEADLINE, "took {:?}", start.elapsed());
    rig.shutdown();
}
