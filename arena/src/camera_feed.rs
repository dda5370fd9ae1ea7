//! Camera frames into cars' frame grabbers. [`WindowPublisher`] is the writer side of the
//! window protocol over any [`WindowWriter`]: a soft-core car's window in the SoC model, or a
//! QEMU car's RAM (a shared file, `qemu-harness`, with the window at [`FRAME_WINDOW_OFFSET`];
//! [`RamWindow`]). The world renders every camera car's view at a fixed rate of world time and
//! publishes it. [`read_window_frame`] is a host reader of RAM files (for
//! `almc camera snapshot`).
//!
//! With the vision unit on (the default) each published frame also goes to the car's vision
//! unit: on the SoC model into its camera port ([`soc_model::Soc::camera_frame`]); on QEMU,
//! whose virt board has no such device, the host computes the runs with the class table the
//! firmware loaded and publishes them into the run window at [`RUN_WINDOW_OFFSET`] of the RAM
//! file ([`host_runs`]), so the same firmware takes the same path on both engines.
//!
//! Protocol order: the buffer's `buffer_seq` is set to `WRITING` (one write), the pixels are
//! written, then `capture_us` with `buffer_seq`, then `ready`, then `sequence`, each a separate
//! write in that order (`docs/camera.md`).

/// The vision crate whose types this module's API uses.
pub use vision;

use crate::camera::{CameraConfig, CameraError, CarPose};
use crate::engine::{FrameWriteError, WindowWriter};
use qemu_harness::{SharedRam, FRAME_WINDOW_OFFSET};
use std::io;
use std::path::{Path, PathBuf};
use std::thread;
use std::time::Duration;
use vision::blobs::{BlobDetector, Detections};
use vision::colour::rgb565_to_rgb332;
use vision::colour::MARKER_CLASSES;
use vision::frame::{
    field, FrameTicket, HeaderError, HeaderRepr, PixelFormat, HEADER_LEN, WINDOW_LEN, WRITING,
};
use vision::run_window::{self, ctrl, status, Header as RunHeader, LUT_OFFSET};
use vision::runs::encode_codes;
use vision::{process_frame, FrameGeometry, PipelineConfig, PipelineError};

/// File name of car `id`'s RAM file inside a world's run directory.
pub fn ram_file_name(id: u8) -> String {
    format!("car{id}-ram")
}

/// Default frame rate of the feed, frames per second per car.
pub const DEFAULT_FPS: f64 = 15.0;

/// Why a window could not be written or read.
#[derive(Debug)]
pub enum FeedError {
    /// Reading or writing the RAM file failed.
    Io(io::Error),
    /// The window's header is not valid, or shows no usable frame.
    Header(HeaderError),
    /// The renderer failed.
    Camera(CameraError),
    /// The frame does not go through the pipeline.
    Pipeline(PipelineError),
    /// The frame has the wrong size for the window.
    FrameSize { needed: usize, got: usize },
}

impl std::fmt::Display for FeedError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FeedError::Io(e) => write!(f, "{e}"),
            FeedError::Header(HeaderError::NoFrame) => write!(f, "no frame published yet"),
            FeedError::Header(e) => write!(f, "frame-grabber window: {e:?}"),
            FeedError::Camera(e) => write!(f, "camera: {e:?}"),
            FeedError::Pipeline(e) => write!(f, "vision: {e:?}"),
            FeedError::FrameSize { needed, got } => {
                write!(f, "frame of {got} bytes, the window needs {needed}")
            }
        }
    }
}

impl std::error::Error for FeedError {}

impl From<io::Error> for FeedError {
    fn from(e: io::Error) -> Self {
        FeedError::Io(e)
    }
}

impl From<HeaderError> for FeedError {
    fn from(e: HeaderError) -> Self {
        FeedError::Header(e)
    }
}

/// Offset of the vision unit's run window in a QEMU car's RAM file (guest address
/// `0x8113_0000`, right after the frame-grabber window).
pub const RUN_WINDOW_OFFSET: u64 = FRAME_WINDOW_OFFSET + WINDOW_LEN as u64;

/// Run buffer capacity of the host's run window (the SoC's: 4096 words).
pub const RUN_CAPACITY: u32 = 4096;

/// Writes an empty run window (nothing published, the unit stopped) into a QEMU car's RAM file,
/// before its firmware starts: the firmware then finds a vision unit there.
pub fn init_run_window(ram: &mut SharedRam) -> io::Result<()> {
    let mut b = [0u8; run_window::HEADER_LEN + 8];
    RunHeader::new(RUN_CAPACITY).emit(&mut b);
    ram.write_at(RUN_WINDOW_OFFSET, &b)
}

