//! No car drives blind: when a car's firmware dies (killed, trapped, exited, stuck), the world
//! stops its vehicle within one tracking period, as a lab's emergency stop would, and the run
//! says which car failed, when and why. Without the stop the car would drive on with the last
//! command its LBC was given.

#[path = "arena_common.rs"]
mod common;

use arena::experiment::{self, Experiment};
use arena::world::{CarSpec, EngineKind, World, WorldConfig};
use lbc_emu::Pose;
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use ubc_app::program::console::{flags, Reply, Request};

/// One car driving up the arena at 200 mm/s when its firmware is killed; how far it goes in
/// the 3 s after, and how long until it stands.
fn drive_and_kill(engine: EngineKind, stop: bool) -> (f64, Option<Duration>, World) {
    let mut cfg = WorldConfig::new(
        engine.default_firmware().expect("firmware ELF"),
        vec![CarSpec::new(
            5,
            Pose {
                x_mm: 750.0,
                y_mm: 200.0,
                heading_rad: std::f64::consts::FRAC_PI_2,
            },
        )],
    );
    cfg.engine = engine;
    cfg.stop_failed_cars = stop;
    let mut w = World::start(&cfg).expect("world starts");
    let need = flags::DRIVE_ENABLED | flags::POSE_VALID;
    let deadline = w.now() + Duration::from_secs(30);
    loop {
        if let Ok(Reply::Status(s)) = w.request(5, &Request::Status, Duration::from_secs(5)) {
            if s.phase == 2 && s.flags & need == need {
                break;
            }
        }
        assert!(w.now() < deadline, "the car did not come up");
        w.run_for(Duration::from_millis(200));
    }
    let goto = maneuvers::GoTo::params(300, 760, 200).unwrap();
    assert_eq!(
        w.request(5, &Request::GroupStart(goto), Duration::from_secs(5))
            .unwrap(),
        Reply::GroupStarted
    );
    w.run_for(Duration::from_millis(1500));
    assert!(w.truth()[0].v_mm_s > 150.0, "{:?}", w.truth()[0]);
    let at_kill = w.truth()[0].pose;
    let killed = w.now();
    w.kill_car(5, "killed by the test");
    let mut stood = None;
    while w.now() - killed < Duration::from_secs(3) {
        w.run_for(Duration::from_millis(10));
        if stood.is_none() && w.truth()[0].v_mm_s.abs() < 1.0 {
            stood = Some(w.now() - killed);
        }
    }
    let p = w.truth()[0].pose;
    (
        (p.x_mm - at_kill.x_mm).hypot(p.y_mm - at_kill.y_mm),
        stood,
        w,
    )
}

#[test]
fn a_killed_car_is_stopped_and_reported() {
    let (moved, stood, mut w) = drive_and_kill(EngineKind::Iss, true);
    let t = w.truth()[0].clone();
    let f = t.failure.expect("the failure is reported");
    assert!(f.kind.to_string().contains("killed by the test"), "{f:?}");
    let events = w.take_events();
    let stopped = events
        .iter()
        .find(|e| e.what == "vehicle-stopped")
        .expect("the world stopped the vehicle");
    let failed = events
        .iter()
        .find(|e| e.what.starts_with("car-failed"))
        .expect("the failure is an event");
    // Within one tracking period (33 ms) of the firmware dying.
    assert!(
        stopped.at - failed.at <= Duration::from_millis(34),
        "{events:?}"
    );
    eprintln!("after the kill the car rolled {moved:.0} mm and stood after {stood:?}");
    assert!(
        moved < 150.0,
        "the car rolled {moved:.0} mm after its firmware died"
    );
    assert!(stood.is_some_and(|s| s < Duration::from_secs(2)));
}

#[test]
fn without_the_stop_a_dead_car_drives_on() {
    // What the emergency stop prevents: the LBC keeps its last command.
    let (moved, _, _) = drive_and_kill(EngineKind::Iss, false);
    assert!(moved > 400.0, "the unstopped car moved only {moved:.0} mm");
}

#[test]
fn qemu_car_killed_with_sigkill_is_stopped() {
    if qemu_harness::skip_qemu_tests("qemu_car_killed_with_sigkill_is_stopped") {
        return;
    }
    let (moved, _, w) = drive_and_kill(EngineKind::Qemu, true);
    let f = w.truth()[0]
        .failure
        .clone()
        .expect("the failure is reported");
    assert!(f.kind.to_string().contains("QEMU"), "{f:?}");
    assert!(
        moved < 150.0,
        "the car rolled {moved:.0} mm after QEMU died"
    );
    drop(w);
    common::nothing_left_behind();
}

const CRASH: &str = r#"
name = "crash"
duration_s = 8
[[cars]]
id = 1
x = 150
y = 200
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 200
heading_mrad = 1571
[maneuver]
kind = "goto"
speed_mm_s = 200
[[maneuver.cars]]
id = 1
points = [[150, 700]]
[[maneuver.cars]]
id = 2
points = [[450, 700]]
[[faults.crash]]
car = 2
at_s = 1.5
"#;

fn run(text: &str, tag: &str) -> (experiment::Summary, Vec<String>) {
    let exp = Experiment::parse(text).expect("parses");
    let elf = exp.engine.default_firmware().expect("firmware ELF");
    let out = std::env::temp_dir().join(format!("arena-crash-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let mut lines = Vec::new();
    let s = experiment::run(
        &exp,
        &elf,
        &out,
        &mut |p| lines.push(p.to_string()),
        &AtomicBool::new(false),
    )
    .expect("runs");
    let events = std::fs::read_to_string(out.join("events.jsonl")).unwrap();
    assert!(events.contains("car-failed"), "{events}");
    let _ = std::fs::remove_dir_all(&out);
    (s, lines)
}

#[test]
fn a_crash_in_an_experiment_is_in_the_summary() {
    let (s, lines) = run(CRASH, "stop");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("car2") && l.contains("FAILED")),
        "{lines:?}"
    );
    assert_eq!(s.failed_cars.len(), 1, "{s:?}");
    let f = &s.failed_cars[0];
    assert_eq!(f.car, 2);
    assert!((1.5..1.6).contains(&f.t_s), "{f:?}");
    assert!(f.reason.contains("crash injected"), "{f:?}");
    assert!(!s.aborted);
    let car2 = s.cars.iter().find(|c| c.id == 2).unwrap();
    assert!(car2.failed.is_some() && !car2.arrived);
    let car1 = s.cars.iter().find(|c| c.id == 1).unwrap();
    assert!(car1.arrived, "the other car carries on: {car1:?}");
    let aborting = CRASH.replace(
        "duration_s = 8",
        "duration_s = 8\non_car_failure = \"abort\"",
    );
    let (s, _) = run(&aborting, "abort");
    assert!(s.aborted && s.duration_s < 2.0, "{s:?}");
}
