//! The law interface: what a group-maneuver law sees in one control period and what it
//! answers.
//!
//! A law is a type implementing [`Law`]: its name, its parameters ([`Param`]), its default
//! options ([`LawOptions`]), a constructor from the parameter values and a `step` run once per
//! control period. Everything it is given is in the project's integer units ([`LawInput`]:
//! tracking units, mrad, mm/s, microseconds) and everything it answers can be integers too
//! ([`Guidance::Velocity`], [`Guidance::Point`], [`Plan::error_units`]), so a law can be
//! written without floating point (the firmware's core has no FPU; [`crate::imath`] has the
//! integer helpers). A law written with `f32` takes [`LawInput::me`] and answers
//! [`Guidance::VelocityF`].
//!
//! Laws are registered in one list, `laws/mod.rs`; the controller, the firmware, the command
//! line and the experiment files all read it (see `docs/writing-a-law.md`).

use crate::geom::{mrad_to_rad, Vec2};
use crate::param::{Param, Values};
use crate::{CarPose, Neighbour, Phase};

/// How the steering layer may drive backwards when the way to go lies behind the car.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Reverse {
    /// A way more than 140 degrees behind is driven in reverse, back to forward once the nose
    /// is within 40 degrees of it (reverse stretches can be long).
    #[default]
    Allowed = 1,
    /// Turn round instead: back up on full lock, the nose swinging towards the way, until it is
    /// within 90 degrees of it, then drive forward (a two- or three-point turn).
    Turn = 2,
    /// Never backwards: turn forward on full lock (a 139 mm radius arc) until facing the way.
    Never = 3,
}

impl Reverse {
    /// Every mode, for names and tests.
    pub const ALL: [Reverse; 3] = [Reverse::Allowed, Reverse::Turn, Reverse::Never];

    /// The mode's name in commands and files.
    pub const fn name(self) -> &'static str {
        match self {
            Reverse::Allowed => "allowed",
            Reverse::Turn => "turn",
            Reverse::Never => "never",
        }
    }

    /// The mode with wire value `v` (1..=3).
    pub const fn from_u8(v: u8) -> Option<Reverse> {
        match v {
            1 => Some(Reverse::Allowed),
            2 => Some(Reverse::Turn),
            3 => Some(Reverse::Never),
            _ => None,
        }
    }
}

/// Which of the fresh neighbours a law is given (the avoidance always sees all of them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Neighbours {
    /// Every fresh neighbour (at most [`crate::MAX_NEIGHBOURS`]), in the order heard.
    #[default]
    All,
    /// The `k` nearest fresh neighbours (1..=16), nearest first.
    Nearest(u8),
    /// None: the law sees only its own car.
    None,
}

/// Largest `k` of [`Neighbours::Nearest`].
pub const MAX_NEAREST: u8 = 16;

/// Options of a law: its defaults are part of its registration, and a group command may
/// override each of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LawOptions {
    /// How the steering layer may use reverse.
    pub reverse: Reverse,
    /// Distance at which the car counts as arrived at a point (a go-to target, a waypoint),
    /// tracking units, 1..=255.
    pub arrival_units: u8,
    /// Which neighbours the law is given.
    pub neighbours: Neighbours,
}

impl LawOptions {
    /// Reverse allowed, arrival within 8 units (20 mm, the LBC's own `MOVE_XY` arrival
    /// distance), every neighbour.
    pub const DEFAULT: LawOptions = LawOptions {
        reverse: Reverse::Allowed,
        arrival_units: 8,
        neighbours: Neighbours::All,
    };
}

impl Default for LawOptions {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A waypoint given to the running law (the console's `GroupWaypoint`), moved inside the
/// walls like every goal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Waypoint {
    /// X, tracking units.
    pub x: u16,
    /// Y, tracking units.
    pub y: u16,
    /// Waypoints given since the law started, before this one: a law tells a new waypoint
    /// from the one it already reached by this number.
    pub index: u16,
}

/// The rectangle goals must lie in (tracking units, inclusive): far enough from the walls
/// that the car's body keeps out of them whatever its heading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GoalArea {
    /// Lowest X.
    pub x_min: u16,
    /// Highest X.
    pub x_max: u16,
    /// Lowest Y.
    pub y_min: u16,
    /// Highest Y.
    pub y_max: u16,
}

impl GoalArea {
    /// `(x, y)` moved into the area.
    pub fn clamp(&self, x: u16, y: u16) -> (u16, u16) {
        // Not `Ord::clamp`: it panics on an empty range, and its panic message would pull
        // the formatting code into the firmware.
        (
            x.max(self.x_min).min(self.x_max),
            y.max(self.y_min).min(self.y_max),
        )
    }
}

/// Everything a law is given in one control period.
#[derive(Debug, Clone, Copy)]
pub struct LawInput<'a> {
    /// Local monotonic time, microseconds.
    pub now_us: u64,
    /// This car's ID.
    pub id: u8,
    /// This car's pose and speed from its LBC stream.
    pub own: CarPose,
    /// The neighbours the law's [`LawOptions::neighbours`] selects: fresh ones only (younger
    /// than the avoidance's stale limit), never this car.
    pub neighbours: &'a [Neighbour],
    /// The latest waypoint given since the law started, if any.
    pub waypoint: Option<Waypoint>,
    /// The options in force (the law's defaults, overridden by the group command).
    pub options: LawOptions,
    /// Where goals may lie.
    pub area: GoalArea,
}

