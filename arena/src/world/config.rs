//! What configures a world, and why one cannot start or answer.

use crate::camera_feed::FeedConfig;
use crate::engine::iss::IssError;
use crate::engine::qemu::QemuEngineError;
use crate::radio_medium::MediumParams;
use lbc_emu::{FaultConfig, Pose};
use qemu_harness::{firmware_elf, softcore_elf};
use std::fmt;
use std::io;
use std::path::PathBuf;
use std::time::Duration;

/// Default quantum: cars and world meet every 100 us of world time (about one UART
/// character at 115200 baud).
pub const DEFAULT_QUANTUM: Duration = Duration::from_micros(100);

/// What runs the cars' firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EngineKind {
    /// The soft core's cycle-accurate model, in virtual time (`softcore` firmware builds).
    #[default]
    Iss,
    /// QEMU in wall-clock time (`qemu_virt` firmware builds).
    Qemu,
}

impl EngineKind {
    /// `"iss"` or `"qemu"`.
    pub fn name(self) -> &'static str {
        match self {
            EngineKind::Iss => "iss",
            EngineKind::Qemu => "qemu",
        }
    }

    /// Parses `"iss"` or `"qemu"`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "iss" => Some(EngineKind::Iss),
            "qemu" => Some(EngineKind::Qemu),
            _ => None,
        }
    }

    /// The firmware this engine runs, as built by `cargo xtask fw` (or given by
    /// `VTB_FIRMWARE` / `UBC_FW_ELF`).
    pub fn default_firmware(self) -> Result<PathBuf, qemu_harness::Error> {
        match self {
            EngineKind::Iss => softcore_elf(),
            EngineKind::Qemu => firmware_elf(),
        }
    }

    /// The board this engine's firmware is built for.
    pub fn board(self) -> &'static str {
        match self {
            EngineKind::Iss => "softcore",
            EngineKind::Qemu => "qemu_virt",
        }
    }

    /// Program `name` (a firmware binary, `cargo xtask new-program`) built for this engine's
    /// board.
    pub fn program_firmware(self, name: &str) -> Result<PathBuf, qemu_harness::Error> {
        qemu_harness::program_elf(self.board(), name)
    }
}

/// One car of the world.
#[derive(Debug, Clone, PartialEq)]
pub struct CarSpec {
    /// Car ID (1..=126), written to EEPROM register 0x00.
    pub id: u8,
    /// Start pose (mm, mm, rad counter-clockwise from +X).
    pub start: Pose,
    /// This car's firmware ELF, when it differs from [`WorldConfig::firmware`].
    pub firmware: Option<PathBuf>,
    /// The radio channel the car's module is set to (0..=[`MAX_RADIO_CHANNEL`]): cars on
    /// different channels neither hear nor disturb each other, and each channel in use has a
    /// ground station of its own.
    pub radio_channel: u8,
}

/// Highest radio channel number.
pub const MAX_RADIO_CHANNEL: u8 = 15;

impl CarSpec {
    /// Car `id` at `start` with the world's firmware, on radio channel 0.
    pub fn new(id: u8, start: Pose) -> Self {
        CarSpec {
            id,
            start,
            firmware: None,
            radio_channel: 0,
        }
    }
}

/// The overhead tracker's imperfections.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingParams {
    /// Broadcast rate, Hz.
    pub rate_hz: f64,
    /// Standard deviation of the position noise, mm.
    pub noise_mm: f64,
    /// Standard deviation of the heading noise, mrad.
    pub heading_noise_mrad: f64,
    /// Delay from measuring a pose to the LBC receiving it.
    pub latency: Duration,
    /// Probability that one car's fix is lost.
    pub drop: f64,
}

impl Default for TrackingParams {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            noise_mm: 0.0,
            heading_noise_mrad: 0.0,
            latency: Duration::from_millis(10),
            drop: 0.0,
        }
    }
}