/// What the vision unit does with a frame, done by the host for a QEMU car: if the RAM file
/// holds a run window and the firmware has enabled it, the frame's RGB332 codes are classified
/// with the class table the firmware loaded and their runs published into the buffer that is
/// not ready, through the run window's writer protocol, and the status's frame bit is set.
/// Unlike the SoC's unit (which waits for the end of a frame after it is enabled and takes the
/// frame's stream time), every frame is published at once. `Ok(false)`: no run window.
pub fn host_runs(ram: &mut SharedRam, codes: &[u8], width: u16) -> io::Result<bool> {
    let mut head = [0u8; run_window::HEADER_LEN + 8];
    ram.read_at(RUN_WINDOW_OFFSET, &mut head)?;
    let Ok(mut header) = RunHeader::parse(&head) else {
        return Ok(false);
    };
    let mut c = [0u8; 4];
    c.copy_from_slice(&head[run_window::field::CTRL]);
    let c = u32::from_le_bytes(c);
    if c & ctrl::ENABLE == 0 {
        return Ok(true);
    }
    let mut lut = [0u8; 256];
    ram.read_at(RUN_WINDOW_OFFSET + LUT_OFFSET as u64, &mut lut)?;
    let mut words = vec![0u32; header.capacity as usize];
    let s = encode_codes(codes, width, &lut, &mut words);
    run_window::publish(
        &mut header,
        &words[..s.words],
        u32::from(s.dropped),
        (s.width, s.height),
        |off, b| ram.write_at(RUN_WINDOW_OFFSET + off as u64, b),
    )?;
    let st = status::FRAME | status::ACTIVE;
    ram.write_at(
        RUN_WINDOW_OFFSET + run_window::field::STATUS.start as u64,
        &st.to_le_bytes(),
    )?;
    Ok(true)
}

/// The writer side of the window protocol, over any [`WindowWriter`]: a QEMU car's RAM file
/// or a soft-core car's frame-grabber window in the SoC model; with the vision unit on, each
/// frame also goes to the car's unit.
#[derive(Debug, Clone)]
pub struct WindowPublisher {
    header: HeaderRepr,
    unit: bool,
    codes: Vec<u8>,
}

fn sink_err(e: FrameWriteError) -> FeedError {
    FeedError::Io(io::Error::other(e.0))
}

impl WindowPublisher {
    /// Writes a fresh header (nothing published) for `geometry` into the window.
    pub fn init(sink: &mut dyn WindowWriter, geometry: &FrameGeometry) -> Result<Self, FeedError> {
        let header = HeaderRepr::new(geometry.width, geometry.height, geometry.format);
        if header.window_len() > WINDOW_LEN {
            return Err(FeedError::FrameSize {
                needed: header.window_len(),
                got: WINDOW_LEN,
            });
        }
        let mut bytes = [0u8; HEADER_LEN];
        header.emit(&mut bytes)?;
        sink.write_window(0, &bytes).map_err(sink_err)?;
        Ok(WindowPublisher {
            header,
            unit: false,
            codes: Vec::new(),
        })
    }

    /// From now on every published frame also goes to the car's vision unit (or not).
    pub fn with_vision_unit(mut self, on: bool) -> Self {
        self.unit = on;
        self
    }

    /// The header as last written.
    pub fn header(&self) -> &HeaderRepr {
        &self.header
    }

