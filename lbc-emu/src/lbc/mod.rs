//! The emulated lower board controller: a sans-IO core stepped by the caller's clock.
//!
//! [`Lbc`] holds the car ([`Vehicle`]), the EEPROM, the UART and the firmware state, and runs
//! the firmware's periodic tasks (seed Table 2-2) at their rates as time advances. Nothing in
//! here reads a clock or touches a socket: the real-time server and lockstep simulations both
//! drive it through [`Lbc::push_rx`], [`Lbc::step_until`] and [`Lbc::pop_tx`] (or [`Lbc::poll`]).
//!
//! Every behaviour the seed leaves open is documented in docs/lbc-emulator.md.

use std::collections::VecDeque;
use std::fmt;

use lbc_link::lbc::Ignored;
use lbc_link::{
    ChipStatus, ChipTemperature, Command, CommandKind, CommandParser, EepromAddress, GpioPattern,
    GyroOffsets, GyroRaw, Heading, Incoming, LbcMessage, LedPattern, Param, ParamValue, Position,
    Reply, SteerVelocity, SteeringAngle, SteeringCalibration, StreamData, StreamFormat,
    StreamSample, VehicleId, Velocity, Warnings, XCoord, YCoord, I14, I28, MAX_FRAME_LEN, U14,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::control::{
    self, mm_per_count, path_step, servo_pulse_us, steer_from_lp, MotorGains, PathConfig,
    PathPhase, VelocityEstimator, VelocityPid, PWM_FULL, STANDSTILL_MM_S, STEER_LIMIT_MRAD,
    VELOCITY_LIMIT_MM_S,
};
use crate::eeprom::{reg, EepromImage, EepromStore, MemoryStore};
use crate::faults::{FaultConfig, FaultInjector, FaultStats};
use crate::scheduler::{Scheduler, Task};
use crate::uart::UartTx;
use crate::vehicle::{wrap_2pi, Actuators, AdcSample, Pose, Vehicle, VehicleConfig};

mod commands;
mod tasks;
mod values;

use values::*;

/// Battery warning threshold, V (seed 2.1.12: internal reference 4.54 V).
pub const BATTERY_WARN_V: f64 = 4.54;
/// Die temperature warning threshold, degrees C.
pub const TEMP_WARN_C: f64 = 65.0;
/// Depth of the EEPROM task's job queue.
pub const EEPROM_QUEUE: usize = 8;
/// Interval of the internal tracker when the vehicle model provides the pose, us (30 Hz).
pub const MODEL_TRACKING_PERIOD_US: u64 = 33_333;
/// ADC samples averaged by CALB_GS (0.5 s at 500 Hz).
pub const GYRO_CAL_SAMPLES: u32 = 250;
/// Servo pulse step used by CALB_ST either side of centre, us.
pub const STEER_CAL_STEP_US: f64 = 200.0;
/// Settling time of each CALB_ST step, us.
pub const STEER_CAL_SETTLE_US: u64 = 300_000;
/// Default streaming format: ID, X/Y, steering/velocity, adjusted yaw, heading.
pub const DEFAULT_STREAM_FORMAT: u32 = 0x1F;

/// Where poses come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct TrackingConfig {
    /// An external pose older than this is stale, us.
    pub stale_after_us: u64,
    /// Without a fresh external pose, use the vehicle model's pose (sampled at 30 Hz) as if the
    /// overhead tracker had sent it. When false, there is no pose: READ_XY / READ_HD answer
    /// with their errors and MOVE_XY holds the car still.
    pub fallback_to_model: bool,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self {
            stale_after_us: 200_000,
            fallback_to_model: true,
        }
    }
}

/// Everything that configures one emulated LBC.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct LbcConfig {
    /// The car's physical truth.
    pub vehicle: VehicleConfig,
    /// Where the car stands at power-up.
    pub start_pose: Pose,
    /// MOVE_XY path generator tuning.
    pub path: PathConfig,
    /// Tracking input.
    pub tracking: TrackingConfig,
    /// Link faults.
    pub faults: FaultConfig,
    /// Seed of every random source (sensor noise, faults).
    pub seed: u64,
    /// Record [`LogEvent`]s for [`Lbc::take_log`].
    pub log: bool,
    /// Time from a spontaneous reset until the firmware runs again, us.
    pub boot_time_us: u64,
}

