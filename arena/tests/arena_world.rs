//! One QEMU car in a world: the tracker feeds its LBC at 30 Hz, the console answers over the
//! radio, and a panic with the world alive still leaves no QEMU or socket behind.

#[path = "arena_common.rs"]
mod common;

use arena::world::{CarSpec, TrackingParams, World, WorldConfig, WorldError};
use lbc_emu::Pose;
use std::time::Duration;
use ubc_app::program::console::{Reply, Request};

fn one_car() -> WorldConfig {
    let elf = qemu_harness::firmware_elf().expect("firmware ELF");
    let mut cfg = WorldConfig::new(
        elf,
        vec![CarSpec {
            id: 9,
            start: Pose {
                x_mm: 500.0,
                y_mm: 700.0,
                heading_rad: 0.0,
            },
        }],
    );
    cfg.tracking = TrackingParams {
        drop: 0.5,
        ..TrackingParams::default()
    };
    cfg
}

#[test]
fn tracking_console_and_cleanup_after_a_panic() {
    if qemu_harness::skip_qemu_tests("tracking_console_and_cleanup_after_a_panic") {
        return;
    }
    let result = std::panic::catch_unwind(|| {
        let world = World::start(&one_car()).expect("world starts");
        let a = world.truth()[0];
        std::thread::sleep(Duration::from_secs(2));
        let b = world.truth()[0];
        let fixes = (b.fixes_delivered - a.fixes_delivered) + (b.fixes_dropped - a.fixes_dropped);
        assert!((55..=65).contains(&fixes), "{fixes} fixes in 2 s");
        assert!(b.fixes_dropped - a.fixes_dropped > 10, "drops not applied");
        assert!(b.connected);
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
        panic!("leaving with the world alive");
    });
    assert!(result.is_err());
    common::nothing_left_behind();
}

#[test]
fn bad_worlds_are_refused() {
    let mut cfg = one_car_without_firmware();
    assert!(matches!(
        World::start(&cfg),
        Err(WorldError::BadCar { id: 0 })
    ));
    cfg.cars.push(CarSpec {
        id: 127,
        start: Pose {
            x_mm: 0.0,
            y_mm: 0.0,
            heading_rad: 0.0,
        },
    });
    assert!(matches!(
        World::start(&cfg),
        Err(WorldError::BadCar { id: 127 })
    ));
}

fn one_car_without_firmware() -> WorldConfig {
    WorldConfig::new("/nonexistent", Vec::new())
}
