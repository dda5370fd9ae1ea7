//! Board layer of the program (feature `firmware`): brings the board up, feeds the two UARTs'
//! interrupt-driven rings and the CLINT time to [`crate::program::Program`] (with a program
//! loop, [`crate::program::user::UserProgram`], when the binary has one), runs the vision
//! pipeline on each new camera frame and hands the program its detections, logs its events
//! through defmt and sleeps in WFI until the program's next deadline, a whole frame on either
//! line, the vision unit's next frame, or the next look at the frame grabber.
//!
//! Vision: where the board has a vision unit (the SoC's pixel pipeline, or on QEMU the host
//! writing the same run window), the firmware loads its class table, starts it, and builds
//! the blobs from each frame's runs (`vision::runs::blobs_from_runs`); otherwise it runs the
//! whole pipeline over the frame grabber's pixels (`vision::process_frame`). Both give the same
//! detections for the same frame.
//!
//! The processor's time is the car's budget: the UARTs' interrupts move bytes into rings
//! without waking the program, which runs when a frame from the LBC is complete, when a radio
//! frame has waited [`RADIO_BATCH_US`] (so a poll takes several of the many state broadcasts
//! of a fleet at once; the serial driver stamps each with its arrival, so its time is exact
//! however late it is read), when something is due, or when a ring fills up. A look at the
//! frame grabber that finds nothing new costs two word reads.
//!
//! Every firmware binary is a few lines on top of this: `src/main.rs` (the stock program)
//! and the programs in `src/bin/` (`cargo xtask new-program NAME`) call [`start`] from their
//! entry point and [`panic`] from their panic handler.

#[cfg(feature = "qemu_virt")]
pub use ubc_hal::boards::qemu_virt as board;

#[cfg(feature = "softcore")]
pub use ubc_hal::boards::softcore as board;

#[cfg(not(any(feature = "qemu_virt", feature = "softcore")))]
compile_error!("select a board with a cargo feature, e.g. `--features qemu_virt`");

use crate::program::user::UserProgram;
use crate::program::{self, BytePort, Config, LogEvent, LogSink, Program};
use board::{Board, Camera, Clock, Uart, Vision};
use core::sync::atomic::{AtomicBool, Ordering};
use ubc_hal::cpu;
use vision::blobs::BlobDetector;
use vision::colour::MARKER_CLASSES;
use vision::{process_frame, PipelineConfig};

/// Period of the liveness log line, in microseconds.
const STATS_PERIOD_US: u64 = 10_000_000;
/// How often the frame grabber is looked at, in microseconds (the camera publishes at 15 to
/// 30 frames per second; only the vision unit of the SoC raises an interrupt).
const CAMERA_POLL_US: u64 = 10_000;

/// Bytes waiting in a receive ring that wake the program even without a whole frame (noise
/// or a frame longer than any the protocols use), well before the ring fills.
const RX_WAKE_BYTES: usize = 1024;
/// Longest a whole radio frame waits before the program reads it, in microseconds: a quarter
/// of a 30 Hz period, far below any reply timeout, well within the serial driver's
/// [`ubc_hal::serial::FRAME_END_SLOTS`] stamps.
const RADIO_BATCH_US: u64 = 8_000;

struct BoardClock<'a>(&'a Clock);

impl program::Clock for BoardClock<'_> {
    fn now_us(&self) -> u64 {
        self.0.micros()
    }
}

/// A UART as the program's byte port; a missing one (no radio found) takes every byte and
/// never delivers any.
struct Port<'a>(Option<&'a mut Uart>, &'a Clock);

impl BytePort for Port<'_> {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        self.0.as_mut().map_or(0, |u| u.read_available(buf))
    }

    fn read_frame(&mut self, buf: &mut [u8]) -> (usize, Option<u64>) {
        match self.0.as_mut() {
            Some(u) => {
                let (n, tick) = u.read_frame(buf);
                (n, tick.map(|t| self.1.micros_of_recent(t)))
            }
            None => (0, None),
        }
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        self.0
            .as_mut()
            .map_or(bytes.len(), |u| u.write_available(bytes))
    }
}

