//! Group-maneuver control laws for the ALMC car.
//!
//! Called once per control period (typically every 30 Hz STREAM frame) with what a real car
//! knows: its own pose and velocity from the LBC, its neighbours' poses from the radio state
//! broadcasts (with their age), its ID and the maneuver parameters. It answers with one LBC
//! motion command (`MOVE_SV`, `MOVE_XY` or `STOP`) and a status to broadcast.
//!
//! Each law ([`Formation`], [`Rendezvous`], [`Circle`], [`GoTo`]) implements [`Maneuver`] and
//! only says where the car should go ([`Guidance`]). The [`Controller`] layers car and wall
//! avoidance on top ([`safety`]) and turns the result into steering and velocity for the
//! kinematic bicycle ([`drive`]). The parameters of every law fit into 6 bytes
//! ([`ManeuverParams::encode`]), the field width of a radio group message.
//!
//! Units are the project's: X/Y in tracking units of 2.5 mm (arena X 0..=600, Y 0..=800),
//! heading in mrad counter-clockwise from +X, steering in signed mrad (+ = left, limit +/-523),
//! velocity in signed mm/s, time in microseconds. Internally the laws use `f32` with the
//! compact functions of [`fmath`] (no `f64`, no `libm`, so the FPU-less firmware stays
//! small); everything is deterministic and free of heap and `unsafe`.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod circle;
pub mod controller;
pub mod drive;
pub mod fmath;
pub mod formation;
pub mod geom;
pub mod goto;
pub mod params;
pub mod rendezvous;
pub mod safety;

#[cfg(test)]
mod sim;
#[cfg(test)]
mod sim_tests;

pub use circle::Circle;
pub use controller::{Controller, ControllerConfig, MAX_NEIGHBOURS};
pub use formation::{Formation, Shape};
pub use goto::GoTo;
pub use params::{DecodeError, EncodeError, ManeuverParams, ParamField, PARAMS_LEN};
pub use rendezvous::Rendezvous;
pub use safety::SafetyConfig;

use geom::Vec2;

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

/// What a law wants, before avoidance and steering.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Guidance {
    /// Move with this world-frame velocity (mm/s along +X, +Y).
    Velocity(Vec2),
    /// Drive to a fixed point (tracking units) at up to `speed_mm_s`, slowing down on arrival;
    /// the LBC's own `MOVE_XY` may be used for it.
    Point {
        /// The point, tracking units.
        at: Vec2,
        /// Cruise speed, mm/s.
        speed_mm_s: f32,
    },
    /// Stand still.
    Hold,
}

/// Goal and convergence report of a law for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// What to do.
    pub guidance: Guidance,
    /// Phase to report when avoidance does not intervene.
    pub phase: Phase,
    /// Convergence test of the law.
    pub converged: bool,
    /// Distance to the goal, tracking units.
    pub error_units: f32,
}

/// A group-maneuver control law.
pub trait Maneuver {
    /// Decide where this car should go, from its own pose and its fresh neighbours
    /// (`fresh` holds only the neighbours younger than the stale limit).
    fn plan(&mut self, me: &Me, fresh: &[Neighbour]) -> Plan;
}

/// This car as the laws see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Me {
    /// Car ID.
    pub id: u8,
    /// Position (rear axle), tracking units.
    pub pos: Vec2,
    /// Heading, rad.
    pub heading: f32,
    /// Signed speed, mm/s.
    pub speed: f32,
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
