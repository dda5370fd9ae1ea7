//! Synthetic camera benchmark: frames per second of one car's view with four other cars in sight,
//! for each pixel format, and of the vision pipeline on the rendered frames (host speed; the board's
//! cost is counted in instructions in `docs/camera.md`). `cargo bench -p arena --bench camera`
//! (`CAMERA_BENCH_FRAMES=N` to change the number of frames).

use arena::camera::{CameraConfig, CarPose, SyntheticCamera};
use std::time::Instant;
use vision::blobs::BlobDetector;
use vision::colour::MARKER_CLASSES;
use vision::frame::PixelFormat;
use vision::{process_frame, PipelineConfig};

fn main() {
    let frames: u32 = std::env::var("CAMERA_BENCH_FRAMES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(120);
    let viewer = CarPose {
        id: 0,
        x_mm: 750.0,
        y_mm: 300.0,
        yaw_rad: std::f32::consts::FRAC_PI_2,
    };
    let others = [
        CarPose {
            id: 1,
            x_mm: 700.0,
            y_mm: 800.0,
            yaw_rad: 0.3,
        },
        CarPose {
            id: 2,
            x_mm: 950.0,
            y_mm: 1100.0,
            yaw_rad: 1.0,
        },
        CarPose {
            id: 3,
            x_mm: 500.0,
            y_mm: 1300.0,
            yaw_rad: 2.0,
        },
        CarPose {
            id: 4,
            x_mm: 800.0,
            y_mm: 1700.0,
            yaw_rad: 4.0,
        },
    ];
    let mut cars = vec![viewer];
    cars.extend_from_slice(&others);
    println!("| pixel format | render fps (one car's view) | vision fps (host) | blobs |");
    println!("|---|---|---|---|");
    for format in [PixelFormat::Rgb332, PixelFormat::Rgb565] {
        let config = CameraConfig {
            format,
            ..CameraConfig::default()
        };
        let mut cam = SyntheticCamera::new(config, 1);
        let geometry = cam.geometry();
        let mut frame = vec![0u8; geometry.frame_len()];
        let start = Instant::now();
        for k in 0..frames {
            let mut v = viewer;
            v.yaw_rad += 0.001 * k as f32;
            if cam.render(&v, &cars, &mut frame).is_err() {
                eprintln!("render failed");
                return;
            }
        }
        let render_fps = f64::from(frames) / start.elapsed().as_secs_f64();
        let mut det = BlobDetector::new();
        let cfg = PipelineConfig::default();
        let start = Instant::now();
        let mut blobs = 0;
        for _ in 0..frames {
            match process_frame(&frame, &geometry, &MARKER_CLASSES, &cfg, &mut det) {
                Ok(d) => blobs = d.blobs().len(),
                Err(e) => {
                    eprintln!("pipeline failed: {e:?}");
                    return;
                }
            }
        }
        let vision_fps = f64::from(frames) / start.elapsed().as_secs_f64();
        println!("| {format:?} | {render_fps:.0} | {vision_fps:.0} | {blobs} |");
    }
    accuracy();
}

/// Largest bearing and range errors of the marker observation over a grid of relative poses.
fn accuracy() {
    let config = CameraConfig::default();
    let mut cam = SyntheticCamera::new(config, 3);
    let mut frame = vec![0u8; cam.geometry().frame_len()];
    let mut det = BlobDetector::new();
    let viewer = CarPose {
        id: 0,
        x_mm: 750.0,
        y_mm: 150.0,
        yaw_rad: std::f32::consts::FRAC_PI_2,
    };
    let o = cam.camera_position(&viewer);
    println!();
    println!(
        "| range band (mm) | poses | detected | max bearing error (mrad) | max range error (%) |"
    );
    println!("|---|---|---|---|---|");
    for (lo, hi) in [(300.0f32, 600.0f32), (600.0, 1000.0), (1000.0, 1500.0)] {
        let (mut n, mut seen, mut eb, mut er) = (0, 0, 0i32, 0.0f32);
        let mut ahead = lo;
        while ahead < hi {
            for k in -3..=3 {
                // Bearings up to +/-24 degrees, inside the 60 degree view with the marker whole.
                let bearing = 0.14 * k as f32;
                let (left, fwd) = (ahead * bearing.tan(), ahead);
                let other = CarPose {
                    id: 2,
                    x_mm: o[0] - left,
                    y_mm: o[1] + fwd,
                    yaw_rad: 0.5 * k as f32,
                };
                n += 1;
                if cam.render(&viewer, &[viewer, other], &mut frame).is_err() {
                    return;
                }
                let Ok(d) = process_frame(
                    &frame,
                    &cam.geometry(),
                    &MARKER_CLASSES,
                    &PipelineConfig::default(),
                    &mut det,
                ) else {
                    return;
                };
                if let Some(b) = d.largest_of_class(vision::colour::marker_class_for_car(2)) {
                    seen += 1;
                    let obs = config.model.observe(b, &config.marker);
                    let want_b = (left.atan2(fwd) * 1000.0) as i32;
                    let want_r = fwd.hypot(left);
                    eb = eb.max((obs.bearing_mrad - want_b).abs());
                    er = er.max((obs.range_mm as f32 - want_r).abs() / want_r * 100.0);
                }
            }
            ahead += 50.0;
        }
        println!("| {lo:.0}..{hi:.0} | {n} | {seen} | {eb} | {er:.1} |");
    }
}
