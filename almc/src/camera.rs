//! `almc camera snapshot --car N OUT.png`: saves what car N's camera sees, with the vision
//! pipeline's detections drawn (white boxes, black centroid crosses), and lists them.
//!
//! Sources:
//! - a running arena (default): the car's frame is read from its QEMU RAM file, which a world with
//!   a camera keeps at `$TMPDIR/almc-arena-<pid>-<n>/car<N>-ram` (`--run DIR` names the directory;
//!   without it the most recent running world that has car N is used);
//! - `--experiment FILE`: no QEMU; the view is rendered from the experiment's start poses.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use arena::camera::{write_png, CameraConfig, CarPose, SyntheticCamera};
use arena::camera_feed::vision::blobs::Detections;
use arena::camera_feed::vision::frame::FrameTicket;
use arena::camera_feed::vision::pinhole::{CameraModel, MarkerModel};
use arena::camera_feed::{find_car_ram, read_window_frame, WindowFrame};
use arena::experiment::Experiment;
use clap::{Args, Subcommand};

/// `almc camera ...`
#[derive(Debug, Subcommand)]
pub enum CameraCommand {
    /// Save a car's current camera frame as PNG with its detections drawn.
    Snapshot(SnapshotArgs),
}

/// `almc camera snapshot`
#[derive(Debug, Args)]
pub struct SnapshotArgs {
    /// The car (ID, 1..=126).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=126))]
    car: u8,
    /// The run directory of a running arena (default: the newest running one with this car).
    #[arg(long, value_name = "DIR", conflicts_with = "experiment")]
    run: Option<PathBuf>,
    /// Render from this experiment's start poses instead of reading a running car.
    #[arg(long, value_name = "FILE")]
    experiment: Option<PathBuf>,
    /// Seed of the rendered noise (with `--experiment`).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The PNG to write.
    out: PathBuf,
}

pub fn run(cmd: CameraCommand) -> ExitCode {
    match cmd {
        CameraCommand::Snapshot(args) => match snapshot(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
    }
}

fn snapshot(args: &SnapshotArgs) -> Result<(), String> {
    let (frame, source) = match &args.experiment {
        Some(file) => (
            render_start(file, args.car, args.seed)?,
            file.display().to_string(),
        ),
        None => {
            let ram = find_car_ram(args.car, args.run.as_deref()).map_err(|e| e.to_string())?;
            let frame = read_window_frame(&ram).map_err(|e| format!("{}: {e}", ram.display()))?;
            (frame, ram.display().to_string())
        }
    };
    let detections = frame.detect().map_err(|e| e.to_string())?;
    save(&args.out, &frame, &detections)?;
    println!(
        "car {} frame {} ({}x{}) from {source} -> {}",
        args.car,
        frame.ticket.sequence,
        frame.geometry.width,
        frame.geometry.height,
        args.out.display()
    );
    list(&detections);
    Ok(())
}

/// The view of `car` at the experiment's start.
fn render_start(file: &Path, car: u8, seed: u64) -> Result<WindowFrame, String> {
    let exp = Experiment::load(file).map_err(|e| e.to_string())?;
    let poses: Vec<CarPose> = exp
        .cars
        .iter()
        .map(|c| CarPose::from_tracking(c.id, c.x, c.y, c.heading_mrad))
        .collect();
    let viewer = poses
        .iter()
        .find(|p| p.id == car)
        .copied()
        .ok_or_else(|| format!("{} has no car {car}", file.display()))?;
    let mut cam = SyntheticCamera::new(CameraConfig::default(), seed);
    let geometry = cam.geometry();
    let mut pixels = vec![0u8; geometry.frame_len()];
    cam.render(&viewer, &poses, &mut pixels)
        .map_err(|e| format!("rendering: {e:?}"))?;
    Ok(WindowFrame {
        ticket: FrameTicket {
            index: 0,
            sequence: 0,
            capture_us: 0,
        },
        geometry,
        pixels,
    })
}

fn save(out: &Path, frame: &WindowFrame, detections: &Detections) -> Result<(), String> {
    let file = File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
    write_png(
        BufWriter::new(file),
        &frame.pixels,
        &frame.geometry,
        detections,
    )
    .map_err(|e| format!("{}: {e:?}", out.display()))
}

fn list(detections: &Detections) {
    let model = CameraModel::default();
    let marker = MarkerModel::default();
    if detections.blobs().is_empty() {
        println!("no blobs");
    }
    for b in detections.blobs() {
        let (cx, cy) = b.centroid();
        let o = model.observe(b, &marker);
        println!(
            "class {} area {} centroid ({cx:.1}, {cy:.1}) box ({},{})-({},{}) bearing {} mrad range {} mm",
            b.class, b.area, b.min_x, b.min_y, b.max_x, b.max_y, o.bearing_mrad, o.range_mm
        );
    }
}
