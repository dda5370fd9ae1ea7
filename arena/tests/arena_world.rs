//! One car in a world, on each engine: the tracker feeds its LBC at 30 Hz, the console answers
//! over the radio, and (QEMU) a panic with the world alive still leaves no QEMU or socket
//! behind. Bad worlds are refused with the reason.

#[path = "arena_common.rs"]
mod common;

use arena::world::{CarSpec, EngineKind, TrackingParams, World, WorldConfig, WorldError};
use lbc_emu::Pose;
use std::time::Duration;
use ubc_app::program::console::{Reply, Request};

fn one_car(engine: EngineKind) -> WorldConfig {
    let elf = engine.default_firmware().expect("firmware ELF");
    let mut cfg = WorldConfig::new(
        elf,
        vec![CarSpec::new(
            9,
            Pose {
                x_mm: 500.0,
                y_mm: 700.0,
                heading_rad: 0.0,
            },
        )],
    );
    cfg.engine = engine;
    cfg.tracking = TrackingParams {
        drop: 0.5,
        ..TrackingParams::default()
    };
    cfg
}

fn tracking_and_console(world: &mut World, exact: bool) {
    world.run_for(Duration::from_millis(500));
    let a = world.truth()[0].clone();
    world.run_for(Duration::from_secs(2));
    let b = world.truth()[0].clone();
    let fixes = (b.fixes_delivered - a.fixes_delivered) + (b.fixes_dropped - a.fixes_dropped);
    if exact {
        // Dropped fixes count at the tick, delivered ones 10 ms later: 60 +- 1 in 2 s.
        assert!(
            (59..=61).contains(&fixes),
            "{fixes} fixes in 2 s of world time"
        );
    } else {
        assert!((55..=65).contains(&fixes), "{fixes} fixes in 2 s");
    }
    assert!(b.fixes_dropped - a.fixes_dropped > 10, "drops not applied");
    assert!(b.connected && b.failure.is_none(), "{:?}", b.failure);
    let moved = (b.pose.x_mm - 500.0).hypot(b.pose.y_mm - 700.0);
    assert!(moved < 1.0, "an idle car moved {moved} mm");
    let status = world.request(9, &Request::Status, Duration::from_secs(8));
    match status {
        Ok(Reply::Status(s)) => assert_eq!(s.car_id, 9),
        other => panic!("status: {other:?}"),
    }
    assert!(matches!(
        world.request(0, &Request::Status, Duration::from_secs(1)),
        Err(WorldError::BadCar { id: 0 })
    ));
}

#[test]
fn virtual_time_tracking_and_console() {
    let mut world = World::start(&one_car(EngineKind::Iss)).expect("world starts");
    assert_eq!(world.engine_name(), "iss");
    tracking_and_console(&mut world, true);
    let load = world.core_load(0).expect("the model counts cycles");
    assert!(load.cycles > 14_000_000, "{load:?}");
    assert!(load.load() > 0.0 && load.load() < 0.5, "{load:?}");
    let log = world.firmware_log(9).unwrap();
    assert!(log.iter().any(|l| l.contains("board=softcore")), "{log:?}");
}

#[test]
fn qemu_tracking_console_and_cleanup_after_a_panic() {
    if qemu_harness::skip_qemu_tests("qemu_tracking_console_and_cleanup_after_a_panic") {
        return;
    }
    let result = std::panic::catch_unwind(|| {
        let mut world = World::start(&one_car(EngineKind::Qemu)).expect("world starts");
        assert!(world.paced());
        tracking_and_console(&mut world, false);
        panic!("leaving with the world alive");
    });
    assert!(result.is_err());
    common::nothing_left_behind();
}

#[test]
fn bad_worlds_are_refused() {
    let mut cfg = WorldConfig::new("/nonexistent", Vec::new());
    assert!(matches!(
        World::start(&cfg),
        Err(WorldError::BadCar { id: 0 })
    ));
    cfg.cars.push(CarSpec::new(127, Pose::default()));
    assert!(matches!(
        World::start(&cfg),
        Err(WorldError::BadCar { id: 127 })
    ));
    cfg.cars[0].id = 3;
    let err = World::start(&cfg).unwrap_err();
    assert!(
        matches!(err, WorldError::Iss(_)) && err.to_string().contains("/nonexistent"),
        "{err}"
    );
    cfg.quantum = Duration::ZERO;
    assert!(matches!(World::start(&cfg), Err(WorldError::BadQuantum(_))));
}

#[test]
fn radio_channels_are_apart_and_each_has_its_ground_station() {
    use arena::world::TapConfig;
    use radio_mac::{Deframer, Frame};
    let elf = EngineKind::Iss.default_firmware().expect("firmware ELF");
    // Cars 1 and 2 on channel 0, cars 3 and 4 on channel 5.
    let cars: Vec<CarSpec> = (1..=4u8)
        .map(|id| {
            let mut c = CarSpec::new(
                id,
                Pose {
                    x_mm: 300.0 * f64::from(id),
                    y_mm: 500.0,
                    heading_rad: 0.0,
                },
            );
            c.radio_channel = if id <= 2 { 0 } else { 5 };
            c
        })
        .collect();
    let mut cfg = WorldConfig::new(elf, cars);
    let mut world = World::start(&cfg).expect("world starts");
    assert_eq!(world.radio_channels(), [0, 5]);
    let names: Vec<&str> = world
        .node_counters()
        .iter()
        .map(|n| n.name.as_str())
        .collect();
    assert_eq!(names, ["ground", "car1", "car2", "car3", "car4", "ground5"]);
    world.run_for(Duration::from_secs(3));
    world.start_tap(TapConfig::default());
    world.run_for(Duration::from_secs(2));
    // The console reaches the cars of both channels through their own ground stations.
    for id in 1..=4 {
        match world.request(id, &Request::Status, Duration::from_secs(8)) {
            Ok(Reply::Status(s)) => assert_eq!(s.car_id, id),
            other => panic!("car {id}: {other:?}"),
        }
    }
    let tap = world.take_tap();
    let heard_from = |node: usize| -> Vec<u8> {
        let mut d = Deframer::new();
        let mut src: Vec<u8> = tap.radio[node]
            .received
            .iter()
            .filter_map(|&(_, b)| match d.push(b) {
                Some(Ok(Frame::State { src, .. })) => Some(src.get()),
                _ => None,
            })
            .collect();
        src.sort_unstable();
        src.dedup();
        src
    };
    // Each car hears only its channel's other car; each ground station only its channel.
    assert_eq!(heard_from(1), [2]);
    assert_eq!(heard_from(2), [1]);
    assert_eq!(heard_from(3), [4]);
    assert_eq!(heard_from(4), [3]);
    assert_eq!(heard_from(0), [1, 2]);
    assert_eq!(heard_from(5), [3, 4]);
    let truth = world.truth();
    assert!(truth.iter().all(|t| t.states_heard > 30), "{truth:?}");
    // A channel above the highest is refused.
    cfg.cars[0].radio_channel = 16;
    assert!(matches!(
        World::start(&cfg),
        Err(WorldError::BadChannel { id: 1, channel: 16 })
    ));
}