/// Everything that configures a world.
#[derive(Debug, Clone)]
pub struct WorldConfig {
    /// The firmware ELF of every car without its own (a `softcore` build for
    /// [`EngineKind::Iss`], a `qemu_virt` build for [`EngineKind::Qemu`]).
    pub firmware: PathBuf,
    /// The cars.
    pub cars: Vec<CarSpec>,
    /// The tracker.
    pub tracking: TrackingParams,
    /// The radio channel.
    pub radio: MediumParams,
    /// LBC link faults, applied to every car.
    pub lbc_faults: FaultConfig,
    /// Seed of every random source.
    pub seed: u64,
    /// The command key shared by the ground station and the firmware.
    pub key: [u8; 16],
    /// How long to wait for each QEMU firmware's banner.
    pub boot_timeout: Duration,
    /// Camera frames into every car's frame grabber; `None`: no camera.
    pub camera: Option<FeedConfig>,
    /// What runs the firmware.
    pub engine: EngineKind,
    /// Threads stepping the cars (virtual-time engine); the result does not depend on it.
    pub threads: usize,
    /// Pace world time to the wall clock (always so with QEMU), and open a radio node for
    /// `almc car` at `<run dir>/ground.sock`.
    pub realtime: bool,
    /// How much world time passes between two meetings of the cars and the world.
    pub quantum: Duration,
    /// Stop a car's vehicle (as an emergency stop would) when its firmware stops running.
    pub stop_failed_cars: bool,
    /// Cars whose processor time is profiled by function (virtual-time engine).
    pub profile_cars: Vec<u8>,
}

impl WorldConfig {
    /// A world of `cars` with default tracking, radio, no faults, on the virtual-time engine.
    pub fn new(firmware: impl Into<PathBuf>, cars: Vec<CarSpec>) -> Self {
        Self {
            firmware: firmware.into(),
            cars,
            tracking: TrackingParams::default(),
            radio: MediumParams::default(),
            lbc_faults: FaultConfig::default(),
            seed: 1,
            key: ubc_app::program::DEFAULT_KEY,
            boot_timeout: Duration::from_secs(30),
            camera: None,
            engine: EngineKind::Iss,
            threads: 1,
            realtime: false,
            quantum: DEFAULT_QUANTUM,
            stop_failed_cars: true,
            profile_cars: Vec::new(),
        }
    }
}

/// Why the world could not start or answer.
#[derive(Debug)]
pub enum WorldError {
    /// No cars, a car ID outside 1..=126, or one ID twice.
    BadCar { id: u8 },
    /// A car's radio channel is above [`MAX_RADIO_CHANNEL`].
    BadChannel { id: u8, channel: u8 },
    /// A socket, file or directory of the run.
    Io(io::Error),
    /// The virtual-time engine could not start.
    Iss(IssError),
    /// QEMU could not start.
    Qemu(QemuEngineError),
    /// The quantum is zero or longer than 10 ms.
    BadQuantum(Duration),
    /// The console request could not be encoded.
    Encode(ubc_app::program::console::EncodeError),
    /// The ground station refused the request.
    Send(radio_mac::SendError),
    /// The reply did not decode.
    BadReply(ubc_app::program::console::DecodeError),
    /// No reply after every retransmission.
    NoReply { id: u8 },
    /// No reply within the time asked for.
    Timeout { id: u8 },
}

impl fmt::Display for WorldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            WorldError::BadCar { id: 0 } => write!(f, "the world needs at least one car"),
            WorldError::BadCar { id } => {
                write!(f, "car ID {id} is outside 1..=126 or appears twice")
            }
            WorldError::BadChannel { id, channel } => write!(
                f,
                "car {id}: radio channel {channel} is outside 0..={MAX_RADIO_CHANNEL}"
            ),
            WorldError::Io(e) => write!(f, "{e}"),
            WorldError::Iss(e) => write!(f, "{e}"),
            WorldError::Qemu(e) => write!(f, "{e}"),
            WorldError::BadQuantum(q) => {
                write!(f, "quantum {q:?} is outside (0, 10 ms]")
            }
            WorldError::Encode(e) => write!(f, "cannot encode the request: {e:?}"),
            WorldError::Send(e) => write!(f, "the ground station cannot send: {e:?}"),
            WorldError::BadReply(e) => write!(f, "the reply does not decode: {e:?}"),
            WorldError::NoReply { id } => write!(f, "car {id} did not answer"),
            WorldError::Timeout { id } => write!(f, "car {id} did not answer in time"),
        }
    }
}

impl std::error::Error for WorldError {}

impl From<io::Error> for WorldError {
    fn from(e: io::Error) -> Self {
        WorldError::Io(e)
    }
}