struct Defmt;

impl LogSink for Defmt {
    fn log(&mut self, _now_us: u64, event: LogEvent) {
        // The logger stamps every line with the CLINT time already.
        match event {
            LogEvent::BringUpStarted { attempt } => {
                defmt::info!("lbc bring-up attempt {=u32}", attempt)
            }
            LogEvent::BringUpDone { car_id } => {
                defmt::info!("lbc up: car={=u8}", car_id)
            }
            LogEvent::BringUpFailed { step, retry_in_ms } => defmt::warn!(
                "lbc bring-up failed at step {=u8}, retry in {=u32} ms",
                step,
                retry_in_ms
            ),
            LogEvent::LbcLost => {
                defmt::warn!("lbc link lost: stop, bring up again")
            }
            LogEvent::LbcStateLost => {
                defmt::warn!("lbc refused motion with drive enabled: reset")
            }
            LogEvent::RadioStarted { car_id, keyed } => {
                defmt::info!("radio up: car={=u8} keyed={=bool}", car_id, keyed)
            }
            LogEvent::UserLinkLost => defmt::warn!("user link lost: stop"),
            LogEvent::UserLinkRestored => defmt::info!("user link restored"),
            LogEvent::Warnings {
                battery_low,
                over_temperature,
            } => defmt::warn!(
                "warnings: battery_low={=bool} over_temperature={=bool}",
                battery_low,
                over_temperature
            ),
            LogEvent::Console { tag, refused } => match refused {
                Some(code) => defmt::info!("console tag={=u8:#x} refused={=u8:#x}", tag, code),
                None => defmt::debug!("console tag={=u8:#x}", tag),
            },
            LogEvent::ManeuverStarted { points } => {
                defmt::info!("maneuver started: {=u8} points", points)
            }
            LogEvent::ManeuverDone => defmt::info!("maneuver done"),
            LogEvent::ManeuverAborted => defmt::info!("maneuver aborted"),
            LogEvent::GroupStarted { kind } => {
                defmt::info!("group maneuver started: kind {=u8}", kind)
            }
            LogEvent::GroupStopped => defmt::info!("group maneuver stopped"),
            LogEvent::ProgramStarted => defmt::info!("program started"),
            LogEvent::ProgramDone => defmt::info!("program done"),
            LogEvent::ProgramStopped => defmt::info!("program stopped"),
        }
    }
}

/// Firmware version (the crate version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// Exit status reported when the firmware panics.
pub const EXIT_PANIC: u16 = 1;
/// Exit status reported when the board cannot be brought up.
pub const EXIT_BOARD: u16 = 4;

/// Takes the board and logs the banner (`ubc-app VERSION board=NAME timebase=HZ Hz`) and
/// what is missing; ends the firmware with [`EXIT_BOARD`] when the board cannot be brought
/// up.
pub fn take_board() -> Board {
    let board = match Board::take() {
        Ok(board) => board,
        Err(e) => {
            defmt::error!("board bring-up failed: {}", e);
            board::exit_device().fail(EXIT_BOARD)
        }
    };
    defmt::info!(
        "ubc-app {=str} board={=str} timebase={=u32} Hz",
        VERSION,
        board::NAME,
        board.clock.hz()
    );
    #[cfg(feature = "qemu_virt")]
    match (&board.radio, &board.radio_info) {
        (Ok(_), Some(info)) => defmt::info!(
            "radio uart: pci-serial at {=usize:#x} (slot {=u8}, pin {}, PLIC source {=u32})",
            info.device.cpu_address,
            info.device.bdf.device,
            info.device.pin,
            info.plic_source
        ),
        (Err(e), _) => defmt::warn!("radio uart unavailable: {}", e),
        _ => {}
    }
    #[cfg(feature = "softcore")]
    if let Err(e) = &board.radio {
        defmt::warn!("radio uart unavailable: {}", e);
    }
    board
}

