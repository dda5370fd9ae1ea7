//! Group-maneuver control laws for the ALMC car.
//!
//! Called once per control period (typically every 30 Hz STREAM frame) with what a real car
//! knows: its own pose and velocity from the LBC, its neighbours' poses from the radio state
//! broadcasts (with their age), its ID and the maneuver parameters. It answers with one LBC
//! motion command (`MOVE_SV`, `MOVE_XY` or `STOP`) and a status to broadcast.
//!
//! Each law implements [`Law`] ([`law`]: what it sees, what it answers, its parameters and
//! options) and only says where the car should go ([`Guidance`]). The laws are registered in
//! one list ([`laws`]: formation, rendezvous, circle, go-to, camera follow, and whatever a
//! researcher adds), which the firmware, `almc` and the experiment files read. The
//! [`Controller`] runs the law a group command names ([`ManeuverParams`], wire form in
//! [`params`]), layers car and wall avoidance on top ([`safety`]) and turns the result into
//! steering and velocity for the kinematic bicycle ([`drive`]).
//!
//! Units are the project's: X/Y in tracking units of 2.5 mm (arena X 0..=600, Y 0..=800),
//! heading in mrad counter-clockwise from +X, steering in signed mrad (+ = left, limit +/-523),
//! velocity in signed mm/s, time in microseconds. A law's inputs and outputs are integers in
//! these units, so a law can be written without floating point ([`imath`]); the built-in
//! laws and the controller use `f32` with the compact functions of [`fmath`] (no `f64`, no
//! `libm`, so the FPU-less firmware stays small). Everything is deterministic and free of
//! heap and `unsafe`.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod args;
pub mod controller;
pub mod drive;
pub mod fixed;
pub mod fmath;
pub mod geom;
pub mod imath;
pub mod law;
pub mod laws;
pub mod param;
pub mod params;
pub mod reference;
pub mod registry;
pub mod safety;

#[cfg(test)]
mod sim;
#[cfg(test)]
mod sim_tests;

pub use controller::{Controller, ControllerConfig, MAX_NEIGHBOURS};
pub use law::{Guidance, Law, LawInput, LawOptions, Me, Neighbours, Plan, Reverse, Waypoint};
pub use laws::formation::Shape;
pub use laws::{AnyLaw, CameraFollow, Circle, Formation, GoTo, Rendezvous, LAWS};
pub use param::{Param, Values};
pub use params::{DecodeError, EncodeError, ManeuverParams, Overrides};
pub use registry::{LawInfo, Registered};
pub use safety::SafetyConfig;

/// Millimetres per tracking unit.
pub const MM_PER_UNIT: f32 = 2.5;
/// Inside of the arena along X, tracking units.
pub const ARENA_X_MAX: u16 = 600;
/// Inside of the arena along Y, tracking units.
pub const ARENA_Y_MAX: u16 = 800;
/// Steering limit of the car (30 degrees), mrad.
pub const STEER_LIMIT_MRAD: i16 = 523;
/// Wheelbase of the car, mm.
pub const WHEELBASE_MM: f32 = 80.0;

/// A car's pose and speed, as the LBC streams it or a state broadcast carries it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarPose {
    /// X, tracking units (midpoint of the rear axle).
    pub x: u16,
    /// Y, tracking units.
    pub y: u16,
    /// Heading, mrad counter-clockwise from +X, 0..=6283.
    pub heading_mrad: u16,
    /// Signed forward velocity, mm/s.
    pub velocity_mm_s: i16,
}

/// A neighbour heard on the radio.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Neighbour {
    /// Car ID.
    pub id: u8,
    /// Its latest broadcast pose.
    pub pose: CarPose,
    /// Time since that broadcast arrived, microseconds.
    pub age_us: u32,
}

/// Everything a law may use in one control period.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Local monotonic time, microseconds.
    pub now_us: u64,
    /// This car's ID.
    pub id: u8,
    /// This car's pose from the LBC stream.
    pub own: CarPose,
    /// Neighbours of the group (fresh or stale; stale ones are ignored).
    pub neighbours: &'a [Neighbour],
}

/// One LBC motion command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// `STOP`: brake to standstill.
    Stop,
    /// `MOVE_XY`: the LBC's own path generator drives to the point (tracking units).
    MoveXy {
        /// Target X.
        x: u16,
        /// Target Y.
        y: u16,
    },
    /// `MOVE_SV`: hold this steering angle and velocity.
    MoveSv {
        /// Steering, signed mrad within +/-[`STEER_LIMIT_MRAD`].
        steering_mrad: i16,
        /// Velocity, signed mm/s.
        velocity_mm_s: i16,
    },
}

/// Maneuver phase, broadcast in the low nibble of the state frame's mode byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Phase {
    /// No maneuver.
    #[default]
    Idle = 0,
    /// Driving towards the goal of the law.
    Approach = 1,
    /// At the goal and tracking it (moving goals).
    Track = 2,
    /// At the goal, holding still.
    Hold = 3,
    /// The avoidance layer changed or vetoed the law's command.
    Avoid = 4,
    /// The reference the law needs (the leader) is missing or stale: stopped.
    NoReference = 5,
}

impl Phase {
    /// The 4-bit value for the radio mode byte.
    pub const fn bits(self) -> u8 {
        self as u8
    }

    /// The phase with mode-byte value `bits`, if there is one.
    pub const fn from_bits(bits: u8) -> Option<Phase> {
        Some(match bits {
            0 => Phase::Idle,
            1 => Phase::Approach,
            2 => Phase::Track,
            3 => Phase::Hold,
            4 => Phase::Avoid,
            5 => Phase::NoReference,
            _ => return None,
        })
    }

    /// The phase's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            Phase::Idle => "idle",
            Phase::Approach => "approach",
            Phase::Track => "track",
            Phase::Hold => "hold",
            Phase::Avoid => "avoid",
            Phase::NoReference => "no-reference",
        }
    }
}

/// What a car broadcasts about its maneuver.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Current phase.
    pub phase: Phase,
    /// The law's own convergence test holds.
    pub converged: bool,
    /// Distance to the law's goal, tracking units (saturated).
    pub error_units: u16,
}

/// Result of one control period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Output {
    /// Command to send to the LBC.
    pub command: Command,
    /// Status to broadcast.
    pub status: Status,
}

#[cfg(test)]
mod tests {
    use super::Phase;

    #[test]
    fn phase_bits_round_trip() {
        for b in 0..=255u8 {
            match Phase::from_bits(b) {
                Some(p) => assert_eq!(p.bits(), b),
                None => assert!(b > 5, "{b}"),
            }
        }
        assert_eq!(Phase::from_bits(5).map(Phase::name), Some("no-reference"));
    }
}