impl<'a> LawInput<'a> {
    /// This car as `f32` (tracking units, rad, mm/s), for laws written in floating point.
    pub fn me(&self) -> Me {
        Me {
            id: self.id,
            pos: Vec2::new(f32::from(self.own.x), f32::from(self.own.y)),
            heading: mrad_to_rad(self.own.heading_mrad),
            speed: f32::from(self.own.velocity_mm_s),
        }
    }

    /// The neighbour with ID `id`, if it is fresh and selected.
    pub fn neighbour(&self, id: u8) -> Option<&'a Neighbour> {
        self.neighbours.iter().find(|n| n.id == id)
    }
}

/// This car in floating point, for laws written with `f32`.
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

/// What a law wants, before avoidance and steering.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Guidance {
    /// Stand still.
    Hold,
    /// Move with this world-frame velocity, mm/s along +X and +Y.
    Velocity {
        /// Along +X, mm/s.
        vx_mm_s: i16,
        /// Along +Y, mm/s.
        vy_mm_s: i16,
    },
    /// Drive to a point at up to `speed_mm_s`, slowing down on arrival (the LBC's own
    /// `MOVE_XY` may be used for it); the controller moves it inside the walls.
    Point {
        /// X, tracking units.
        x: u16,
        /// Y, tracking units.
        y: u16,
        /// Cruise speed, mm/s.
        speed_mm_s: u16,
    },
    /// [`Guidance::Velocity`] in `f32` (mm/s), for laws written in floating point.
    VelocityF(Vec2),
}

/// A law's answer for one period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// What to do.
    pub guidance: Guidance,
    /// Phase to report when the avoidance does not intervene.
    pub phase: Phase,
    /// The law's own convergence test holds.
    pub converged: bool,
    /// Distance to the law's goal, tracking units (reported in the car's status).
    pub error_units: u16,
}

impl Plan {
    /// Stand still in `phase`.
    pub const fn hold(phase: Phase, converged: bool, error_units: u16) -> Plan {
        Plan {
            guidance: Guidance::Hold,
            phase,
            converged,
            error_units,
        }
    }
}

/// An error in tracking units from `f32` (truncated, saturated to `0..=u16::MAX`), for laws
/// written in floating point.
// Out of line: one call is smaller than the soft-float conversion at every use.
#[inline(never)]
pub fn error_units(e: f32) -> u16 {
    crate::geom::clampf(e, 0.0, f32::from(u16::MAX)) as u16
}

/// An error in 1/16 tracking unit ([`crate::fixed`]) in whole units (truncated, saturated to
/// `0..=u16::MAX`).
// Out of line: its clamps inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub fn error_units_fx(e: i32) -> u16 {
    (e.max(0) >> crate::fixed::FRAC).min(i32::from(u16::MAX)) as u16
}

/// A velocity in 1/16 mm/s ([`crate::fixed`]) in whole mm/s, rounded (saturated to `i16`).
// Out of line: its rounding and clamps inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn velocity_mm_s(v: crate::fixed::IVec2) -> (i16, i16) {
    let (x, y) = v.to_units();
    let sat = |c: i32| c.max(-i32::from(i16::MAX)).min(i32::from(i16::MAX)) as i16;
    (sat(x), sat(y))
}

impl Guidance {
    /// A velocity in 1/16 mm/s ([`crate::fixed`]) as [`Guidance::Velocity`], rounded to whole
    /// mm/s (saturated to `i16`).
    pub fn velocity(v: crate::fixed::IVec2) -> Guidance {
        let (vx_mm_s, vy_mm_s) = velocity_mm_s(v);
        Guidance::Velocity { vx_mm_s, vy_mm_s }
    }
}

/// A group-maneuver law. Registered with one line in `laws/mod.rs`.
pub trait Law: Sized + Clone + core::fmt::Debug {
    /// Name in commands, experiment files and reports: lowercase letters, digits and `-`.
    const NAME: &'static str;
    /// One sentence saying what the law does (shown by `almc laws` and in the docs).
    const SUMMARY: &'static str;
    /// The parameters, in the order of the wire form and of [`Values`].
    const PARAMS: &'static [Param];
    /// Default options.
    const OPTIONS: LawOptions = LawOptions::DEFAULT;
    /// Whether the controller's commands drive the car. A law that only reports (the camera
    /// follow, which the firmware's camera part carries out) sets this to `false`.
    const DRIVES: bool = true;
    /// Whether the law can say it has converged. One that cannot (the camera follow, which
    /// keeps following) ends an experiment's phase when the phase's time is up, and that is
    /// its normal end, not a timeout.
    const CONVERGES: bool = true;

    /// The law from its parameter values (in [`Law::PARAMS`] order, each within its range).
    fn new(params: &Values) -> Self;

    /// One control period.
    fn step(&mut self, input: &LawInput<'_>) -> Plan;

    /// Whether car `id` leads the group (broadcast as the leader role).
    fn leads(&self, _id: u8) -> bool {
        false
    }
}