    /// Publishes `pixels` (one packed frame) as the next frame; returns its sequence.
    pub fn publish(
        &mut self,
        sink: &mut dyn WindowWriter,
        pixels: &[u8],
        capture_us: u64,
    ) -> Result<u32, FeedError> {
        let mut h = self.header;
        let needed = h.frame_len();
        if pixels.len() != needed {
            return Err(FeedError::FrameSize {
                needed,
                got: pixels.len(),
            });
        }
        let index = if h.sequence == 0 {
            0
        } else {
            ((h.ready & 1) ^ 1) as usize
        };
        let mut put = |range: &std::ops::Range<usize>, bytes: &[u8]| {
            debug_assert_eq!(range.len(), bytes.len());
            sink.write_window(range.start, bytes).map_err(sink_err)
        };
        // The local copy and the window agree on WRITING even if a later write fails.
        self.header.buffer_seq[index] = WRITING;
        h.buffer_seq[index] = WRITING;
        put(&field::BUFFER_SEQ[index], &WRITING.to_le_bytes())?;
        let start = h.buffer_offset[index] as usize;
        put(&(start..start + pixels.len()), pixels)?;
        let mut next = h.sequence.wrapping_add(1);
        if next == 0 || next == WRITING {
            next = 1;
        }
        put(&field::CAPTURE_US[index], &capture_us.to_le_bytes())?;
        put(&field::BUFFER_SEQ[index], &next.to_le_bytes())?;
        put(&field::READY, &(index as u32).to_le_bytes())?;
        put(&field::SEQUENCE, &next.to_le_bytes())?;
        h.capture_us[index] = capture_us;
        h.buffer_seq[index] = next;
        h.ready = index as u32;
        h.sequence = next;
        self.header = h;
        if self.unit {
            let codes: &[u8] = match h.format {
                PixelFormat::Rgb332 => pixels,
                PixelFormat::Rgb565 => {
                    self.codes.clear();
                    self.codes.extend(
                        pixels
                            .chunks_exact(2)
                            .map(|p| rgb565_to_rgb332(u16::from_le_bytes([p[0], p[1]]))),
                    );
                    &self.codes
                }
            };
            sink.camera_stream(codes, h.width, h.height)
                .map_err(sink_err)?;
        }
        Ok(next)
    }
}

/// A QEMU car's RAM file as a window: offsets are relative to [`FRAME_WINDOW_OFFSET`]; its
/// vision unit is the host ([`host_runs`]), present when the file has a run window.
impl WindowWriter for SharedRam {
    fn write_window(&mut self, offset: usize, bytes: &[u8]) -> Result<(), FrameWriteError> {
        self.write_at(FRAME_WINDOW_OFFSET + offset as u64, bytes)
            .map_err(|e| FrameWriteError(e.to_string()))
    }

    fn camera_stream(
        &mut self,
        codes: &[u8],
        width: u16,
        _height: u16,
    ) -> Result<bool, FrameWriteError> {
        host_runs(self, codes, width).map_err(|e| FrameWriteError(e.to_string()))
    }
}

/// The writer of one car's window in its RAM file.
#[derive(Debug)]
pub struct RamWindow {
    ram: SharedRam,
    publisher: WindowPublisher,
}

impl RamWindow {
    /// Writes a fresh header (nothing published) for `geometry` into the RAM file.
    pub fn init(mut ram: SharedRam, geometry: &FrameGeometry) -> Result<Self, FeedError> {
        let publisher = WindowPublisher::init(&mut ram, geometry)?;
        Ok(RamWindow { ram, publisher })
    }

    /// The header as last written.
    pub fn header(&self) -> &HeaderRepr {
        self.publisher.header()
    }

    /// Publishes `pixels` (one packed frame) as the next frame; returns its sequence.
    pub fn publish(&mut self, pixels: &[u8], capture_us: u64) -> Result<u32, FeedError> {
        self.publisher.publish(&mut self.ram, pixels, capture_us)
    }
}

/// A frame read from a RAM file's window, whole (the header did not change under it).
#[derive(Debug, Clone)]
pub struct WindowFrame {
    pub ticket: FrameTicket,
    pub geometry: FrameGeometry,
    pub pixels: Vec<u8>,
}

impl WindowFrame {
    /// Runs the vision pipeline with the marker classes (as the firmware does).
    pub fn detect(&self) -> Result<Detections, FeedError> {
        let mut det = BlobDetector::new();
        process_frame(
            &self.pixels,
            &self.geometry,
            &MARKER_CLASSES,
            &PipelineConfig::default(),
            &mut det,
        )
        .map_err(FeedError::Pipeline)
    }
}

/// Reads the newest published frame from the RAM file at `path` (a few attempts if the writer
/// is mid-publish or overwrites it meanwhile).
pub fn read_window_frame(path: &Path) -> Result<WindowFrame, FeedError> {
    let ram = SharedRam::open_read_only(path)?;
    let mut last = FeedError::Header(HeaderError::NoFrame);
    for _ in 0..5 {
        let mut hb = [0u8; HEADER_LEN];
        ram.read_at(FRAME_WINDOW_OFFSET, &mut hb)?;
        let header = HeaderRepr::parse(&hb)?;
        if header.window_len() > WINDOW_LEN {
            return Err(FeedError::FrameSize {
                needed: header.window_len(),
                got: WINDOW_LEN,
            });
        }
        let ticket = match header.ticket() {
            Ok(t) => t,
            Err(HeaderError::NoFrame) => return Err(HeaderError::NoFrame.into()),
            Err(e) => {
                last = e.into();
                thread::sleep(Duration::from_millis(5));
                continue;
            }
        };
        let range = header.buffer_range(ticket.index);
        let mut pixels = vec![0u8; range.len()];
        ram.read_at(FRAME_WINDOW_OFFSET + range.start as u64, &mut pixels)?;
        ram.read_at(FRAME_WINDOW_OFFSET, &mut hb)?;
        match ticket.verify(&HeaderRepr::parse(&hb)?) {
            Ok(()) => {
                return Ok(WindowFrame {
                    ticket,
                    geometry: FrameGeometry::from(&header),
                    pixels,
                })
            }
            Err(e) => last = e.into(),
        }
    }
    Err(last)
}

