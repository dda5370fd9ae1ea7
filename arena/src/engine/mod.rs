//! Car engines: what runs each car's firmware. The world ([`crate::world`]) owns time and every
//! shared medium; an engine only runs processors. Every quantum the world hands each car the
//! bytes due on its UARTs and asks the engine to run all cars up to the quantum's end; the
//! engine returns what each car sent, stamped with the world time it left.
//!
//! - [`iss`]: each car's firmware on the soft core's cycle-accurate model (`soc-model`), in
//!   virtual time, many cars in one process, stepped by a fixed number of threads. A run is a
//!   function of its inputs.
//! - [`qemu`]: each car in its own QEMU in wall-clock time, bytes exchanged over sockets; the
//!   world is paced to the wall clock.

pub mod gang;
pub mod iss;
pub mod qemu;

use std::fmt;

/// World time, nanoseconds since the world started.
pub type Nanos = u64;

/// The UART a byte travels on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Port {
    /// The link to the lower board.
    Lbc,
    /// The radio module.
    Radio,
}

/// One car's traffic in one quantum.
#[derive(Debug, Default, Clone)]
pub struct CarIo {
    /// Bytes for the car's LBC UART, each arriving no earlier than its time; the engine takes
    /// them all.
    pub lbc_in: Vec<(Nanos, u8)>,
    /// Bytes for the car's radio UART, likewise.
    pub radio_in: Vec<(Nanos, u8)>,
    /// Bytes the car sent on its LBC UART in the quantum, with the time each left.
    pub lbc_out: Vec<(Nanos, u8)>,
    /// Bytes the car sent on its radio UART in the quantum, with the time each left.
    pub radio_out: Vec<(Nanos, u8)>,
}

impl CarIo {
    /// Empties the outputs (the world does this before each quantum).
    pub fn clear_outputs(&mut self) {
        self.lbc_out.clear();
        self.radio_out.clear();
    }
}

/// Why a car's firmware stopped running.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FailureKind {
    /// The firmware ended through its exit device (`value` as written: `0x5555` pass,
    /// `code << 16 | 0x3333` fail).
    Exited { value: u32 },
    /// The processor can never run again (waits for an interrupt none can raise, or spins
    /// on itself with interrupts off).
    Stuck { pc: u32, why: String },
    /// The emulator process died or was killed.
    Killed { why: String },
}

impl fmt::Display for FailureKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FailureKind::Exited { value } => {
                let code = value >> 16;
                match value & 0xffff {
                    0x5555 => write!(f, "firmware exited (pass)"),
                    0x3333 => write!(f, "firmware exited with failure code {code}"),
                    0x7777 => write!(f, "firmware requested a reset"),
                    _ => write!(f, "firmware exited ({value:#x})"),
                }
            }
            FailureKind::Stuck { pc, why } => write!(f, "processor stuck at {pc:#010x}: {why}"),
            FailureKind::Killed { why } => write!(f, "emulator ended: {why}"),
        }
    }
}

/// A car whose firmware stopped, and when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Failure {
    /// World time of the failure.
    pub at: Nanos,
    /// What happened.
    pub kind: FailureKind,
}

/// A car's processor load so far (engines that count cycles).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CoreLoad {
    /// Cycles run.
    pub cycles: u64,
    /// Of those, cycles the processor was awake (not waiting in WFI).
    pub awake_cycles: u64,
    /// Instructions retired.
    pub retired: u64,
}

impl CoreLoad {
    /// Awake cycles over cycles, 0..=1.
    pub fn load(&self) -> f64 {
        if self.cycles == 0 {
            0.0
        } else {
            self.awake_cycles as f64 / self.cycles as f64
        }
    }
}

/// Why a frame could not be published into a car's frame grabber.
#[derive(Debug)]
pub struct FrameWriteError(pub String);

impl fmt::Display for FrameWriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for FrameWriteError {}

/// Writes into one car's frame-grabber window at offsets relative to the window's start, and
/// feeds its vision unit.
pub trait WindowWriter {
    /// Writes `bytes` at `offset` in the window.
    fn write_window(&mut self, offset: usize, bytes: &[u8]) -> Result<(), FrameWriteError>;
    /// Streams a frame of RGB332 codes (`width` per row) into the car's vision unit: the SoC's
    /// camera port, or on QEMU the host computing the runs into the run window as the unit
    /// would. `Ok(false)`: the car has no vision unit.
    fn camera_stream(
        &mut self,
        _codes: &[u8],
        _width: u16,
        _height: u16,
    ) -> Result<bool, FrameWriteError> {
        Ok(false)
    }
    /// Gives the car's SoC a vision unit or takes it away (before its firmware starts).
    fn set_vision_unit(&mut self, _present: bool) {}
}

/// What runs the cars' firmware.
pub trait CarEngine: Send {
    /// `"iss"` or `"qemu"`.
    fn name(&self) -> &'static str;
    /// Whether the engine runs in wall-clock time (the world must then pace itself).
    fn wall_clock(&self) -> bool;
    /// Runs every car that is still alive up to world time `until`. `io[k]` belongs to car
    /// `k` (configuration order): the engine takes its inputs and fills its outputs.
    fn advance(&mut self, until: Nanos, io: &mut [CarIo]);
    /// Car `k`'s failure, once its firmware has stopped.
    fn failure(&self, k: usize) -> Option<Failure>;
    /// How many cars have failed so far, where the engine counts them cheaply: the world
    /// then asks [`CarEngine::failure`] of each car only when the count moves. `None`: ask
    /// every quantum.
    fn failures(&self) -> Option<usize> {
        None
    }
    /// Runs `f` on car `k`'s frame-grabber window; false when the car has none.
    fn with_window(&mut self, k: usize, f: &mut dyn FnMut(&mut dyn WindowWriter)) -> bool;
    /// Car `k`'s processor load, for engines that count cycles.
    fn core_load(&self, k: usize) -> Option<CoreLoad>;
    /// Car `k`'s decoded firmware log so far.
    fn firmware_log(&self, k: usize) -> Vec<String>;
    /// Where car `k`'s processor spent its cycles, by function, largest first (profiled
    /// cars of engines that count cycles).
    fn profile(&self, _k: usize) -> Option<Vec<(u64, f64, String)>> {
        None
    }
    /// From now on, keep car console bytes for [`CarEngine::take_console`] (engines that see
    /// them).
    fn tap_console(&mut self, _on: bool) {}
    /// Moves car `k`'s console bytes kept since the last call, with the world time each was
    /// written, to `out`.
    fn take_console(&mut self, _k: usize, _out: &mut Vec<(Nanos, u8)>) {}
    /// How car `k`'s console bytes become log lines (engines that hand them out).
    fn log_format(&self, _k: usize) -> Option<std::sync::Arc<qemu_harness::LogFormat>> {
        None
    }
    /// Ends car `k`'s firmware now, as a crash would (`kill -9` of its emulator); the
    /// world then treats it as failed.
    fn kill(&mut self, k: usize, why: &str);
    /// Stops every car now (kills processes); idempotent.
    fn shutdown(&mut self);
}