/// Brings the board up and runs the program, with `program` as its loop, forever.
pub fn start<U: UserProgram>(mut program: U) -> ! {
    run(take_board(), &mut program)
}

/// What a firmware's panic handler does: logs the message when it is plain text and the
/// location (formatting a message with arguments would pull `core::fmt`, several KiB, into
/// the image), then ends the firmware with [`EXIT_PANIC`].
pub fn panic(info: &core::panic::PanicInfo) -> ! {
    static PANICKING: AtomicBool = AtomicBool::new(false);
    // A panic while reporting a panic (e.g. inside the logger) must not recurse.
    if !PANICKING.swap(true, Ordering::AcqRel) {
        let message = info.message().as_str().unwrap_or("(formatted message)");
        match info.location() {
            Some(l) => defmt::error!(
                "panic: {=str} at {=str}:{=u32}",
                message,
                l.file(),
                l.line()
            ),
            None => defmt::error!("panic: {=str}", message),
        }
    }
    board::exit_device().fail(EXIT_PANIC)
}

/// Whether the LBC port holds a whole frame, or enough bytes to look at anyway.
fn lbc_input(port: &Uart) -> bool {
    port.frame_end_pending() || port.rx_len() >= RX_WAKE_BYTES
}

/// Ticks until the radio port's input must be read (0: now), `None` while it holds no whole
/// frame.
fn radio_wait(port: Option<&mut Uart>, now_lo: u32, batch: u32) -> Option<u32> {
    let port = port?;
    if port.rx_len() >= RX_WAKE_BYTES {
        return Some(0);
    }
    if !port.frame_end_pending() {
        return None;
    }
    // A frame end that lost its stamp (more frames than stamps) is read at once.
    let age = port
        .oldest_frame_end()
        .map_or(batch, |t| now_lo.wrapping_sub(t));
    Some(batch.saturating_sub(age))
}

/// Runs the program with its loop forever.
fn run<U: UserProgram>(board: Board, user: &mut U) -> ! {
    let clock = board.clock;
    let mut lbc = board.lbc;
    lbc.stamp_frames(board::frame_stamping(lbc_link::header::TERMINATOR));
    let mut radio = board.radio.ok();
    if let Some(r) = radio.as_mut() {
        r.stamp_frames(board::frame_stamping(radio_mac::wire::DELIMITER));
    }
    let batch = u32::try_from(clock.ticks_from_micros(RADIO_BATCH_US)).unwrap_or(u32::MAX);
    let mut camera = board.camera;
    let mut vision = board.vision;
    if let Some(v) = vision.as_mut() {
        v.load_classes(&MARKER_CLASSES);
        v.start(true);
        defmt::info!("vision unit: runs from the pixel pipeline");
    }
    let runs_ready = |v: &Option<Vision>| v.as_ref().is_some_and(|v| v.has_new_runs());
    let mut detector = BlobDetector::new();
    let mut program = Program::new(Config::default());
    let start = clock.micros();
    let mut next_stats = start + STATS_PERIOD_US;
    let mut next_camera = start;
    // The program runs at once, then when input or its next deadline comes.
    let mut program_due = start;
    loop {
        let mut now = clock.micros();
        let radio_now = radio_wait(radio.as_mut(), clock.ticks_lo(), batch) == Some(0);
        if radio_now || lbc_input(&lbc) || now >= program_due {
            program.poll_with(
                &BoardClock(&clock),
                &mut Port(Some(&mut lbc), &clock),
                &mut Port(radio.as_mut(), &clock),
                &mut Defmt,
                user,
            );
            now = clock.micros();
            program_due = program.poll_at(now);
        }
        if now >= next_camera || runs_ready(&vision) {
            next_camera = now + CAMERA_POLL_US;
            let grabbed = match vision.as_mut() {
                Some(v) => grab_runs(v, &mut detector, &mut program, &clock),
                None => grab_frame(&mut camera, &mut detector, &mut program, &clock),
            };
            if grabbed {
                now = clock.micros();
                program_due = program.poll_at(now);
            }
        }
        if now >= next_stats {
            next_stats += STATS_PERIOD_US;
            log_stats(&program, now);
        }
        let due = program_due.min(next_stats).min(next_camera);
        if due > now {
            // Sleep until the deadline, a whole LBC frame, or a radio frame that has waited
            // its batch time; interrupts that bring neither go back to sleep here.
            let wake = clock.wakeup_tick(due);
            let now_ticks = clock.ticks();
            let mut armed = u64::MAX;
            loop {
                let lo = clock.ticks_lo();
                let radio_at = radio_wait(radio.as_mut(), lo, batch)
                    .map(|w| now_ticks.max(clock.ticks()) + u64::from(w));
                let until = radio_at.map_or(wake, |r| r.min(wake));
                if lbc_input(&lbc) || clock.ticks() >= until || runs_ready(&vision) {
                    break;
                }
                if until != armed {
                    clock.set_wakeup(until);
                    armed = until;
                }
                cpu::idle_unless(|| {
                    lbc_input(&lbc) || clock.ticks() >= until || runs_ready(&vision)
                });
            }
        }
    }
}