impl Default for LbcConfig {
    fn default() -> Self {
        Self {
            vehicle: VehicleConfig::default(),
            start_pose: Pose {
                x_mm: 750.0,
                y_mm: 1000.0,
                heading_rad: core::f64::consts::FRAC_PI_2,
            },
            path: PathConfig::default(),
            tracking: TrackingConfig::default(),
            faults: FaultConfig::default(),
            seed: 0,
            log: false,
            boot_time_us: 50_000,
        }
    }
}

/// Which source the tracking receiver is using.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PoseSource {
    /// A fresh pose given to [`Lbc::set_tracked_pose`].
    External,
    /// The vehicle model.
    Model,
    /// None (external pose stale and no fallback).
    None,
}

/// One thing the LBC did, for `--log` and tests.
#[derive(Debug, Clone, PartialEq)]
pub enum LogEvent {
    /// A command was received and decoded.
    Command(Command),
    /// A message was received but not accepted as a command; this is the answer.
    Rejected(LbcMessage),
    /// Received bytes that get no answer (framing noise, general-error messages).
    Ignored(Ignored),
    /// A reply or error left for the UART (STREAM frames are not logged).
    Sent(LbcMessage),
    /// A reply or STREAM frame was discarded by fault injection.
    Suppressed(LbcMessage),
    /// The LBC restarted (INIT is logged as a command instead).
    Reset,
    /// The world cut the drive (the upper board died).
    EmergencyStop,
}

impl fmt::Display for LogEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogEvent::Command(c) => write!(f, "<- {}", describe_command(c)),
            LogEvent::Rejected(m) => write!(f, "<- not accepted, answering {}", describe(m)),
            LogEvent::Ignored(why) => write!(f, "<- ignored: {why:?}"),
            LogEvent::Sent(m) => write!(f, "-> {}", describe(m)),
            LogEvent::Suppressed(m) => write!(f, "-x suppressed {}", describe(m)),
            LogEvent::Reset => write!(f, "** spontaneous reset"),
            LogEvent::EmergencyStop => write!(f, "** emergency stop"),
        }
    }
}

fn describe_command(c: &Command) -> String {
    match Command::without_data(c.kind()) {
        Some(_) => c.kind().to_string(),
        None => format!("{} {c:?}", c.kind()),
    }
}

fn describe(m: &LbcMessage) -> String {
    match m {
        LbcMessage::Reply(Reply::Echo(c)) => format!("{} (ack)", describe_command(c)),
        LbcMessage::Reply(r) => format!("{} {r:?}", r.kind()),
        LbcMessage::Error(k) => format!("{k} error ({:#04x})", k.error_header()),
        LbcMessage::UnknownCommand(Some(e)) => {
            format!(
                "UNKCMD echoing {:#04x} {:02x?}",
                e.header,
                e.data.as_slice()
            )
        }
        LbcMessage::UnknownCommand(None) => "UNKCMD".to_owned(),
        LbcMessage::ChecksumError => "CSER".to_owned(),
        LbcMessage::Stream(d) => format!("STREAM {} bytes", d.0.len()),
    }
}

/// A log event with its time.
#[derive(Debug, Clone, PartialEq)]
pub struct LogEntry {
    /// Emulator time, us.
    pub t_us: u64,
    /// What happened.
    pub event: LogEvent,
}

