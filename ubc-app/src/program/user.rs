//! A researcher's own upper-board program: a loop run at every 30 Hz STREAM sample on top of
//! the stock program, which keeps doing everything else (bring-up, the console over the
//! radio, the state broadcast, the group maneuvers, the safety stops).
//!
//! A program is a type implementing [`UserProgram`], passed to
//! [`crate::firmware::start`] by its binary (`cargo xtask new-program NAME` writes one from a
//! template; `docs/writing-a-program.md`). The ground station starts it with the console's
//! `ProgramStart` (arguments: up to [`MAX_ARGS`] signed 16-bit numbers, meaning what the
//! program says) and stops it with `ProgramStop`; while it runs, the commands it returns go
//! to the LBC through the same gate as the group maneuver's (at most every 100 ms unless they
//! change to `STOP`, refreshed every second). The stock program stops it like any maneuver:
//! on a lost LBC or user link, a manual motion command, or another maneuver starting.

use heapless::Vec;
use maneuvers::{CarPose, Command as Motion, Neighbour};

/// Most arguments of a `ProgramStart`.
pub const MAX_ARGS: usize = 14;

/// A program's arguments.
pub type Args = Vec<i16, MAX_ARGS>;

/// What a program sees at one STREAM sample.
#[derive(Debug, Clone, Copy)]
pub struct ProgramInput<'a> {
    /// Local monotonic time, microseconds.
    pub now_us: u64,
    /// This car's ID.
    pub id: u8,
    /// This car's pose and speed from its LBC stream (tracking units, mrad, mm/s).
    pub own: CarPose,
    /// The other cars heard on the radio, with the age of their latest state.
    pub neighbours: &'a [Neighbour],
}

/// What a program wants after one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Drive with this command (`STOP`, `MOVE_XY` or `MOVE_SV`); an unchanged command is not
    /// sent again before its refresh.
    Drive(Motion),
    /// Finished: the car is stopped and the ground station told (`ManeuverDone`).
    Done,
}

/// A program's loop.
pub trait UserProgram {
    /// `false` only for [`NoProgram`]: the stock firmware refuses `ProgramStart`.
    const PRESENT: bool = true;

    /// The ground station started the program with `args` (the loop runs from the next
    /// sample). Called again for every `ProgramStart`.
    fn start(&mut self, now_us: u64, args: &[i16]);

    /// One sample while running.
    fn step(&mut self, input: &ProgramInput<'_>) -> Step;

    /// The program was stopped before it finished (a `ProgramStop`, a lost link, a manual
    /// command); the stock program stops the car.
    fn stop(&mut self) {}

    /// Progress for the status reply: (step, of steps), e.g. the corner driven to.
    fn progress(&self) -> (u8, u8) {
        (0, 0)
    }
}

/// The stock firmware's program: none.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgram;

impl UserProgram for NoProgram {
    const PRESENT: bool = false;

    fn start(&mut self, _now_us: u64, _args: &[i16]) {}

    fn step(&mut self, _input: &ProgramInput<'_>) -> Step {
        Step::Done
    }
}
