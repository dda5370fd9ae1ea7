//! The on-firmware vision benchmark (`cargo xtask bench --only fw-vision`): renders the benchmark
//! scene, publishes it into a RAM file's frame-grabber window, boots the `bench_vision` firmware
//! (ELF in `UBC_BENCH_VISION_ELF`) in QEMU with that RAM and `-icount shift=0`, and prints the
//! firmware's `bench ...` lines. The blobs the firmware found must equal the host's, exactly.
//!
//! Ignored by default (it needs the benchmark ELF): `UBC_BENCH_VISION_ELF=... cargo test -p arena
//! --release --test camera_fw_bench -- --ignored --nocapture`.

use arena::camera::{CameraConfig, SyntheticCamera};
use arena::camera_feed::{bench_scene, RamWindow};
use qemu_harness::{Qemu, SharedRam, SharedRamSpec, UartAttach};
use std::time::Duration;

#[test]
#[ignore]
fn vision_instructions_per_pixel_on_the_firmware() {
    let Some(elf) = std::env::var_os("UBC_BENCH_VISION_ELF") else {
        panic!("set UBC_BENCH_VISION_ELF to the bench_vision firmware ELF");
    };
    let dir = std::env::temp_dir().join(format!("arena-fw-vision-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec = SharedRamSpec::new(dir.join("ram"));
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 1);
    let g = cam.geometry();
    let (viewer, cars) = bench_scene();
    let mut frame = vec![0u8; g.frame_len()];
    cam.render(&viewer, &cars, &mut frame).unwrap();
    let ram = SharedRam::create(&spec.path, spec.len()).unwrap();
    let mut window = RamWindow::init(ram, &g).unwrap();
    window.publish(&frame, 0).unwrap();
    let host = arena::camera_feed::read_window_frame(&spec.path)
        .unwrap()
        .detect()
        .unwrap();

    let mut qemu = Qemu::builder(elf)
        .lbc(UartAttach::Null)
        .radio(UartAttach::Null)
        .icount(Some(0))
        .shared_ram(spec)
        .spawn()
        .unwrap();
    let status = qemu.wait_exit(Duration::from_secs(120));
    let _ = qemu.kill();
    let lines: Vec<String> = qemu
        .log()
        .lines()
        .iter()
        .map(|l| l.message.clone())
        .collect();
    for l in &lines {
        println!("fw: {l}");
    }
    let _ = std::fs::remove_dir_all(&dir);
    let status = status.unwrap();
    assert!(status.success(), "{status}: {}", qemu.stderr_text());
    let fw_blobs: Vec<&String> = lines
        .iter()
        .filter(|l| l.starts_with("bench blob "))
        .collect();
    assert_eq!(fw_blobs.len(), host.blobs().len(), "{lines:?}");
    for (line, b) in fw_blobs.iter().zip(host.blobs()) {
        let want = format!(
            "bench blob class={} area={} sum_x={} sum_y={} box={},{},{},{} ",
            b.class, b.area, b.sum_x, b.sum_y, b.min_x, b.min_y, b.max_x, b.max_y
        );
        assert!(line.starts_with(&want), "{line} != {want}");
    }
}