/// Prefix of a running world's directory in the system temp dir: `almc-arena-<pid>-<n>`.
pub const RUN_DIR_PREFIX: &str = "almc-arena-";

/// Why no running car's RAM file was found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FindError {
    /// The given run directory does not exist.
    NoRunDir { dir: PathBuf },
    /// The run directory has no RAM file for the car (no such car, or no camera in that run).
    NoCarInRun { car: u8, dir: PathBuf },
    /// No running world in the temp dir has a RAM file for the car.
    NoneRunning { car: u8, temp_dir: PathBuf },
}

impl std::fmt::Display for FindError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FindError::NoRunDir { dir } => {
                write!(f, "run directory {} does not exist", dir.display())
            }
            FindError::NoCarInRun { car, dir } => write!(
                f,
                "{} has no {} (no car {car} in that run, or it runs without a camera)",
                dir.display(),
                ram_file_name(*car)
            ),
            FindError::NoneRunning { car, temp_dir } => write!(
                f,
                "no running arena has car {car} with a camera (looked for {}/{RUN_DIR_PREFIX}*/{})",
                temp_dir.display(),
                ram_file_name(*car)
            ),
        }
    }
}

impl std::error::Error for FindError {}

/// Whether the process that owns world directory `name` (`almc-arena-<pid>-<n>`) is alive.
pub(crate) fn owner_alive(name: &str) -> bool {
    let Some(pid) = name
        .strip_prefix(RUN_DIR_PREFIX)
        .and_then(|rest| rest.split('-').next())
        .and_then(|pid| pid.parse::<u32>().ok())
    else {
        return false;
    };
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Car `car`'s RAM file: in `run` if given, else in the most recently started running world
/// under the system temp dir.
pub fn find_car_ram(car: u8, run: Option<&Path>) -> Result<PathBuf, FindError> {
    if let Some(dir) = run {
        if !dir.is_dir() {
            return Err(FindError::NoRunDir { dir: dir.into() });
        }
        let path = dir.join(ram_file_name(car));
        return if path.is_file() {
            Ok(path)
        } else {
            Err(FindError::NoCarInRun {
                car,
                dir: dir.into(),
            })
        };
    }
    let temp_dir = std::env::temp_dir();
    let none = || FindError::NoneRunning {
        car,
        temp_dir: temp_dir.clone(),
    };
    let entries = std::fs::read_dir(&temp_dir).map_err(|_| none())?;
    let mut best: Option<(std::time::SystemTime, PathBuf)> = None;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !name.starts_with(RUN_DIR_PREFIX) || !owner_alive(&name) {
            continue;
        }
        let path = e.path().join(ram_file_name(car));
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        let t = meta.modified().unwrap_or(std::time::UNIX_EPOCH);
        if best.as_ref().is_none_or(|(bt, _)| t > *bt) {
            best = Some((t, path));
        }
    }
    best.map(|(_, p)| p).ok_or_else(none)
}

/// Settings of the world's camera feed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedConfig {
    /// Frames per second per car.
    pub fps: f64,
    /// The camera of every car.
    pub camera: CameraConfig,
    /// Seed of the cameras' noise (car `id` adds `id`).
    pub seed: u64,
    /// Every car has a vision unit that turns the frames into runs (default); false: the cars
    /// are boards without one.
    pub vision_unit: bool,
}

impl Default for FeedConfig {
    fn default() -> Self {
        FeedConfig {
            fps: DEFAULT_FPS,
            camera: CameraConfig::default(),
            seed: 1,
            vision_unit: true,
        }
    }
}

/// What the world's camera has done so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FeedStats {
    /// Frames published (all cars).
    pub frames: u64,
    /// Frames that could not be rendered or written.
    pub failed: u64,
}

