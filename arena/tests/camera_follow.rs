//! End to end with the camera, on the soft core's model in virtual time: the arena renders each
//! car's view into its frame grabber at 15 fps of world time with the firmware's own pixel
//! pipeline (a board without the vision unit), and at 30 fps, the tracker's rate, streamed
//! into the SoC's vision unit; car 1 drives up the arena and to the side by
//! a go-to group maneuver, and car 2 follows it by the camera alone (`CameraFollow`: marker
//! class of car 1, 200 units = 500 mm). The follower must see the leader in its camera report,
//! move with it, and keep within the band documented in `docs/camera.md` (reference points
//! 300..900 mm apart while the leader drives, 400..750 mm once both have stopped); at 30 fps its
//! firmware must build blobs from every frame's runs. A run is a function of its inputs, so the
//! machine's load cannot change the outcome. (`camera_qemu.rs` checks the same on QEMU.)

use arena::camera_feed::FeedConfig;
use arena::world::{CarSpec, EngineKind, World, WorldConfig};
use lbc_emu::Pose;
use std::time::Duration;
use ubc_app::program::console::{flags, Reply, Request};
use vision::colour::marker_class_for_car;

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

fn two_cars(engine: EngineKind, feed: FeedConfig) -> World {
    let elf = engine.default_firmware().expect("firmware ELF");
    let mut cfg = WorldConfig::new(
        elf,
        vec![
            CarSpec::new(LEADER, pose(300.0, 330.0)),
            CarSpec::new(FOLLOWER, pose(300.0, 110.0)),
        ],
    );
    cfg.engine = engine;
    cfg.camera = Some(feed);
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

fn distance_mm(world: &World) -> f64 {
    let t = world.truth();
    let (a, b) = (t[0].pose, t[1].pose);
    (a.x_mm - b.x_mm).hypot(a.y_mm - b.y_mm)
}

/// The follower's camera report.
fn camera_report(world: &mut World) -> ubc_app::program::console::CameraReport {
    match world.request(FOLLOWER, &Request::Camera { blob: 0 }, REQUEST_TIMEOUT) {
        Ok(Reply::Camera(r)) => r,
        other => panic!("{other:?}"),
    }
}

/// At 15 fps on a board without the vision unit: the firmware runs the pixel pipeline itself.
#[test]
fn camera_follower_keeps_its_distance_behind_a_driving_leader() {
    let frames_per_s = follow(FeedConfig {
        vision_unit: false,
        ..FeedConfig::default()
    });
    assert!(
        (14.5..=15.5).contains(&frames_per_s),
        "the firmware processed {frames_per_s:.1} frames per second"
    );
}

/// At the tracker's 30 Hz, on the soft core's clock: the vision unit does the pixels, so the
/// firmware keeps up with every frame.
#[test]
fn camera_follower_at_30_fps_on_the_vision_unit() {
    let frames_per_s = follow(FeedConfig {
        fps: 30.0,
        ..FeedConfig::default()
    });
    assert!(
        (29.0..=30.5).contains(&frames_per_s),
        "the firmware processed {frames_per_s:.1} frames per second"
    );
}

/// Runs the follow scenario with `feed`; returns the frames per second the follower's firmware
/// processed while the leader drove.
fn follow(feed: FeedConfig) -> f64 {
    let mut world = two_cars(EngineKind::Iss, feed);
    let class = marker_class_for_car(LEADER);
    // The follower's camera sees the leader's marker straight ahead, about 510 mm away.
    let report = first_report(&mut world);
    let (_, blob) = report.blob.unwrap();
    assert_eq!(blob.class, class, "{report:?}");
    assert!((280 * 4..360 * 4).contains(&blob.cx_q2), "{report:?}");

    let follow = maneuvers::CameraFollow::params(class, 200, 400).unwrap();
    assert_eq!(
        world
            .request(FOLLOWER, &Request::GroupStart(follow), REQUEST_TIMEOUT)
            .unwrap(),
        Reply::GroupStarted
    );
    let start_follower = world.truth()[1].pose;
    // Up the arena and 250 mm to the side: the follower has to steer.
    let goto = maneuvers::GoTo::params(400, 700, 150).unwrap();
    assert_eq!(
        world
            .request(LEADER, &Request::GroupStart(goto), REQUEST_TIMEOUT)
            .unwrap(),
        Reply::GroupStarted
    );

    // Drive: sample the distance; the leader needs about 7 s for its 960 mm.
    let t0 = world.now();
    let frames0 = camera_report(&mut world).frames;
    let mut rate = None;
    let mut worst = (f64::MAX, 0.0f64);
    let mut leader_stopped_at = None;
    while world.now() - t0 < Duration::from_secs(30) {
        world.run_for(Duration::from_millis(100));
        let elapsed = world.now() - t0;
        let d = distance_mm(&world);
        if elapsed > Duration::from_secs(2) {
            worst = (worst.0.min(d), worst.1.max(d));
        }
        let t = world.truth();
        if rate.is_none() && elapsed >= Duration::from_secs(5) {
            let r = camera_report(&mut world);
            let dt = (world.now() - t0).as_secs_f64();
            rate = Some(f64::from(r.frames.wrapping_sub(frames0)) / dt);
        }
        if elapsed.as_millis() % 1000 < 100 {
            eprintln!(
                "t={:.1} s leader ({:.0}, {:.0}) {:.0} mm/s, follower ({:.0}, {:.0}) {:.0} mm/s, distance {d:.0} mm",
                elapsed.as_secs_f64(),
                t[0].pose.x_mm,
                t[0].pose.y_mm,
                t[0].v_mm_s,
                t[1].pose.x_mm,
                t[1].pose.y_mm,
                t[1].v_mm_s
            );
        }
        // The leader stops inside its arrival radius of (1000, 1750) mm.
        if leader_stopped_at.is_none() && t[0].pose.y_mm > 1550.0 && t[0].v_mm_s.abs() < 5.0 {
            leader_stopped_at = Some(world.now());
        }
        if leader_stopped_at.is_some_and(|s| world.now() - s > Duration::from_secs(5)) {
            break;
        }
    }
    assert!(
        leader_stopped_at.is_some(),
        "the leader did not arrive: {:?}",
        world.truth()[0].pose
    );
    let end = world.truth();
    let moved = (end[1].pose.y_mm - start_follower.y_mm).abs();
    let report = camera_report(&mut world);
    let final_d = distance_mm(&world);
    let stats = world.camera_stats().unwrap();
    eprintln!(
        "follower moved {moved:.0} mm; distance while driving {:.0}..{:.0} mm, final {final_d:.0} mm; \
         report {report:?}; feed {stats:?}",
        worst.0, worst.1
    );
    assert!(moved > 600.0, "the follower moved only {moved:.0} mm");
    // It turned towards the leader's side and ends with the marker centred.
    assert!(
        end[1].pose.x_mm - start_follower.x_mm > 60.0,
        "{:?}",
        end[1].pose
    );
    assert!(report.leader_bearing_mrad.abs() < 60, "{report:?}");
    assert!(
        worst.0 > 300.0 && worst.1 < 900.0,
        "distance left the band: {worst:?}"
    );
    assert!(
        (400.0..750.0).contains(&final_d),
        "final distance {final_d}"
    );
    assert_eq!(report.leader_class, class);
    assert_eq!(report.follow_state, 1, "{report:?}");
    assert!((400..700).contains(&report.leader_range_mm), "{report:?}");
    let load = world.core_load(1).expect("cycle counts");
    let rate = rate.expect("measured while driving");
    eprintln!(
        "follower processor load {:.1} %, {rate:.1} frames per second processed",
        100.0 * load.load()
    );
    rate
}
