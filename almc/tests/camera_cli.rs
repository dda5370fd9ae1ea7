//! `almc camera snapshot`: rendered from an experiment's start poses, read from a car's RAM file
//! (as a running arena keeps it), and the errors when there is nothing to read.

use std::path::Path;
use std::process::{Command, Output};

use arena::camera::{CameraConfig, CarPose, SyntheticCamera};
use arena::camera_feed::{bench_scene, ram_file_name, RamWindow};
use qemu_harness::{SharedRam, SharedRamSpec};

fn almc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(args)
        .output()
        .expect("almc runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&b[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    (be(16), be(20))
}

const EXPERIMENT: &str = r#"
name = "camera-cli"
duration_s = 10

[[cars]]
id = 2
x = 300
y = 200
heading_mrad = 1571

[[cars]]
id = 5
x = 300
y = 500
heading_mrad = 1571

[maneuver]
kind = "circle"
centre = [300, 400]
radius_units = 150
speed_mm_s = 120
"#;

#[test]
fn snapshot_from_experiment_start_poses() {
    let dir = tempfile::tempdir().unwrap();
    let exp = dir.path().join("e.toml");
    std::fs::write(&exp, EXPERIMENT).unwrap();
    let png = dir.path().join("car2.png");
    let o = almc(&[
        "camera",
        "snapshot",
        "--car",
        "2",
        "--experiment",
        exp.to_str().unwrap(),
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert_eq!(png_size(&png), (640, 480));
    // Car 5 (cyan, class 6) is 750 mm straight ahead of car 2's reference point: the camera
    // sits 40 mm forward, so about 710 mm.
    let line = out.lines().find(|l| l.starts_with("class 6 ")).expect(&out);
    let num = |key: &str| -> i64 {
        let rest = &line[line.find(key).unwrap() + key.len()..];
        rest.split_whitespace().next().unwrap().parse().unwrap()
    };
    assert!(num("bearing ").abs() <= 15, "{line}");
    assert!((num("range ") - 710).abs() <= 60, "{line}");

    // Car 5 looks at the far wall: nothing.
    let o = almc(&[
        "camera",
        "snapshot",
        "--car",
        "5",
        "--experiment",
        exp.to_str().unwrap(),
        png.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("no blobs"), "{}", text(&o.stdout));

    let o = almc(&[
        "camera",
        "snapshot",
        "--car",
        "9",
        "--experiment",
        exp.to_str().unwrap(),
        png.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("has no car 9"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn snapshot_from_a_run_directory() {
    let run = tempfile::tempdir().unwrap();
    let spec = SharedRamSpec::new(run.path().join(ram_file_name(7)));
    let ram = SharedRam::create(&spec.path, spec.len()).unwrap();
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 9);
    let g = cam.geometry();
    let mut window = RamWindow::init(ram, &g).unwrap();
    let png = run.path().join("out.png");
    let args = |car: &str| {
        vec![
            "camera".to_owned(),
            "snapshot".to_owned(),
            "--car".to_owned(),
            car.to_owned(),
            "--run".to_owned(),
            run.path().to_string_lossy().into_owned(),
            png.to_string_lossy().into_owned(),
        ]
    };
    let run_almc = |car: &str| {
        let a = args(car);
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        almc(&refs)
    };

    // The car's QEMU has not got a frame yet.
    let o = run_almc("7");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("no frame published yet"),
        "{}",
        text(&o.stderr)
    );

    let (viewer, cars) = bench_scene();
    let viewer = CarPose { id: 7, ..viewer };
    let cars: Vec<CarPose> = cars.into_iter().filter(|c| c.id != 0).collect();
    let mut frame = vec![0u8; g.frame_len()];
    for _ in 0..2 {
        cam.render(&viewer, &cars, &mut frame).unwrap();
        window.publish(&frame, 1).unwrap();
    }
    let o = run_almc("7");
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.starts_with("car 7 frame 2 (640x480)"), "{out}");
    for class in 2..=5 {
        assert!(out.contains(&format!("class {class} ")), "{out}");
    }
    assert_eq!(png_size(&png), (640, 480));

    let o = run_almc("8");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("has no car8-ram"),
        "{}",
        text(&o.stderr)
    );
}

#[test]
fn no_running_arena_and_bad_arguments_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("x.png");
    // Car 126 with a camera is not running anywhere (the tests never start one).
    let o = almc(&["camera", "snapshot", "--car", "126", png.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert!(err.contains("no running arena has car 126"), "{err}");
    assert!(!png.exists());

    let o = almc(&["camera", "snapshot", "--car", "0", png.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    let o = almc(&[
        "camera",
        "snapshot",
        "--car",
        "3",
        "--run",
        "/nonexistent-run-dir",
        png.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o.stderr).contains("does not exist"),
        "{}",
        text(&o.stderr)
    );
}