/// Runs the vision pipeline on the newest frame, if a new one is published, and gives the
/// program its detections; whether it did. A frame the writer overwrote meanwhile is dropped
/// (counted by the grabber); a window without a valid header (no camera) costs one word read.
// Out of line (one call per camera frame): inlined into `run`, whose stack frame holds the
// program, its temporaries lay out of an instruction's reach; 148 bytes less.
#[inline(never)]
fn grab_frame(
    camera: &mut Camera,
    detector: &mut BlobDetector,
    program: &mut Program,
    clock: &Clock,
) -> bool {
    if !camera.has_new_frame() {
        return false;
    }
    let grabbed = camera.with_latest(|f| {
        process_frame(
            f.pixels,
            &f.geometry,
            &MARKER_CLASSES,
            &PipelineConfig::default(),
            detector,
        )
    });
    match grabbed {
        Ok(Some((ticket, Ok(detections)))) => {
            program.on_camera_frame(clock.micros(), ticket.sequence, &detections);
            true
        }
        Ok(Some((_, Err(e)))) => {
            defmt::warn!("camera frame rejected: {}", e);
            false
        }
        Ok(None) | Err(_) => false,
    }
}

/// Builds the blobs from the vision unit's newest run buffer, if a new frame is published, and
/// gives the program its detections; whether it did. Runs the unit overwrote meanwhile are
/// dropped (counted by the reader).
// Out of line, as `grab_frame`: 140 bytes less.
#[inline(never)]
fn grab_runs(
    unit: &mut Vision,
    detector: &mut BlobDetector,
    program: &mut Program,
    clock: &Clock,
) -> bool {
    if !unit.has_new_runs() {
        return false;
    }
    let grabbed = unit.with_latest(|r| {
        let t = r.ticket;
        vision::runs::blobs_from_runs(
            r.words,
            t.width,
            t.height,
            t.dropped,
            &PipelineConfig::default(),
            detector,
        )
    });
    match grabbed {
        Ok(Some((ticket, Ok(detections)))) => {
            program.on_camera_frame(clock.micros(), ticket.sequence, &detections);
            true
        }
        Ok(Some((_, Err(e)))) => {
            defmt::warn!("vision runs rejected: {}", e);
            false
        }
        Ok(None) | Err(_) => false,
    }
}

fn log_stats(program: &Program, now_us: u64) {
    let s = program.status(now_us);
    let l = program.lbc_stats();
    defmt::info!(
        "status phase={=u8} flags={=u8:#x} x={=u16} y={=u16} hd={=u16} v={=i16} stream={=u32} timeouts={=u32} bringups={=u16}",
        s.phase,
        s.flags,
        s.x,
        s.y,
        s.heading_mrad,
        s.velocity_mm_s,
        l.stream_frames,
        l.timeouts,
        s.bringups
    );
}