/// The scene of the benchmarks: a car at the near end looking down the arena at four others.
pub fn bench_scene() -> (CarPose, Vec<CarPose>) {
    let viewer = CarPose {
        id: 0,
        x_mm: 750.0,
        y_mm: 300.0,
        yaw_rad: std::f32::consts::FRAC_PI_2,
    };
    let mut cars = vec![viewer];
    for (id, x, y, yaw) in [
        (1, 700.0, 800.0, 0.3),
        (2, 950.0, 1100.0, 1.0),
        (3, 500.0, 1300.0, 2.0),
        (4, 800.0, 1700.0, 4.0),
    ] {
        cars.push(CarPose {
            id,
            x_mm: x,
            y_mm: y,
            yaw_rad: yaw,
        });
    }
    (viewer, cars)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::SyntheticCamera;
    use std::sync::atomic::{AtomicU64, Ordering};
    use vision::frame::FrameWindow;

    #[test]
    fn published_frames_read_back_whole_and_match_the_slice_writer() {
        let dir = tempfile_dir();
        let path = dir.join("ram");
        let ram = SharedRam::create(&path, FRAME_WINDOW_OFFSET + WINDOW_LEN as u64).unwrap();
        let mut cam = SyntheticCamera::new(CameraConfig::default(), 3);
        let g = cam.geometry();
        let mut win = RamWindow::init(ram, &g).unwrap();
        assert!(matches!(
            read_window_frame(&path),
            Err(FeedError::Header(HeaderError::NoFrame))
        ));
        let (viewer, cars) = bench_scene();
        let mut frame = vec![0u8; g.frame_len()];
        // The same frames through the in-memory writer of `vision::frame`.
        let mut mem = vec![0u8; WINDOW_LEN];
        let mut reference = FrameWindow::init(&mut mem[..], g.width, g.height, g.format).unwrap();
        for k in 0..3u64 {
            cam.render(&viewer, &cars, &mut frame).unwrap();
            assert_eq!(win.publish(&frame, 100 * k).unwrap(), k as u32 + 1);
            let i = reference.begin_write();
            reference.buffer_mut(i).copy_from_slice(&frame);
            reference.publish(i, 100 * k);
        }
        let mut file = vec![0u8; WINDOW_LEN];
        SharedRam::open_read_only(&path)
            .unwrap()
            .read_at(FRAME_WINDOW_OFFSET, &mut file)
            .unwrap();
        assert_eq!(file, mem);
        let back = read_window_frame(&path).unwrap();
        assert_eq!((back.ticket.sequence, back.ticket.capture_us), (3, 200));
        assert_eq!(back.pixels, frame);
        let d = back.detect().unwrap();
        assert!(d.blobs().len() >= 3, "{d:?}");
        assert!(matches!(
            win.publish(&frame[1..], 0),
            Err(FeedError::FrameSize { .. })
        ));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn finds_ram_files_of_live_runs_only() {
        let base = tempfile_dir();
        assert!(matches!(
            find_car_ram(3, Some(&base.join("nope"))),
            Err(FindError::NoRunDir { .. })
        ));
        assert!(matches!(
            find_car_ram(3, Some(&base)),
            Err(FindError::NoCarInRun { car: 3, .. })
        ));
        std::fs::write(base.join(ram_file_name(3)), b"x").unwrap();
        assert_eq!(find_car_ram(3, Some(&base)).unwrap(), base.join("car3-ram"));
        // A world directory of this (live) process, and one of a process that cannot exist.
        let tmp = std::env::temp_dir();
        let live = tmp.join(format!("{RUN_DIR_PREFIX}{}-9999", std::process::id()));
        let dead = tmp.join(format!("{RUN_DIR_PREFIX}4294967295-0"));
        for d in [&live, &dead] {
            std::fs::create_dir_all(d).unwrap();
            std::fs::write(d.join(ram_file_name(125)), b"x").unwrap();
        }
        assert_eq!(find_car_ram(125, None).unwrap(), live.join("car125-ram"));
        std::fs::remove_dir_all(&live).unwrap();
        let err = find_car_ram(125, None).unwrap_err();
        assert!(
            matches!(err, FindError::NoneRunning { car: 125, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("almc-arena-*/car125-ram"), "{err}");
        let _ = std::fs::remove_dir_all(&dead);
        let _ = std::fs::remove_dir_all(&base);
    }

    fn tempfile_dir() -> PathBuf {
        let d = std::env::temp_dir().join(format!(
            "arena-camera-feed-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    static NEXT: AtomicU64 = AtomicU64::new(0);
}
