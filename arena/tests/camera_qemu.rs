//! The camera on QEMU: the arena renders each car's view into the frame-grabber window in the
//! car's RAM file (a shared file QEMU maps); `almc camera snapshot` finds and reads that file,
//! and the firmware's camera report matches what the host sees in it. The host also plays the
//! vision unit QEMU's board lacks: the firmware finds the run window in its RAM, loads the class
//! table and enables it, and builds its blobs from the runs the host publishes there. Without
//! the unit (`vision_unit = false`) there is no run window and the firmware uses the pixels.

use arena::camera_feed::FeedConfig;
use arena::world::{CarSpec, EngineKind, World, WorldConfig};
use lbc_emu::Pose;
use std::time::Duration;
use ubc_app::program::console::{flags, Reply, Request};
use vision::colour::{marker_class_for_car, MARKER_CLASSES};

const LEADER: u8 = 1;
const FOLLOWER: u8 = 2;
const REQUEST_TIMEOUT: Duration = Duration::from_secs(8);

fn pose(x_units: f64, y_units: f64) -> Pose {
    Pose {
        x_mm: x_units * 2.5,
        y_mm: y_units * 2.5,
        heading_rad: std::f64::consts::FRAC_PI_2,
    }
}

fn wait_ready(world: &mut World, id: u8, deadline: Duration) {
    let need = flags::DRIVE_ENABLED | flags::POSE_VALID;
    loop {
        if let Ok(Reply::Status(s)) = world.request(id, &Request::Status, REQUEST_TIMEOUT) {
            if s.phase == 2 && s.flags & need == need {
                return;
            }
        }
        assert!(world.now() < deadline, "car {id} not ready in time");
        world.run_for(Duration::from_millis(200));
    }
}

fn two_cars(engine: EngineKind, vision_unit: bool) -> World {
    let elf = engine.default_firmware().expect("firmware ELF");
    let mut cfg = WorldConfig::new(
        elf,
        vec![
            CarSpec::new(LEADER, pose(300.0, 330.0)),
            CarSpec::new(FOLLOWER, pose(300.0, 110.0)),
        ],
    );
    cfg.engine = engine;
    cfg.camera = Some(FeedConfig {
        vision_unit,
        ..FeedConfig::default()
    });
    World::start(&cfg).expect("world starts")
}

/// The follower's first camera report with a blob, once both cars are up.
fn first_report(world: &mut World) -> ubc_app::program::console::CameraReport {
    let deadline = world.now() + Duration::from_secs(60);
    wait_ready(world, LEADER, deadline);
    wait_ready(world, FOLLOWER, deadline);
    loop {
        match world.request(FOLLOWER, &Request::Camera { blob: 0 }, REQUEST_TIMEOUT) {
            Ok(Reply::Camera(r)) if r.sequence > 0 && r.blob.is_some() => return r,
            other => {
                assert!(world.now() < deadline, "no camera report: {other:?}");
                world.run_for(Duration::from_millis(200));
            }
        }
    }
}

#[test]
fn qemu_window_is_what_the_snapshot_tool_reads() {
    if qemu_harness::skip_qemu_tests("qemu_window_is_what_the_snapshot_tool_reads") {
        return;
    }
    let mut world = two_cars(EngineKind::Qemu, true);
    let ram = world
        .run_dir()
        .join(arena::camera_feed::ram_file_name(FOLLOWER));
    assert!(ram.is_file());
    // `almc camera snapshot` finds it without being told the run directory.
    assert_eq!(
        arena::camera_feed::find_car_ram(FOLLOWER, None).expect("found"),
        ram
    );
    let report = first_report(&mut world);
    let class = marker_class_for_car(LEADER);
    assert_eq!(report.blob.map(|(_, b)| b.class), Some(class), "{report:?}");
    let frame = arena::camera_feed::read_window_frame(&ram).expect("frame in the RAM file");
    assert!(frame.ticket.sequence >= 1);
    let host = frame.detect().unwrap();
    assert_eq!(host.blobs().first().map(|b| b.class), Some(class));
    // the firmware took the vision unit's path: it loaded the table and enabled the unit, and
    // the host has been publishing runs; the newest runs give the host's blobs of that frame
    let file = qemu_harness::SharedRam::open_read_only(&ram).unwrap();
    let mut win = vec![0u8; vision::run_window::WINDOW_LEN];
    file.read_at(arena::camera_feed::RUN_WINDOW_OFFSET, &mut win)
        .unwrap();
    let ctrl = u32::from_le_bytes(win[64..68].try_into().unwrap());
    assert_eq!(ctrl & vision::run_window::ctrl::ENABLE, 1, "{ctrl:#x}");
    assert_eq!(&win[0x100..0x200], &MARKER_CLASSES.table()[..]);
    let h = vision::run_window::Header::parse(&win).unwrap();
    let t = h.ticket().expect("runs published");
    assert!(
        report.sequence <= t.sequence && t.sequence >= 1,
        "{report:?} {t:?}"
    );
    let words: Vec<u32> = win[t.range()]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let mut det = vision::blobs::BlobDetector::new();
    let from_runs = vision::runs::blobs_from_runs(
        &words,
        t.width,
        t.height,
        t.dropped,
        &vision::PipelineConfig::default(),
        &mut det,
    )
    .unwrap();
    assert_eq!(from_runs.blobs().first().map(|b| b.class), Some(class));
    drop(world);

    // Without the unit the RAM file has no run window, and the firmware finds the leader in
    // the pixels itself.
    let mut world = two_cars(EngineKind::Qemu, false);
    let report = first_report(&mut world);
    assert_eq!(report.blob.map(|(_, b)| b.class), Some(class), "{report:?}");
    let ram = world
        .run_dir()
        .join(arena::camera_feed::ram_file_name(FOLLOWER));
    let file = qemu_harness::SharedRam::open_read_only(&ram).unwrap();
    let mut head = [0u8; 72];
    file.read_at(arena::camera_feed::RUN_WINDOW_OFFSET, &mut head)
        .unwrap();
    assert!(
        head.iter().all(|&b| b == 0),
        "a run window without the unit"
    );
    drop(world);
    let me = std::process::id().to_string();
    let left = std::process::Command::new("pgrep")
        .args(["-P", &me, "qemu-system"])
        .output()
        .expect("pgrep");
    assert!(left.stdout.is_empty(), "QEMU left behind");
}
