//! The program loop of a researcher's firmware (`program::user`) inside the stock program:
//! started and stopped from the console, driving through the same gate as the group maneuver,
//! finishing with the `ManeuverDone` notice, and stopped like any maneuver.

mod sim;

use lbc_link::Command;
use sim::*;
use ubc_app::program::console::{flags, Notice, Refusal, Reply, Request};
use ubc_app::program::LogEvent;

fn start(s: &mut Sim, args: &[i16]) -> Reply {
    s.request(&Request::ProgramStart(args.iter().copied().collect()))
}

#[test]
fn the_stock_firmware_has_no_program() {
    let mut s = Sim::new();
    s.bring_up();
    assert_eq!(
        start(&mut s, &[300, 500]),
        Reply::Refused(Refusal::NoProgram)
    );
}

#[test]
fn a_program_drives_and_finishes() {
    let mut s = Sim::new();
    s.user = Some(DriveTo::default());
    s.bring_up();
    assert_eq!(start(&mut s, &[300, 520]), Reply::ProgramStarted);
    // The loop runs from the next stream sample (30 Hz).
    s.run_ms(100);
    let st = s.status();
    assert!(st.flags & flags::MANEUVER != 0, "{st:?}");
    assert_eq!((st.maneuver_index, st.maneuver_len), (1, 2));
    let done = s.run_until(20_000, |s| s.notices.contains(&Notice::ManeuverDone));
    assert!(done, "no ManeuverDone: {:?}", s.log.0.last());
    let p = s.lbc.vehicle().pose();
    let (x, y) = (p.x_mm / 2.5, p.y_mm / 2.5);
    assert!((x - 300.0).hypot(y - 520.0) < 15.0, "at ({x}, {y})");
    let u = s.user.as_ref().unwrap();
    assert_eq!((u.starts, u.stops), (1, 0));
    assert!(u.steps > 30, "{} steps", u.steps);
    assert_eq!(s.logged(|e| *e == LogEvent::ProgramDone), 1);
    let st = s.status();
    assert_eq!(st.flags & flags::MANEUVER, 0);
    // Commands at the group's rate: about one a second while unchanged.
    let moves = s.lbc.stats().commands;
    assert!(moves < 200, "{moves} LBC commands");
}

#[test]
fn a_program_is_stopped_like_a_maneuver() {
    let mut s = Sim::new();
    s.user = Some(DriveTo::default());
    s.bring_up();
    assert_eq!(start(&mut s, &[300, 700]), Reply::ProgramStarted);
    s.run_ms(500);
    assert_eq!(s.request(&Request::ProgramStop), Reply::ProgramStopped);
    s.run_ms(300);
    assert_eq!(s.user.as_ref().unwrap().stops, 1);
    assert_eq!(s.logged(|e| *e == LogEvent::ProgramStopped), 1);
    let st = s.status();
    assert_eq!(st.flags & flags::MANEUVER, 0);
    // Started again, then a group maneuver takes over.
    assert_eq!(start(&mut s, &[300, 700]), Reply::ProgramStarted);
    s.run_ms(300);
    let goto = maneuvers::GoTo::params(300, 300, 200).unwrap();
    assert_eq!(s.request(&Request::GroupStart(goto)), Reply::GroupStarted);
    s.run_ms(300);
    let u = s.user.as_ref().unwrap();
    assert_eq!((u.starts, u.stops), (2, 2));
    // With the drive disabled it does not start.
    assert!(matches!(
        s.request(&Request::Lbc(Command::Drds)),
        Reply::Lbc(_)
    ));
    assert_eq!(
        start(&mut s, &[300, 700]),
        Reply::Refused(Refusal::DriveDisabled)
    );
}
