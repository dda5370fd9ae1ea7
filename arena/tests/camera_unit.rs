//! The vision unit against the software path, on the firmware: the same scene (three cars
//! standing still, the viewer seeing the other two) is run twice on the soft core's model, once
//! with each car's SoC having a vision unit (the firmware builds its blobs from the unit's runs)
//! and once without (the firmware runs the pixel pipeline over the frame grabber). The camera
//! renders the same frames at the same times in both runs, so every blob the firmware reports
//! for a frame must be the same in both, field for field; and the unit must have taken most of
//! the work off the processor.

use arena::camera_feed::FeedConfig;
use arena::world::{CarSpec, EngineKind, World, WorldConfig};
use lbc_emu::Pose;
use std::collections::BTreeMap;
use std::time::Duration;
use ubc_app::program::camera::BlobReport;
use ubc_app::program::console::{flags, Reply, Request};
use vision::colour::marker_class_for_car;

const VIEWER: u8 = 2;
const REQUEST_TIMEOUT: Duration = Duration::from_secs(8);
/// World time over which the viewer's reports are collected.
const WINDOW: Duration = Duration::from_secs(3);
/// 10 frames per second: the software path keeps up with every frame too.
const FPS: f64 = 10.0;

fn pose(x_units: f64, y_units: f64, heading_rad: f64) -> Pose {
    Pose {
        x_mm: x_units * 2.5,
        y_mm: y_units * 2.5,
        heading_rad,
    }
}

fn world(vision_unit: bool) -> World {
    let elf = EngineKind::Iss.default_firmware().expect("firmware ELF");
    let up = std::f64::consts::FRAC_PI_2;
    let mut cfg = WorldConfig::new(
        elf,
        vec![
            // straight ahead of the viewer, 550 mm
            CarSpec::new(1, pose(300.0, 330.0, up)),
            CarSpec::new(VIEWER, pose(300.0, 110.0, up)),
            // ahead and to the right, turned across the view
            CarSpec::new(3, pose(390.0, 290.0, 0.4)),
        ],
    );
    cfg.camera = Some(FeedConfig {
        fps: FPS,
        vision_unit,
        ..FeedConfig::default()
    });
    World::start(&cfg).expect("world starts")
}

fn wait_ready(world: &mut World, id: u8, deadline: Duration) {
    loop {
        if let Ok(Reply::Status(s)) = world.request(id, &Request::Status, REQUEST_TIMEOUT) {
            if s.phase == 2 && s.flags & flags::POSE_VALID != 0 {
                return;
            }
        }
        assert!(world.now() < deadline, "car {id} not ready in time");
        world.run_for(Duration::from_millis(200));
    }
}

/// Every blob the viewer reported over [`WINDOW`], by (frame sequence, blob index), and the
/// viewer's awake cycles per frame it processed in that window.
fn reports(vision_unit: bool) -> (BTreeMap<(u32, u8), BlobReport>, u64) {
    let mut w = world(vision_unit);
    let deadline = w.now() + Duration::from_secs(60);
    for id in [1, VIEWER, 3] {
        wait_ready(&mut w, id, deadline);
    }
    let camera = |w: &mut World, blob: u8| match w.request(
        VIEWER,
        &Request::Camera { blob },
        REQUEST_TIMEOUT,
    ) {
        Ok(Reply::Camera(r)) => r,
        other => panic!("{other:?}"),
    };
    let k = w.ids().iter().position(|&i| i == VIEWER).unwrap();
    let load0 = w.core_load(k).expect("cycle counts");
    let frames0 = camera(&mut w, 0).frames;
    let t0 = w.now();
    let mut seen = BTreeMap::new();
    while w.now() - t0 < WINDOW {
        let first = camera(&mut w, 0);
        for i in 0..first.blobs {
            let r = if i == 0 { first } else { camera(&mut w, i) };
            if let Some((index, b)) = r.blob {
                seen.insert((r.sequence, index), b);
            }
        }
        w.run_for(Duration::from_millis(40));
    }
    let load = w.core_load(k).expect("cycle counts");
    let frames = camera(&mut w, 0).frames.wrapping_sub(frames0);
    assert!(frames > 0, "the viewer processed no frame");
    let per_frame = (load.awake_cycles - load0.awake_cycles) / u64::from(frames);
    (seen, per_frame)
}

#[test]
fn firmware_blobs_from_the_unit_equal_the_software_path() {
    let (unit, unit_cycles) = reports(true);
    let (software, software_cycles) = reports(false);
    let mut common = 0;
    let mut indices = std::collections::BTreeSet::new();
    for (key, b) in &unit {
        if let Some(s) = software.get(key) {
            assert_eq!(b, s, "frame {} blob {}", key.0, key.1);
            common += 1;
            indices.insert(key.1);
        }
    }
    eprintln!(
        "{} blob reports with the unit, {} without, {common} of the same frames; awake cycles per frame {unit_cycles} with the unit, {software_cycles} without",
        unit.len(),
        software.len()
    );
    assert!(common >= 10, "too few frames in common: {common}");
    assert_eq!(indices.len(), 2, "both other cars seen: {indices:?}");
    let classes: std::collections::BTreeSet<u8> = unit.values().map(|b| b.class).collect();
    let want: std::collections::BTreeSet<u8> =
        [marker_class_for_car(1), marker_class_for_car(3)].into();
    assert_eq!(classes, want);
    // The software path classifies 640x480 pixels per frame (about 10^6 cycles); with the unit
    // the firmware only walks the runs.
    assert!(
        unit_cycles * 5 < software_cycles,
        "{unit_cycles} against {software_cycles}"
    );
}
