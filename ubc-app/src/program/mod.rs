//! The UBC demo program (seed chapter 4): it brings the LBC up, keeps the vehicle state from
//! the 30 Hz stream, serves the user's console over the radio, runs a go-to-points maneuver
//! or a group maneuver with the other cars ([`group`]) or behind a leader seen by the camera
//! ([`camera`]), and stops the car when a link is lost.
//!
//! Everything here is board-independent and sans-IO: the board layer hands [`Program::poll`]
//! a [`Clock`], the two UARTs as [`BytePort`]s and a [`LogSink`], and sleeps until
//! [`Program::poll_at`]. Host tests drive the same code with fakes and the emulated LBC.

pub mod camera;
mod config;
pub mod console;
pub mod group;
mod leds;
mod machine;
mod maneuver;
pub mod user;

pub use config::{Config, DEFAULT_KEY};
pub use leds::LedState;
pub use machine::{
    touches_secrets, Counters, LogEvent, Phase, Program, BOOT_REGISTER, REQUIRED_STREAM,
};
pub use maneuver::{Maneuver, ManeuverState};

/// `a - b`, or 0 when `b` is later than `a`: the time elapsed since `b` at `a` (one
/// out-of-line copy for the radio MAC and the program).
pub(crate) use radio_mac::sat_sub;

/// A monotonic microsecond clock.
pub trait Clock {
    /// Microseconds since any fixed origin.
    fn now_us(&self) -> u64;
}

/// A non-blocking UART: `read` returns what has arrived (0 if nothing), `write` takes what fits
/// in the transmit buffer (possibly 0) and never waits.
pub trait BytePort {
    /// Moves received bytes into `buf`; returns how many.
    fn read(&mut self, buf: &mut [u8]) -> usize;
    /// Moves received bytes into `buf`, stopping after the first frame delimiter of the
    /// line; returns how many, and when they end with a delimiter whose arrival on the line
    /// the port knows, that time (the [`Clock`]'s microseconds). Ports that do not track
    /// frames read as [`BytePort::read`] does.
    fn read_frame(&mut self, buf: &mut [u8]) -> (usize, Option<u64>) {
        (self.read(buf), None)
    }
    /// Queues bytes for transmission; returns how many were taken.
    fn write(&mut self, bytes: &[u8]) -> usize;
}

/// Where the program reports what it does (defmt on the board, a vector in tests).
pub trait LogSink {
    /// One event at `now_us`.
    fn log(&mut self, now_us: u64, event: LogEvent);
}

/// A sink that drops everything.
#[derive(Debug, Default, Clone, Copy)]
pub struct NoLog;

impl LogSink for NoLog {
    fn log(&mut self, _now_us: u64, _event: LogEvent) {}
}
