//! Rendered views through the on-board vision: a car at a known pose relative to the viewer shows up
//! as a marker blob at the expected bearing and range, in both pixel formats and through a
//! frame-grabber window. Every view is also detected the vision unit's way (its runs, then blobs
//! from the runs), which must give exactly the software pipeline's detections.

use arena::camera::{write_png, CameraConfig, CarPose, SyntheticCamera};
use vision::blobs::{BlobDetector, Detections};
use vision::colour::{marker_class_for_car, MARKER_CLASSES};
use vision::frame::{FrameWindow, PixelFormat, WINDOW_LEN};
use vision::runs::{blobs_from_runs, encode_frame, MAX_CAPACITY};
use vision::{process_frame, PipelineConfig};

const BEARING_TOLERANCE_MRAD: i32 = 15;
const RANGE_TOLERANCE: f32 = 0.08;

fn detect(cam: &SyntheticCamera, frame: &[u8]) -> Detections {
    let mut det = BlobDetector::new();
    let g = cam.geometry();
    let cfg = PipelineConfig::default();
    let want = process_frame(frame, &g, &MARKER_CLASSES, &cfg, &mut det)
        .expect("frame has the camera's geometry");
    // the vision unit's path
    let mut words = vec![0u32; MAX_CAPACITY];
    let s = encode_frame(frame, &g, &MARKER_CLASSES, &mut words).expect("encodes");
    assert_eq!((s.width, s.height, s.dropped), (g.width, g.height, 0));
    let got = blobs_from_runs(&words[..s.words], s.width, s.height, 0, &cfg, &mut det)
        .expect("the encoder's runs parse");
    assert_eq!(got, want, "runs then blobs differ from the pipeline");
    want
}

/// A car `ahead` mm in front of the viewer's camera and `left` mm to its left, at yaw `yaw`.
fn scene(
    viewer_yaw: f32,
    ahead: f32,
    left: f32,
    yaw: f32,
    cam: &SyntheticCamera,
) -> (CarPose, CarPose) {
    let viewer = CarPose {
        id: 0,
        x_mm: 750.0,
        y_mm: 400.0,
        yaw_rad: viewer_yaw,
    };
    let o = cam.camera_position(&viewer);
    let (s, c) = viewer_yaw.sin_cos();
    let other = CarPose {
        id: 5,
        x_mm: o[0] + ahead * c - left * s,
        y_mm: o[1] + ahead * s + left * c,
        yaw_rad: yaw,
    };
    (viewer, other)
}

#[test]
fn marker_bearing_and_range_match_the_pose() {
    for format in [PixelFormat::Rgb332, PixelFormat::Rgb565] {
        let config = CameraConfig {
            format,
            ..CameraConfig::default()
        };
        let mut cam = SyntheticCamera::new(config, 7);
        let mut frame = vec![0u8; cam.geometry().frame_len()];
        for &(ahead, left, yaw) in &[
            (400.0f32, 0.0f32, 0.0f32),
            (600.0, 150.0, 1.0),
            (800.0, -250.0, 2.5),
            (1000.0, 300.0, 4.0),
            (1200.0, -100.0, 0.7),
        ] {
            let (viewer, other) = scene(std::f32::consts::FRAC_PI_2, ahead, left, yaw, &cam);
            cam.render(&viewer, &[viewer, other], &mut frame).unwrap();
            let det = detect(&cam, &frame);
            let class = marker_class_for_car(other.id);
            let blob = det
                .largest_of_class(class)
                .unwrap_or_else(|| panic!("{format:?}: no marker at ({ahead}, {left}): {det:?}"));
            assert_eq!(det.blobs().len(), 1, "{format:?} {det:?}");
            let obs = config.model.observe(blob, &config.marker);
            let bearing = (left.atan2(ahead) * 1000.0) as i32;
            let range = ahead.hypot(left);
            assert!(
                (obs.bearing_mrad - bearing).abs() <= BEARING_TOLERANCE_MRAD,
                "{format:?} ({ahead}, {left}): bearing {} want {bearing}",
                obs.bearing_mrad
            );
            assert!(
                (obs.range_mm as f32 - range).abs() <= range * RANGE_TOLERANCE,
                "{format:?} ({ahead}, {left}): range {} want {range}",
                obs.range_mm
            );
        }
    }
}

#[test]
fn empty_arena_has_no_blobs_from_any_pose() {
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 3);
    let mut frame = vec![0u8; cam.geometry().frame_len()];
    for k in 0..8 {
        let viewer = CarPose {
            id: 0,
            x_mm: 300.0 + 100.0 * k as f32,
            y_mm: 200.0 + 200.0 * k as f32,
            yaw_rad: 0.8 * k as f32,
        };
        cam.render(&viewer, &[viewer], &mut frame).unwrap();
        assert!(detect(&cam, &frame).blobs().is_empty(), "pose {viewer:?}");
    }
}

#[test]
fn car_behind_the_viewer_is_not_seen_and_colours_follow_ids() {
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 11);
    let mut frame = vec![0u8; cam.geometry().frame_len()];
    let (viewer, mut behind) = scene(1.57, -300.0, 0.0, 0.0, &cam);
    behind.id = 1;
    let (_, mut ahead) = scene(1.57, 700.0, 100.0, 0.0, &cam);
    ahead.id = 3;
    cam.render(&viewer, &[viewer, behind, ahead], &mut frame)
        .unwrap();
    let det = detect(&cam, &frame);
    assert_eq!(det.blobs().len(), 1, "{det:?}");
    assert_eq!(det.blobs()[0].class, marker_class_for_car(3));
}