/// Link counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LbcStats {
    /// Bytes received (after receive-side faults).
    pub rx_bytes: u64,
    /// Bytes that left the UART.
    pub tx_bytes: u64,
    /// Commands decoded.
    pub commands: u64,
    /// Positive replies queued.
    pub replies: u64,
    /// Specific errors queued.
    pub errors: u64,
    /// CSER messages queued.
    pub cser: u64,
    /// UNKCMD messages queued.
    pub unkcmd: u64,
    /// STREAM frames queued.
    pub stream_frames: u64,
    /// Messages dropped because the UART queue was full.
    pub tx_overflow: u64,
    /// Resets (spontaneous; INIT not counted).
    pub resets: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct TrackFix {
    t_us: u64,
    x_units: f64,
    y_units: f64,
    heading_rad: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    Idle,
    Velocity {
        steer_mrad: f64,
        v_mm_s: f64,
    },
    GoTo {
        target: Position,
        phase: PathPhase,
        arrived: bool,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Calibration {
    Steering {
        second: bool,
        until_us: u64,
        first_mrad: f64,
    },
    Drive {
        duty: f64,
        start_count: i64,
    },
    Gyro {
        n: u32,
        sums: [f64; 3],
    },
}

impl Calibration {
    fn kind(&self) -> CommandKind {
        match self {
            Calibration::Steering { .. } => CommandKind::CalbSt,
            Calibration::Drive { .. } => CommandKind::CalbDm,
            Calibration::Gyro { .. } => CommandKind::CalbGs,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum EepromJob {
    Write(Command),
    Read(EepromAddress),
    Commit,
    Restore,
}

/// Firmware state that INIT and resets re-initialise.
#[derive(Debug, Clone)]
struct Firmware {
    car_id: u8,
    params: [i16; 12],
    calib: [u16; 8],
    drive_enabled: bool,
    motion: Motion,
    calibration: Option<Calibration>,
    target_v: f64,
    target_steer_mrad: f64,
    servo_pulse_us: f64,
    duty_permille: f64,
    pid: VelocityPid,
    estimator: VelocityEstimator,
    tracked: Option<TrackFix>,
    pose_source: PoseSource,
    next_model_fix_us: u64,
    adc: AdcSample,
    yaw_rad: f64,
    prev_omega: Option<f64>,
    stream_on: bool,
    stream_format: StreamFormat,
    warnings: Warnings,
    leds: [LedPattern; 2],
    gpio: [GpioPattern; 2],
    led_out: [bool; 2],
    gpio_out: [bool; 2],
    pattern_epoch_us: u64,
    eeprom_jobs: VecDeque<EepromJob>,
    target_bearing: Option<f64>,
}

/// The emulated LBC.
pub struct Lbc {
    cfg: LbcConfig,
    now_us: u64,
    phys_us: u64,
    vehicle: Vehicle,
    image: EepromImage,
    store: Box<dyn EepromStore>,
    noise: ChaCha8Rng,
    faults: FaultInjector,
    uart: UartTx,
    rx: VecDeque<(u64, u8)>,
    parser: CommandParser,
    outbox: VecDeque<LbcMessage>,
    fw: Firmware,
    sched: Scheduler,
    booting_until: Option<u64>,
    external: Option<TrackFix>,
    user_vars: [u16; 6],
    log: Vec<LogEntry>,
    stats: LbcStats,
    task_buf: Vec<Task>,
}

impl fmt::Debug for Lbc {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Lbc")
            .field("now_us", &self.now_us)
            .field("car_id", &self.fw.car_id)
            .field("drive_enabled", &self.fw.drive_enabled)
            .field("motion", &self.fw.motion)
            .field("stream_on", &self.fw.stream_on)
            .field("pose", &self.vehicle.pose())
            .finish_non_exhaustive()
    }
}

impl Lbc {
    /// Powers up an LBC at time 0 with the EEPROM content `image`, committing to `store`.
    pub fn new(cfg: LbcConfig, image: EepromImage, store: Box<dyn EepromStore>) -> Self {
        let vehicle = Vehicle::new(cfg.vehicle.clone(), cfg.start_pose);
        let faults = FaultInjector::new(cfg.faults, cfg.seed);
        let noise = ChaCha8Rng::seed_from_u64(cfg.seed);
        let fw = Firmware::boot(&image, 0, &vehicle);
        Self {
            cfg,
            now_us: 0,
            phys_us: 0,
            vehicle,
            image,
            store,
            noise,
            faults,
            uart: UartTx::new(),
            rx: VecDeque::new(),
            parser: CommandParser::new(),
            outbox: VecDeque::new(),
            fw,
            sched: Scheduler::new(0),
            booting_until: None,
            external: None,
            user_vars: [0; 6],
            log: Vec::new(),
            stats: LbcStats::default(),
            task_buf: Vec::with_capacity(Task::ALL.len()),
        }
    }

    /// An LBC with factory EEPROM content for `car_id`, kept in memory.
    pub fn with_memory_eeprom(cfg: LbcConfig, car_id: u8) -> Self {
        Self::new(
            cfg,
            EepromImage::factory(car_id),
            Box::new(MemoryStore::default()),
        )
    }

    // ----- time and bytes -------------------------------------------------------------------

    /// Current emulator time, us.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// Bytes from the UBC that arrived at `t_us` (times before [`Lbc::now_us`] count as now;
    /// successive calls must not go back in time). Bytes arriving while the LBC boots are lost.
    pub fn push_rx(&mut self, t_us: u64, bytes: &[u8]) {
        let t = t_us.max(self.now_us);
        if self.booting_until.is_some_and(|b| t < b) {
            // The UART is not running while the firmware boots.
            return;
        }
        for &b in bytes {
            if let Some(b) = self.faults.byte(b) {
                self.rx.push_back((t, b));
                self.stats.rx_bytes += 1;
            }
        }
    }

    /// The other end of the UART changed (a client left or another one attached): the bytes
    /// already received are parsed now, and a message left unfinished is dropped, so that the
    /// next sender starts on a clean line instead of completing someone else's half frame.
    pub fn line_break(&mut self) {
        self.parse_rx(u64::MAX);
        self.parser = CommandParser::new();
    }

    /// Runs the firmware and the physics up to `t_us`.
    pub fn step_until(&mut self, t_us: u64) {
        loop {
            let next_reset = self.faults.next_reset_us().unwrap_or(u64::MAX);
            let next_task = match self.booting_until {
                Some(b) => b,
                None => self.sched.next_release_us(),
            };
            let next = next_reset.min(next_task);
            if next > t_us {
                break;
            }
            self.advance_physics(next);
            self.now_us = next;
            if next_reset <= next_task {
                self.faults.reset_taken(next);
                self.spontaneous_reset();
                continue;
            }
            if let Some(b) = self.booting_until {
                if b <= next {
                    self.booting_until = None;
                    self.sched = Scheduler::new(next);
                    self.boot_firmware();
                }
                continue;
            }
            let mut tasks = std::mem::take(&mut self.task_buf);
            if self.sched.release(next, &mut tasks).is_some() {
                for &task in &tasks {
                    self.run_task(task);
                }
            }
            self.task_buf = tasks;
        }
        self.advance_physics(t_us);
        self.now_us = self.now_us.max(t_us);
    }

    /// Next byte that has completely left the UART by `until_us`, with its arrival time at the
    /// UBC.
    pub fn pop_tx(&mut self, until_us: u64) -> Option<(u64, u8)> {
        let r = self.uart.pop(until_us);
        if r.is_some() {
            self.stats.tx_bytes += 1;
        }
        r
    }

    /// Appends every byte that has left the UART by `until_us` to `out`.
    pub fn drain_tx(&mut self, until_us: u64, out: &mut Vec<u8>) {
        while let Some((_, b)) = self.pop_tx(until_us) {
            out.push(b);
        }
    }

    /// When the next byte will have left the UART, if any is queued.
    pub fn next_tx_us(&self) -> Option<u64> {
        self.uart.next_departure_us()
    }

    /// Convenience for real-time callers: `bytes_in` arrived at `now_us`; runs up to `now_us`
    /// and appends what the UART has sent by then to `bytes_out`.
    pub fn poll(&mut self, now_us: u64, bytes_in: &[u8], bytes_out: &mut Vec<u8>) {
        self.push_rx(now_us, bytes_in);
        self.step_until(now_us);
        self.drain_tx(now_us, bytes_out);
    }

    // ----- world input ------------------------------------------------------------------------

    /// An overhead tracking fix received at `t_us`: position in tracking units, heading in mrad.
    pub fn set_tracked_pose(&mut self, t_us: u64, x: u16, y: u16, heading_mrad: u16) {
        self.external = Some(TrackFix {
            t_us,
            x_units: f64::from(x),
            y_units: f64::from(y),
            heading_rad: f64::from(heading_mrad.min(6283)) / 1000.0,
        });
    }

    /// Sets user variable `index` (1..=6) streamed as variables 22..=27; other indices are ignored.
    pub fn set_user_var(&mut self, index: usize, value: u16) {
        if let Some(v) = index.checked_sub(1).and_then(|i| self.user_vars.get_mut(i)) {
            *v = value & 0x3FFF;
        }
    }

    /// The car.
    pub fn vehicle(&self) -> &Vehicle {
        &self.vehicle
    }

    /// The car, for placing it or changing its environment.
    pub fn vehicle_mut(&mut self) -> &mut Vehicle {
        &mut self.vehicle
    }

    /// Restarts the LBC as after a power glitch (what spontaneous-reset faults do).
    pub fn reset(&mut self) {
        self.spontaneous_reset();
    }

    /// Cuts the drive as a lab's emergency stop does when the upper board dies: the drive is
    /// disabled and every motion target dropped, so the vehicle rolls to a stop; the LBC keeps
    /// answering commands (a later DREN would drive again).
    pub fn emergency_stop(&mut self) {
        self.abort_calibration();
        self.fw.drive_enabled = false;
        self.fw.motion = Motion::Idle;
        self.fw.target_v = 0.0;
        self.log(LogEvent::EmergencyStop);
    }

    // ----- observation ------------------------------------------------------------------------

    /// The configuration.
    pub fn config(&self) -> &LbcConfig {
        &self.cfg
    }

    /// The committed EEPROM content.
    pub fn eeprom(&self) -> &EepromImage {
        &self.image
    }

    /// Current value of control parameter `p`.
    pub fn param(&self, p: Param) -> i16 {
        self.fw.params[usize::from(p.number() - 1)]
    }

    /// Current value of calibration register `addr` (0x10..=0x17).
    pub fn calibration_register(&self, addr: u8) -> Option<u16> {
        let i = usize::from(addr.checked_sub(reg::GPO)?);
        self.fw.calib.get(i).copied()
    }

    /// Whether DREN is in force.
    pub fn drive_enabled(&self) -> bool {
        self.fw.drive_enabled
    }

    /// Whether STREAM frames are being sent.
    pub fn streaming(&self) -> bool {
        self.fw.stream_on
    }

    /// The streaming format in force.
    pub fn stream_format(&self) -> StreamFormat {
        self.fw.stream_format
    }

    /// Target velocity (mm/s) and steering (mrad) the path generator currently asks for.
    pub fn targets(&self) -> (f64, f64) {
        (self.fw.target_v, self.fw.target_steer_mrad)
    }

    /// What the firmware drives now: PWM in per mille (0 while the drive is disabled) and the
    /// servo pulse in us (`None` while the servo is disabled).
    pub fn drive_output(&self) -> (f64, Option<f64>) {
        let a = self.actuators();
        (a.duty * PWM_FULL, a.servo_pulse_us)
    }

    /// Estimated velocity, mm/s.
    pub fn velocity_estimate_mm_s(&self) -> f64 {
        self.fw.estimator.estimate_mm_s()
    }

    /// Whether a MOVE_XY target has been reached (`None` when no MOVE_XY is active).
    pub fn arrived(&self) -> Option<bool> {
        match self.fw.motion {
            Motion::GoTo { arrived, .. } => Some(arrived),
            _ => None,
        }
    }

    /// The tracked position (units) and heading (rad) the firmware uses, if any.
    pub fn tracked_pose(&self) -> Option<(f64, f64, f64)> {
        self.fw
            .tracked
            .map(|t| (t.x_units, t.y_units, t.heading_rad))
    }

    /// Where the tracking receiver's pose comes from.
    pub fn pose_source(&self) -> PoseSource {
        self.fw.pose_source
    }

    /// Gyro-integrated yaw, rad in `0..2*PI`.
    pub fn yaw_rad(&self) -> f64 {
        wrap_2pi(self.fw.yaw_rad)
    }

    /// LED patterns (green, red) and their present output levels.
    pub fn leds(&self) -> ([LedPattern; 2], [bool; 2]) {
        (self.fw.leds, self.fw.led_out)
    }

    /// GPIO patterns (GPIO0, GPIO1) and their present output levels.
    pub fn gpio(&self) -> ([GpioPattern; 2], [bool; 2]) {
        (self.fw.gpio, self.fw.gpio_out)
    }

    /// Warnings as last evaluated by the 1 Hz monitor.
    pub fn warnings(&self) -> Warnings {
        self.fw.warnings
    }

    /// Whether the firmware is restarting after a reset.
    pub fn booting(&self) -> bool {
        self.booting_until.is_some()
    }

    /// Link counters.
    pub fn stats(&self) -> LbcStats {
        LbcStats {
            tx_overflow: self.uart.dropped_messages(),
            ..self.stats
        }
    }

    /// Fault counters.
    pub fn fault_stats(&self) -> FaultStats {
        self.faults.stats()
    }

    /// Receive-side framing counters.
    pub fn deframer_stats(&self) -> lbc_link::DeframerStats {
        *self.parser.stats()
    }

    /// Takes the log recorded since the last call (empty unless [`LbcConfig::log`]).
    pub fn take_log(&mut self) -> Vec<LogEntry> {
        std::mem::take(&mut self.log)
    }

    // ----- internals --------------------------------------------------------------------------

    fn log(&mut self, event: LogEvent) {
        if self.cfg.log {
            self.log.push(LogEntry {
                t_us: self.now_us,
                event,
            });
        }
    }

    fn actuators(&self) -> Actuators {
        if self.fw.drive_enabled && self.booting_until.is_none() {
            Actuators {
                duty: self.fw.duty_permille / PWM_FULL,
                servo_pulse_us: Some(self.fw.servo_pulse_us),
            }
        } else {
            Actuators::default()
        }
    }

    fn advance_physics(&mut self, to_us: u64) {
        while self.phys_us < to_us {
            let dt = (to_us - self.phys_us).min(1000);
            let act = self.actuators();
            self.vehicle.step(dt as f64 * 1e-6, act);
            self.phys_us += dt;
        }
    }

    fn spontaneous_reset(&mut self) {
        self.stats.resets += 1;
        self.log(LogEvent::Reset);
        self.uart.clear();
        self.rx.clear();
        self.parser = CommandParser::new();
        self.outbox.clear();
        self.fw.drive_enabled = false;
        self.fw.stream_on = false;
        self.booting_until = Some(self.now_us + self.cfg.boot_time_us.max(1));
    }

    fn send(&mut self, msg: LbcMessage) {
        match &msg {
            LbcMessage::Reply(_) => self.stats.replies += 1,
            LbcMessage::Error(_) => self.stats.errors += 1,
            LbcMessage::UnknownCommand(_) => self.stats.unkcmd += 1,
            LbcMessage::ChecksumError => self.stats.cser += 1,
            LbcMessage::Stream(_) => self.stats.stream_frames += 1,
        }
        self.outbox.push_back(msg);
    }

    fn reply(&mut self, r: Reply) {
        self.send(LbcMessage::Reply(r));
    }

    fn error(&mut self, kind: CommandKind) {
        self.send(LbcMessage::Error(kind));
    }

    fn run_task(&mut self, task: Task) {
        match task {
            Task::VelocityControl => self.task_velocity_control(),
            Task::VelocityEstimation => self.task_velocity_estimation(),
            Task::TrackingReceiver => self.task_tracking(),
            Task::AdcSampling => self.task_adc(),
            Task::PathGeneration => self.task_path(),
            Task::CommParser => self.task_comm_parser(),
            Task::CommMerger => self.task_comm_merger(),
            Task::Eeprom => self.task_eeprom(),
            Task::DataStreaming => self.task_streaming(),
            Task::Monitor => self.task_monitor(),
            Task::Led => self.task_led(),
            Task::Gpio => self.task_gpio(),
        }
    }

    /// Re-initialises the firmware state from the EEPROM (power-up, reset, INIT). The adjusted
    /// yaw starts at the heading known now: a fresh external fix, else the vehicle model's.
    fn boot_firmware(&mut self) {
        self.fw = Firmware::boot(&self.image, self.now_us, &self.vehicle);
        if let Some(e) = self.fresh_external() {
            self.fw.yaw_rad = e.heading_rad;
        }
    }

    fn fresh_external(&self) -> Option<TrackFix> {
        let now = self.now_us;
        self.external
            .filter(|e| now.saturating_sub(e.t_us) <= self.cfg.tracking.stale_after_us)
    }
}

impl Firmware {
    fn boot(image: &EepromImage, now_us: u64, vehicle: &Vehicle) -> Self {
        let (params, calib) = params_from_image(image).unwrap_or_else(|| {
            params_from_image(&EepromImage::factory(image.car_id())).unwrap_or(([0; 12], [0; 8]))
        });
        let led_off = LED_OFF;
        let gpio_off = GPIO_OFF;
        Self {
            car_id: image.car_id(),
            params,
            calib,
            drive_enabled: false,
            motion: Motion::Idle,
            calibration: None,
            target_v: 0.0,
            target_steer_mrad: 0.0,
            servo_pulse_us: servo_pulse_us(0.0, params[6], params[7]),
            duty_permille: 0.0,
            pid: VelocityPid::default(),
            estimator: VelocityEstimator::default(),
            tracked: None,
            pose_source: PoseSource::None,
            next_model_fix_us: now_us,
            adc: AdcSample::default(),
            yaw_rad: vehicle.pose().heading_rad,
            prev_omega: None,
            stream_on: false,
            stream_format: StreamFormat::new(DEFAULT_STREAM_FORMAT).unwrap_or(StreamFormat::EMPTY),
            warnings: Warnings::default(),
            leds: [led_off; 2],
            gpio: [gpio_off; 2],
            led_out: [false; 2],
            gpio_out: [false; 2],
            pattern_epoch_us: now_us,
            eeprom_jobs: VecDeque::new(),
            target_bearing: None,
        }
    }
}

fn model_fix(v: &Vehicle, now_us: u64) -> TrackFix {
    let p = v.pose();
    TrackFix {
        t_us: now_us,
        x_units: (p.x_mm / 2.5).round(),
        y_units: (p.y_mm / 2.5).round(),
        heading_rad: (p.heading_rad * 1000.0).round() / 1000.0,
    }
}

/// Whether `value` is acceptable for `param` (beyond its wire width); docs/lbc-emulator.md.
pub fn param_valid(param: Param, value: i16) -> bool {
    let (min, max) = param.range();
    if value < min || value > max {
        return false;
    }
    match param {
        Param::MotorEncoderRatio | Param::MotorGearRatio => value >= 1,
        Param::MotorDeadBand => value <= 1000,
        Param::ServoOffset => (-500..=500).contains(&value),
        Param::ServoGain => value != 0,
        Param::ServoDeadBand => value <= 500,
        _ => true,
    }
}

/// Control parameters (registers 0x04..=0x0F) and calibration (0x10..=0x17) from an image;
/// `None` if a parameter register holds a value that is not valid for its parameter.
fn params_from_image(image: &EepromImage) -> Option<([i16; 12], [u16; 8])> {
    let mut params = [0i16; 12];
    for (slot, p) in params.iter_mut().zip(Param::ALL) {
        let v = image.get(p.eeprom_address().get())? as i16;
        if !param_valid(p, v) {
            return None;
        }
        *slot = v;
    }
    let mut calib = [0u16; 8];
    for (i, slot) in calib.iter_mut().enumerate() {
        *slot = image.get(reg::GPO + i as u8)?;
    }
    Some((params, calib))
}

/// Index into the calibration block (registers 0x10..=0x17).
const fn calib_index(addr: u8) -> usize {
    (addr - reg::GPO) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_ranges() {
        assert!(param_valid(Param::MotorEncoderRatio, 1));
        assert!(!param_valid(Param::MotorEncoderRatio, 0));
        assert!(!param_valid(Param::MotorPGain, -1));
        assert!(param_valid(Param::ServoGain, -1));
        assert!(!param_valid(Param::ServoGain, 0));
        assert!(!param_valid(Param::ServoOffset, 501));
        assert!(param_valid(Param::ServoOffset, -500));
        assert!(!param_valid(Param::MotorDeadBand, 1001));
    }

    #[test]
    fn parameter_block_from_image() {
        let img = EepromImage::factory(4);
        let (params, calib) = params_from_image(&img).unwrap();
        assert_eq!(params[0], 800);
        assert_eq!(params[7], 1000);
        assert_eq!(calib[calib_index(reg::GYO)], 1504);
        let mut bad = img;
        bad.set(reg::SO, (-501i16) as u16);
        assert_eq!(params_from_image(&bad), None);
    }

    #[test]
    fn replies_dropped_by_a_full_uart_are_not_logged_as_sent() {
        let cfg = LbcConfig {
            log: true,
            ..LbcConfig::default()
        };
        let mut lbc = Lbc::with_memory_eeprom(cfg, 1);
        let mut buf = [0u8; 8];
        let n = Command::ReadId.emit(&mut buf).unwrap();
        // 2000 replies of 4 bytes do not fit the 4096-byte queue in one tick.
        let burst: Vec<u8> = buf[..n].repeat(2000);
        lbc.push_rx(0, &burst);
        lbc.step_until(2_000);
        let sent = lbc
            .take_log()
            .iter()
            .filter(|e| matches!(e.event, LogEvent::Sent(_)))
            .count() as u64;
        let stats = lbc.stats();
        assert_eq!(stats.replies, 2000);
        assert!(stats.tx_overflow > 0);
        assert_eq!(sent + stats.tx_overflow, stats.replies);
    }

    #[test]
    fn drive_output_is_off_until_dren() {
        let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 1);
        lbc.step_until(10_000);
        assert_eq!(lbc.drive_output(), (0.0, None));
        let mut buf = [0u8; 8];
        let n = Command::Dren.emit(&mut buf).unwrap();
        lbc.push_rx(10_000, &buf[..n]);
        lbc.step_until(30_000);
        assert_eq!(lbc.drive_output(), (0.0, Some(1500.0)));
    }
}