#[test]
fn nearer_car_hides_the_one_behind() {
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 5);
    let mut frame = vec![0u8; cam.geometry().frame_len()];
    let (viewer, mut near) = scene(1.6, 400.0, 0.0, 1.57, &cam);
    near.id = 2;
    let (_, mut far) = scene(1.6, 900.0, 0.0, 0.0, &cam);
    far.id = 6;
    cam.render(&viewer, &[viewer, near, far], &mut frame)
        .unwrap();
    let det = detect(&cam, &frame);
    assert!(det.largest_of_class(marker_class_for_car(2)).is_some());
    // Same bearing: the near marker (+/-2.9 degrees of elevation) covers the far one (+/-1.3).
    assert_eq!(
        det.largest_of_class(marker_class_for_car(6)),
        None,
        "{det:?}"
    );
    cam.render(&viewer, &[viewer, far], &mut frame).unwrap();
    assert!(detect(&cam, &frame)
        .largest_of_class(marker_class_for_car(6))
        .is_some());
}

#[test]
fn same_seed_same_frame_other_seed_other_noise() {
    let cfg = CameraConfig::default();
    let (viewer, other) = scene(1.0, 600.0, 0.0, 0.0, &SyntheticCamera::new(cfg, 0));
    let render = |seed| {
        let mut cam = SyntheticCamera::new(cfg, seed);
        let mut f = vec![0u8; cam.geometry().frame_len()];
        cam.render(&viewer, &[viewer, other], &mut f).unwrap();
        f
    };
    assert_eq!(render(1), render(1));
    assert_ne!(render(1), render(2));
    let quiet = CameraConfig { noise: 0, ..cfg };
    let mut a = SyntheticCamera::new(quiet, 1);
    let mut b = SyntheticCamera::new(quiet, 2);
    let mut fa = vec![0u8; a.geometry().frame_len()];
    let mut fb = fa.clone();
    a.render(&viewer, &[viewer, other], &mut fa).unwrap();
    b.render(&viewer, &[viewer, other], &mut fb).unwrap();
    assert_eq!(fa, fb);
}

#[test]
fn frames_published_through_the_window_read_back_whole() {
    let mut window = vec![0u8; WINDOW_LEN];
    FrameWindow::init(&mut window[..], 640, 480, PixelFormat::Rgb332).unwrap();
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 9);
    let (viewer, other) = scene(2.0, 700.0, -100.0, 0.0, &cam);
    let mut direct = vec![0u8; cam.geometry().frame_len()];
    for k in 1..=3u32 {
        let seq = cam
            .render_into_window(
                &mut window,
                &viewer,
                &[viewer, other],
                u64::from(k) * 33_333,
            )
            .unwrap();
        assert_eq!(seq, k);
    }
    let mut reader = FrameWindow::new_checked(&window[..]).unwrap();
    let ticket = reader.ticket().unwrap();
    assert_eq!(
        (ticket.sequence, ticket.index, ticket.capture_us),
        (3, 0, 99_999)
    );
    let det = detect(&cam, reader.frame(&ticket));
    assert_eq!(reader.verify(&ticket), Ok(()));
    let mut replay = SyntheticCamera::new(CameraConfig::default(), 9);
    for _ in 0..3 {
        replay
            .render(&viewer, &[viewer, other], &mut direct)
            .unwrap();
    }
    assert_eq!(reader.frame(&ticket), &direct[..]);
    assert_eq!(det.blobs().len(), 1);

    let mut wrong = vec![0u8; WINDOW_LEN];
    FrameWindow::init(&mut wrong[..], 320, 240, PixelFormat::Rgb332).unwrap();
    assert!(matches!(
        cam.render_into_window(&mut wrong, &viewer, &[viewer], 0),
        Err(arena::camera::CameraError::WindowMismatch)
    ));
    assert!(matches!(
        cam.render_into_window(&mut [0u8; 10], &viewer, &[viewer], 0),
        Err(arena::camera::CameraError::Window(_))
    ));
}

#[test]
fn png_export_has_the_frame_and_the_drawn_boxes() {
    let mut cam = SyntheticCamera::new(CameraConfig::default(), 4);
    let (viewer, other) = scene(0.5, 500.0, 50.0, 0.0, &cam);
    let mut frame = vec![0u8; cam.geometry().frame_len()];
    cam.render(&viewer, &[viewer, other], &mut frame).unwrap();
    let det = detect(&cam, &frame);
    let blob = *det.blobs().first().expect("one marker");
    let mut bytes = Vec::new();
    write_png(&mut bytes, &frame, &cam.geometry(), &det).unwrap();

    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().unwrap();
    let mut rgb = vec![0u8; reader.output_buffer_size()];
    let info = reader.next_frame(&mut rgb).unwrap();
    assert_eq!((info.width, info.height), (640, 480));
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let px = |x: u16, y: u16| {
        let i = (usize::from(y) * 640 + usize::from(x)) * 3;
        [rgb[i], rgb[i + 1], rgb[i + 2]]
    };
    // The box is drawn one pixel outside the blob.
    assert_eq!(px(blob.min_x - 1, blob.min_y - 1), [255; 3]);
    assert_eq!(px(blob.max_x + 1, blob.max_y + 1), [255; 3]);
    let (cx, cy) = blob.centroid();
    assert_eq!(px(cx.round() as u16, cy.round() as u16), [0; 3]);
    let path = std::env::temp_dir().join("camera_view_test.png");
    let file = std::fs::File::create(&path).unwrap();
    write_png(std::io::BufWriter::new(file), &frame, &cam.geometry(), &det).unwrap();
    assert!(std::fs::metadata(&path).unwrap().len() > 1000);
}
