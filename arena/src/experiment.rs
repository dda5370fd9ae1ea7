//! Experiments as files: a TOML document names the cars and their start poses, the maneuvers
//! (one `[maneuver]`, or a sequence of `[[phases]]`) with their parameters, the duration and
//! the faults. [`Experiment::load`] reads and checks one; [`run`] plays it in a
//! [`World`](crate::world::World) of QEMU cars in real time and writes the results (trajectory
//! CSVs, an event log, a JSON summary and an SVG plot) to a directory. The format and the
//! metrics are described in `docs/experiments.md`.

use crate::camera_feed::FeedConfig;
use crate::radio_medium::MediumParams;
use crate::world::{CarSpec, TrackingParams, WorldConfig, WorldError, MM_PER_UNIT};
use lbc_emu::{FaultConfig, Pose};
use maneuvers::{ManeuverParams, Shape};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;
use ubc_app::program::console::{Status, MAX_POINTS};

pub use crate::runner::{run, CarResult, PhaseResult, Progress, Summary};

/// Largest number of followers in a formation (slots 0..=14 on the wire).
pub const MAX_FOLLOWERS: usize = 15;
/// Default time a phase's completion test must hold before it counts as complete, s.
pub const DEFAULT_HOLD_S: f64 = 2.0;
/// Default distance at which a formation leader counts as at its waypoint, tracking units.
pub const DEFAULT_REACH_UNITS: u16 = 16;
/// Default go-to tolerance: a car this close to its last point has arrived, mm (the
/// firmware's own arrival radius is 12 units, 30 mm).
pub const DEFAULT_GOTO_TOLERANCE_MM: f64 = 62.5;
/// Default formation tolerance: every follower this close to its slot, mm.
pub const DEFAULT_FORMATION_TOLERANCE_MM: f64 = 75.0;
/// Default circle tolerance: radius and spacing errors below this, mm.
pub const DEFAULT_CIRCLE_TOLERANCE_MM: f64 = 75.0;
/// Default rendezvous tolerance beyond the arrival radius, mm: a car whose way to the
/// consensus point is blocked by a nearer car holds within this much more (130 units, the
/// law's blocking distance, see `docs/maneuvers.md`).
pub const RENDEZVOUS_MARGIN_MM: f64 = 325.0;
/// A rendezvous is complete only while every car is slower than this, mm/s.
pub const RENDEZVOUS_STILL_MM_S: f64 = 20.0;

/// An experiment, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    /// Name, used in outputs.
    pub name: String,
    /// Seconds the maneuvers may run, all phases together.
    pub duration_s: f64,
    /// Seed of every random source.
    pub seed: u64,
    /// Seconds allowed for every car's bring-up.
    pub bringup_s: f64,
    /// The cars.
    pub cars: Vec<CarEntry>,
    /// What the cars do, in order.
    pub phases: Vec<Phase>,
    /// Imperfections of the world.
    pub faults: Faults,
    /// Frames per second of every car's synthetic camera (written into its frame grabber);
    /// `None`: no camera feed.
    pub camera_fps: Option<f64>,
}

/// A car and its start pose (tracking units, 2.5 mm; heading mrad counter-clockwise from +X).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CarEntry {
    /// Car ID, 1..=126.
    pub id: u8,
    /// X, 0..=600 inside the arena.
    pub x: u16,
    /// Y, 0..=800 inside the arena.
    pub y: u16,
    /// Heading, 0..=6283 mrad.
    #[serde(default)]
    pub heading_mrad: u16,
}

/// One car's go-to points, tracking units.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GotoCar {
    /// Car ID.
    pub id: u8,
    /// Up to 7 points `[x, y]`.
    pub points: Vec<[u16; 2]>,
}

/// When a phase starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// Once the previous phase is complete or timed out (the first phase: at once).
    AfterPrevious,
    /// At this many seconds after the first phase started (cutting the previous one short).
    At(f64),
}

/// One maneuver of the sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct Phase {
    /// The maneuver.
    pub kind: PhaseKind,
    /// When it starts.
    pub start: Start,
    /// Longest time it may run before the next phase starts, s (`None`: bounded only by the
    /// experiment's `duration_s`).
    pub timeout_s: Option<f64>,
    /// How long its completion test must hold, s.
    pub hold_s: f64,
    /// The completion test's bound on the phase error, mm (not used by `goto`).
    pub tolerance_mm: f64,
}

/// A formation phase.
#[derive(Debug, Clone, PartialEq)]
pub struct FormationPhase {
    /// Line or wedge.
    pub shape: Shape,
    /// The leader's car ID.
    pub leader: u8,
    /// The followers in slot order (slot `k` is `followers[k]`).
    pub followers: Vec<u8>,
    /// Distance between neighbouring slots, tracking units.
    pub spacing_units: u16,
    /// The leader's cruise speed, mm/s.
    pub speed_mm_s: u16,
    /// The leader's waypoints, tracking units.
    pub waypoints: Vec<[u16; 2]>,
    /// When each waypoint is sent, s after the phase started (`None`: each once the leader
    /// reached the previous one).
    pub waypoint_at_s: Option<Vec<f64>>,
    /// The leader has reached a waypoint within this distance, tracking units.
    pub reach_units: u16,
}

/// What a phase does.
#[derive(Debug, Clone, PartialEq)]
pub enum PhaseKind {
    /// Each car drives through its points and stops: without a speed with the console go-to
    /// maneuver (the LBC's own `MOVE_XY`, no avoidance), with a speed to its one point with
    /// the group go-to law (car and wall avoidance).
    Goto {
        /// Per-car point lists (cars without one stay still).
        cars: Vec<GotoCar>,
        /// Speed of the group go-to law, mm/s (`None`: console go-to).
        speed_mm_s: Option<u16>,
    },
    /// Leader-follower formation.
    Formation(FormationPhase),
    /// Rendezvous by consensus.
    Rendezvous {
        /// Arrival radius, tracking units.
        radius_units: u16,
        /// Maximum speed, mm/s.
        speed_mm_s: u16,
    },
    /// Even spacing on a rotating circle.
    Circle {
        /// Centre `[x, y]`, tracking units.
        centre: [u16; 2],
        /// Radius, tracking units.
        radius_units: u16,
        /// Speed along the circle, mm/s (positive counter-clockwise).
        speed_mm_s: i16,
    },
}

impl PhaseKind {
    /// The kind's name in the file.
    pub fn name(&self) -> &'static str {
        match self {
            PhaseKind::Goto { .. } => "goto",
            PhaseKind::Formation(_) => "formation",
            PhaseKind::Rendezvous { .. } => "rendezvous",
            PhaseKind::Circle { .. } => "circle",
        }
    }
}

impl Phase {
    /// The group maneuver parameters car `id` is started with (`None` for a console `goto`,
    /// for a car without a point in a group `goto`, and for a car that is neither leader nor
    /// follower of a formation: these stand still).
    pub fn params_for(&self, id: u8) -> Option<ManeuverParams> {
        match &self.kind {
            PhaseKind::Goto {
                speed_mm_s: Some(speed),
                ..
            } => self.goto_points(id).first().map(|p| ManeuverParams::GoTo {
                x: p[0],
                y: p[1],
                speed_mm_s: *speed,
            }),
            PhaseKind::Goto { .. } => None,
            PhaseKind::Formation(f) if f.leader != id && !f.followers.contains(&id) => None,
            PhaseKind::Formation(f) => Some(ManeuverParams::Formation {
                shape: f.shape,
                leader: f.leader,
                slot: f
                    .followers
                    .iter()
                    .position(|&c| c == id)
                    .and_then(|k| u8::try_from(k).ok()),
                spacing_units: f.spacing_units,
                speed_mm_s: f.speed_mm_s,
            }),
            PhaseKind::Rendezvous {
                radius_units,
                speed_mm_s,
            } => Some(ManeuverParams::Rendezvous {
                radius_units: *radius_units,
                speed_mm_s: *speed_mm_s,
            }),
            PhaseKind::Circle {
                centre,
                radius_units,
                speed_mm_s,
            } => Some(ManeuverParams::Circle {
                cx: centre[0],
                cy: centre[1],
                radius_units: *radius_units,
                speed_mm_s: *speed_mm_s,
            }),
        }
    }

    /// Car `id`'s go-to points in a `goto` phase (empty otherwise).
    pub fn goto_points(&self, id: u8) -> Vec<[u16; 2]> {
        match &self.kind {
            PhaseKind::Goto { cars, .. } => cars
                .iter()
                .find(|g| g.id == id)
                .map(|g| g.points.clone())
                .unwrap_or_default(),
            _ => Vec::new(),
        }
    }
}

/// Faults: radio loss, tracking imperfections, LBC link faults.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Probability that a radio reception is lost.
    pub radio_loss: f64,
    /// Tracking position noise, standard deviation, mm.
    pub tracking_noise_mm: f64,
    /// Tracking heading noise, standard deviation, mrad.
    pub tracking_heading_noise_mrad: f64,
    /// Probability that a tracking fix is lost.
    pub tracking_drop: f64,
    /// Tracking latency, ms.
    pub tracking_latency_ms: u64,
    /// Tracking rate, Hz.
    pub tracking_rate_hz: f64,
    /// LBC link faults (every car).
    pub lbc: LbcFaults,
}

impl Default for Faults {
    fn default() -> Self {
        Self {
            radio_loss: 0.0,
            tracking_noise_mm: 0.0,
            tracking_heading_noise_mrad: 0.0,
            tracking_drop: 0.0,
            tracking_latency_ms: 10,
            tracking_rate_hz: 30.0,
            lbc: LbcFaults::default(),
        }
    }
}

/// LBC link faults, as `lbc_emu::FaultConfig`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct LbcFaults {
    /// Probability that a byte is lost, each direction.
    pub drop: f64,
    /// Probability that a byte has a bit flipped, each direction.
    pub corrupt: f64,
    /// Extra delay of each outgoing message, us.
    pub delay_us: u64,
    /// Probability that a reply or STREAM frame is never sent.
    pub suppress: f64,
    /// Mean seconds between spontaneous LBC resets (0: none).
    pub reset_every_s: f64,
}

impl From<LbcFaults> for FaultConfig {
    fn from(f: LbcFaults) -> Self {
        FaultConfig {
            drop: f.drop,
            corrupt: f.corrupt,
            delay_us: f.delay_us,
            suppress: f.suppress,
            reset_every_s: f.reset_every_s,
        }
    }
}

/// The file as written (checked and normalised into [`Experiment`]).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExperiment {
    name: String,
    duration_s: f64,
    #[serde(default = "one")]
    seed: u64,
    #[serde(default = "bringup_default")]
    bringup_s: f64,
    cars: Vec<CarEntry>,
    maneuver: Option<RawPhase>,
    #[serde(default)]
    phases: Vec<RawPhase>,
    #[serde(default)]
    faults: Faults,
    camera_fps: Option<f64>,
}

fn one() -> u64 {
    1
}

fn bringup_default() -> f64 {
    40.0
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum KindName {
    Goto,
    Formation,
    Rendezvous,
    Circle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum ShapeName {
    Line,
    Wedge,
}

/// One `[maneuver]` or `[[phases]]` table: every field of every kind, checked per kind.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPhase {
    kind: Option<KindName>,
    start_s: Option<f64>,
    timeout_s: Option<f64>,
    hold_s: Option<f64>,
    tolerance_mm: Option<f64>,
    cars: Option<Vec<GotoCar>>,
    shape: Option<ShapeName>,
    leader: Option<u8>,
    followers: Option<Vec<u8>>,
    spacing_units: Option<u16>,
    speed_mm_s: Option<i64>,
    waypoints: Option<Vec<[u16; 2]>>,
    waypoint_at_s: Option<Vec<f64>>,
    reach_units: Option<u16>,
    radius_units: Option<u16>,
    centre: Option<[u16; 2]>,
}

/// Why an experiment could not be loaded or run.
#[derive(Debug)]
pub enum ExperimentError {
    /// The file could not be read.
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML does not describe an experiment (syntax, a missing or unknown key, a wrong type).
    Parse(toml::de::Error),
    /// The experiment is inconsistent.
    Invalid(Invalid),
    /// An error in this file.
    InFile {
        /// The file.
        path: PathBuf,
        /// The error.
        source: Box<ExperimentError>,
    },
    /// The world failed.
    World(WorldError),
    /// A car did not complete bring-up in time.
    BringUp {
        /// The car.
        id: u8,
        /// Its last status, if any.
        last: Option<Status>,
    },
    /// A car refused or failed a maneuver start.
    ManeuverRefused {
        /// The car.
        id: u8,
        /// What it answered.
        reply: String,
    },
    /// An output could not be written.
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// What is wrong with a car reference in a phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CarProblem {
    /// The car is not in `[[cars]]`.
    NotInExperiment,
    /// The car is named twice.
    Duplicate,
    /// A follower is the leader.
    IsLeader,
}

/// What is inconsistent in an experiment. Phases are numbered from 1 in the file's order.
#[derive(Debug, Clone, PartialEq)]
pub enum Invalid {
    /// No cars.
    NoCars,
    /// A car ID outside 1..=126 or given twice.
    CarId {
        /// The ID.
        id: u8,
    },
    /// A start pose outside the protocol ranges (X 0..=640, Y 0..=960, heading 0..=6283).
    StartPose {
        /// The car.
        id: u8,
    },
    /// `duration_s` or `bringup_s` not positive and finite.
    Duration,
    /// `camera_fps` outside (0, 60].
    CameraFps {
        /// The value given.
        value: f64,
    },
    /// Neither `[maneuver]` nor `[[phases]]`, or both.
    Maneuvers,
    /// A phase without `kind`.
    MissingKind {
        /// The phase.
        phase: usize,
    },
    /// A field the phase's kind needs is missing.
    Missing {
        /// The phase.
        phase: usize,
        /// Its kind.
        kind: &'static str,
        /// The field.
        field: &'static str,
    },
    /// A field that does not apply to the phase's kind.
    NotApplicable {
        /// The phase.
        phase: usize,
        /// Its kind.
        kind: &'static str,
        /// The field.
        field: &'static str,
    },
    /// A field's value outside its range.
    OutOfRange {
        /// The phase (0: not in a phase).
        phase: usize,
        /// The field.
        field: &'static str,
        /// The value.
        value: f64,
        /// Smallest allowed.
        min: f64,
        /// Largest allowed.
        max: f64,
    },
    /// A car named in a phase is unknown, named twice or the leader.
    Car {
        /// The phase.
        phase: usize,
        /// The field naming it.
        field: &'static str,
        /// The car.
        id: u8,
        /// What is wrong.
        problem: CarProblem,
    },
    /// A car's go-to points: none, more than 7 (more than 1 with `speed_mm_s`), or one
    /// outside X 0..=640, Y 0..=960.
    Points {
        /// The phase.
        phase: usize,
        /// The car.
        id: u8,
    },
    /// Waypoint times: not one per waypoint, or decreasing.
    WaypointTimes {
        /// The phase.
        phase: usize,
    },
    /// A phase's `start_s` before an earlier phase's, or a first phase not starting at 0.
    StartOrder {
        /// The phase.
        phase: usize,
    },
    /// A fault setting outside its range.
    Fault {
        /// The field.
        field: &'static str,
        /// The value.
        value: f64,
    },
}

impl fmt::Display for CarProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            CarProblem::NotInExperiment => "is not one of the experiment's [[cars]]",
            CarProblem::Duplicate => "is named twice",
            CarProblem::IsLeader => "is the leader",
        })
    }
}

impl fmt::Display for Invalid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoCars => write!(f, "no [[cars]]"),
            Self::CarId { id } => write!(f, "car ID {id} is outside 1..=126 or given twice"),
            Self::StartPose { id } => write!(
                f,
                "car {id}: start pose outside X 0..=640, Y 0..=960, heading 0..=6283"
            ),
            Self::Duration => write!(f, "`duration_s` and `bringup_s` must be positive"),
            Self::CameraFps { value } => {
                write!(f, "`camera_fps` = {value} is outside 0 (exclusive) ..= 60")
            }
            Self::Maneuvers => write!(f, "give either one [maneuver] or a list of [[phases]]"),
            Self::MissingKind { phase } => write!(f, "phase {phase}: `kind` is missing"),
            Self::Missing { phase, kind, field } => {
                write!(f, "phase {phase} ({kind}): `{field}` is missing")
            }
            Self::NotApplicable { phase, kind, field } => {
                write!(f, "phase {phase} ({kind}): `{field}` does not apply to {kind}")
            }
            Self::OutOfRange {
                phase,
                field,
                value,
                min,
                max,
            } => {
                if *phase > 0 {
                    write!(f, "phase {phase}: ")?;
                }
                write!(f, "`{field}` = {value} is outside {min}..={max}")
            }
            Self::Car {
                phase,
                field,
                id,
                problem,
            } => write!(f, "phase {phase}: car {id} in `{field}` {problem}"),
            Self::Points { phase, id } => write!(
                f,
                "phase {phase}: car {id} needs 1..=7 points (exactly 1 with `speed_mm_s`) within X 0..=640, Y 0..=960"
            ),
            Self::WaypointTimes { phase } => write!(
                f,
                "phase {phase}: `waypoint_at_s` needs one non-decreasing time per waypoint"
            ),
            Self::StartOrder { phase } => write!(
                f,
                "phase {phase}: `start_s` must not be before an earlier phase's (the first starts at 0)"
            ),
            Self::Fault { field, value } => write!(f, "faults: `{field}` = {value} is out of range"),
        }
    }
}

impl fmt::Display for ExperimentError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Read { path, source } => write!(f, "reading {}: {source}", path.display()),
            Self::Parse(e) => write!(f, "{e}"),
            Self::Invalid(i) => write!(f, "invalid experiment: {i}"),
            Self::InFile { path, source } => write!(f, "{}: {source}", path.display()),
            Self::World(e) => write!(f, "{e}"),
            Self::BringUp { id, last } => {
                write!(
                    f,
                    "car {id} did not complete bring-up (last status {last:?})"
                )
            }
            Self::ManeuverRefused { id, reply } => {
                write!(f, "car {id} did not start the maneuver: {reply}")
            }
            Self::Write { path, source } => write!(f, "writing {}: {source}", path.display()),
        }
    }
}

impl std::error::Error for ExperimentError {}

impl From<WorldError> for ExperimentError {
    fn from(e: WorldError) -> Self {
        Self::World(e)
    }
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

/// Checks one phase table against its kind.
struct PhaseCheck<'a> {
    n: usize,
    kind: &'static str,
    raw: &'a RawPhase,
    cars: &'a [u8],
}

impl PhaseCheck<'_> {
    fn need<T: Clone>(&self, v: &Option<T>, field: &'static str) -> Result<T, Invalid> {
        v.clone().ok_or(Invalid::Missing {
            phase: self.n,
            kind: self.kind,
            field,
        })
    }

    /// Fails if any of `fields` (name, present) is present.
    fn none_of(&self, fields: &[(&'static str, bool)]) -> Result<(), Invalid> {
        match fields.iter().find(|(_, present)| *present) {
            Some((field, _)) => Err(Invalid::NotApplicable {
                phase: self.n,
                kind: self.kind,
                field,
            }),
            None => Ok(()),
        }
    }

    fn range(&self, field: &'static str, v: f64, min: f64, max: f64) -> Result<(), Invalid> {
        if v.is_finite() && (min..=max).contains(&v) {
            Ok(())
        } else {
            Err(Invalid::OutOfRange {
                phase: self.n,
                field,
                value: v,
                min,
                max,
            })
        }
    }

    fn car(&self, field: &'static str, id: u8) -> Result<(), Invalid> {
        if self.cars.contains(&id) {
            Ok(())
        } else {
            Err(Invalid::Car {
                phase: self.n,
                field,
                id,
                problem: CarProblem::NotInExperiment,
            })
        }
    }

    fn check(&self) -> Result<Phase, Invalid> {
        let r = self.raw;
        let n = self.n;
        if let Some(t) = r.timeout_s {
            self.range("timeout_s", t, 0.1, 1e6)?;
        }
        let hold_s = r.hold_s.unwrap_or(DEFAULT_HOLD_S);
        self.range("hold_s", hold_s, 0.0, 1e6)?;
        let start = match r.start_s {
            Some(t) => {
                self.range("start_s", t, 0.0, 1e6)?;
                Start::At(t)
            }
            None => Start::AfterPrevious,
        };
        let goto_fields = [("cars", r.cars.is_some())];
        let formation_fields = [
            ("shape", r.shape.is_some()),
            ("leader", r.leader.is_some()),
            ("followers", r.followers.is_some()),
            ("spacing_units", r.spacing_units.is_some()),
            ("waypoints", r.waypoints.is_some()),
            ("waypoint_at_s", r.waypoint_at_s.is_some()),
            ("reach_units", r.reach_units.is_some()),
        ];
        let circle_fields = [("centre", r.centre.is_some())];
        let radius_field = [("radius_units", r.radius_units.is_some())];
        let (kind, default_tolerance) = match r.kind {
            None => return Err(Invalid::MissingKind { phase: n }),
            Some(KindName::Goto) => {
                self.none_of(&formation_fields)?;
                self.none_of(&circle_fields)?;
                self.none_of(&radius_field)?;
                if let Some(v) = r.speed_mm_s {
                    self.range("speed_mm_s", v as f64, 0.0, 2047.0)?;
                }
                let max_points = if r.speed_mm_s.is_some() {
                    1
                } else {
                    MAX_POINTS
                };
                let cars = r.cars.clone().unwrap_or_default();
                let mut seen = Vec::new();
                for g in &cars {
                    self.car("cars", g.id)?;
                    if seen.contains(&g.id) {
                        return Err(Invalid::Car {
                            phase: n,
                            field: "cars",
                            id: g.id,
                            problem: CarProblem::Duplicate,
                        });
                    }
                    seen.push(g.id);
                    if g.points.is_empty()
                        || g.points.len() > max_points
                        || g.points.iter().any(|p| p[0] > 640 || p[1] > 960)
                    {
                        return Err(Invalid::Points { phase: n, id: g.id });
                    }
                }
                (
                    PhaseKind::Goto {
                        cars,
                        speed_mm_s: r.speed_mm_s.map(|v| v as u16),
                    },
                    DEFAULT_GOTO_TOLERANCE_MM,
                )
            }
            Some(KindName::Formation) => {
                self.none_of(&goto_fields)?;
                self.none_of(&circle_fields)?;
                self.none_of(&radius_field)?;
                let leader = self.need(&r.leader, "leader")?;
                self.car("leader", leader)?;
                let followers = match &r.followers {
                    Some(list) => {
                        let mut seen = Vec::new();
                        for &id in list {
                            self.car("followers", id)?;
                            let problem = if id == leader {
                                Some(CarProblem::IsLeader)
                            } else if seen.contains(&id) {
                                Some(CarProblem::Duplicate)
                            } else {
                                None
                            };
                            if let Some(problem) = problem {
                                return Err(Invalid::Car {
                                    phase: n,
                                    field: "followers",
                                    id,
                                    problem,
                                });
                            }
                            seen.push(id);
                        }
                        seen
                    }
                    None => {
                        let mut ids: Vec<u8> =
                            self.cars.iter().copied().filter(|&c| c != leader).collect();
                        ids.sort_unstable();
                        ids
                    }
                };
                self.range(
                    "followers",
                    followers.len() as f64,
                    0.0,
                    MAX_FOLLOWERS as f64,
                )?;
                let spacing_units = self.need(&r.spacing_units, "spacing_units")?;
                self.range("spacing_units", f64::from(spacing_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, 0.0, 2047.0)?;
                let waypoints = r.waypoints.clone().unwrap_or_default();
                for w in &waypoints {
                    self.range("waypoints", f64::from(w[0]), 0.0, 640.0)?;
                    self.range("waypoints", f64::from(w[1]), 0.0, 960.0)?;
                }
                if let Some(at) = &r.waypoint_at_s {
                    if at.len() != waypoints.len()
                        || at.iter().any(|t| !non_negative(*t))
                        || at.windows(2).any(|w| w[1] < w[0])
                    {
                        return Err(Invalid::WaypointTimes { phase: n });
                    }
                }
                let reach_units = r.reach_units.unwrap_or(DEFAULT_REACH_UNITS);
                self.range("reach_units", f64::from(reach_units), 1.0, 200.0)?;
                (
                    PhaseKind::Formation(FormationPhase {
                        shape: match r.shape {
                            Some(ShapeName::Wedge) => Shape::Wedge,
                            Some(ShapeName::Line) | None => Shape::Line,
                        },
                        leader,
                        followers,
                        spacing_units,
                        speed_mm_s: speed as u16,
                        waypoints,
                        waypoint_at_s: r.waypoint_at_s.clone(),
                        reach_units,
                    }),
                    DEFAULT_FORMATION_TOLERANCE_MM,
                )
            }
            Some(KindName::Rendezvous) => {
                self.none_of(&goto_fields)?;
                self.none_of(&formation_fields)?;
                self.none_of(&circle_fields)?;
                let radius_units = self.need(&r.radius_units, "radius_units")?;
                self.range("radius_units", f64::from(radius_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, 0.0, 2047.0)?;
                (
                    PhaseKind::Rendezvous {
                        radius_units,
                        speed_mm_s: speed as u16,
                    },
                    f64::from(radius_units) * MM_PER_UNIT + RENDEZVOUS_MARGIN_MM,
                )
            }
            Some(KindName::Circle) => {
                self.none_of(&goto_fields)?;
                self.none_of(&formation_fields)?;
                let centre = self.need(&r.centre, "centre")?;
                self.range("centre", f64::from(centre[0]), 0.0, 640.0)?;
                self.range("centre", f64::from(centre[1]), 0.0, 960.0)?;
                let radius_units = self.need(&r.radius_units, "radius_units")?;
                self.range("radius_units", f64::from(radius_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, -2048.0, 2047.0)?;
                (
                    PhaseKind::Circle {
                        centre,
                        radius_units,
                        speed_mm_s: speed as i16,
                    },
                    DEFAULT_CIRCLE_TOLERANCE_MM,
                )
            }
        };
        let tolerance_mm = r.tolerance_mm.unwrap_or(default_tolerance);
        self.range("tolerance_mm", tolerance_mm, 0.0, 5000.0)?;
        Ok(Phase {
            kind,
            start,
            timeout_s: r.timeout_s,
            hold_s,
            tolerance_mm,
        })
    }
}

impl Experiment {
    /// Reads and checks an experiment file; errors name the file.
    pub fn load(path: &Path) -> Result<Self, ExperimentError> {
        let text = fs::read_to_string(path).map_err(|source| ExperimentError::Read {
            path: path.into(),
            source,
        })?;
        Self::parse(&text).map_err(|e| ExperimentError::InFile {
            path: path.into(),
            source: Box::new(e),
        })
    }

    /// Parses and checks an experiment.
    pub fn parse(text: &str) -> Result<Self, ExperimentError> {
        let raw: RawExperiment = toml::from_str(text).map_err(ExperimentError::Parse)?;
        Self::from_raw(raw).map_err(ExperimentError::Invalid)
    }

    fn from_raw(raw: RawExperiment) -> Result<Self, Invalid> {
        if raw.cars.is_empty() {
            return Err(Invalid::NoCars);
        }
        let mut ids = Vec::new();
        for c in &raw.cars {
            if !(1..=126).contains(&c.id) || ids.contains(&c.id) {
                return Err(Invalid::CarId { id: c.id });
            }
            ids.push(c.id);
            if c.x > 640 || c.y > 960 || c.heading_mrad > 6283 {
                return Err(Invalid::StartPose { id: c.id });
            }
        }
        if !positive(raw.duration_s) || !positive(raw.bringup_s) {
            return Err(Invalid::Duration);
        }
        if let Some(value) = raw.camera_fps {
            if !positive(value) || value > 60.0 {
                return Err(Invalid::CameraFps { value });
            }
        }
        let raws: Vec<RawPhase> = match (raw.maneuver, raw.phases.is_empty()) {
            (Some(m), true) => vec![m],
            (None, false) => raw.phases,
            _ => return Err(Invalid::Maneuvers),
        };
        let mut phases = Vec::new();
        let mut last_start = 0.0;
        for (i, r) in raws.iter().enumerate() {
            let kind = match r.kind {
                Some(KindName::Goto) => "goto",
                Some(KindName::Formation) => "formation",
                Some(KindName::Rendezvous) => "rendezvous",
                Some(KindName::Circle) => "circle",
                None => "?",
            };
            let p = PhaseCheck {
                n: i + 1,
                kind,
                raw: r,
                cars: &ids,
            }
            .check()?;
            if let Start::At(t) = p.start {
                if t < last_start || (i == 0 && t != 0.0) {
                    return Err(Invalid::StartOrder { phase: i + 1 });
                }
                last_start = t;
            }
            phases.push(p);
        }
        let e = Experiment {
            name: raw.name,
            duration_s: raw.duration_s,
            seed: raw.seed,
            bringup_s: raw.bringup_s,
            cars: raw.cars,
            phases,
            faults: raw.faults,
            camera_fps: raw.camera_fps,
        };
        e.check_faults()?;
        Ok(e)
    }

    fn check_faults(&self) -> Result<(), Invalid> {
        let f = &self.faults;
        for (field, p) in [
            ("radio_loss", f.radio_loss),
            ("tracking_drop", f.tracking_drop),
            ("lbc.drop", f.lbc.drop),
            ("lbc.corrupt", f.lbc.corrupt),
            ("lbc.suppress", f.lbc.suppress),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(Invalid::Fault { field, value: p });
            }
        }
        for (field, v, ok) in [
            (
                "tracking_rate_hz",
                f.tracking_rate_hz,
                positive(f.tracking_rate_hz) && f.tracking_rate_hz <= 1000.0,
            ),
            (
                "tracking_noise_mm",
                f.tracking_noise_mm,
                non_negative(f.tracking_noise_mm),
            ),
            (
                "tracking_heading_noise_mrad",
                f.tracking_heading_noise_mrad,
                non_negative(f.tracking_heading_noise_mrad),
            ),
            (
                "lbc.reset_every_s",
                f.lbc.reset_every_s,
                non_negative(f.lbc.reset_every_s),
            ),
        ] {
            if !ok {
                return Err(Invalid::Fault { field, value: v });
            }
        }
        Ok(())
    }

    /// The world this experiment runs in.
    pub fn world_config(&self, firmware: &Path) -> WorldConfig {
        let cars = self
            .cars
            .iter()
            .map(|c| CarSpec {
                id: c.id,
                start: Pose {
                    x_mm: f64::from(c.x) * MM_PER_UNIT,
                    y_mm: f64::from(c.y) * MM_PER_UNIT,
                    heading_rad: f64::from(c.heading_mrad) / 1000.0,
                },
            })
            .collect();
        let mut cfg = WorldConfig::new(firmware, cars);
        cfg.seed = self.seed;
        cfg.radio = MediumParams {
            loss_probability: self.faults.radio_loss,
            ..MediumParams::default()
        };
        cfg.tracking = TrackingParams {
            rate_hz: self.faults.tracking_rate_hz,
            noise_mm: self.faults.tracking_noise_mm,
            heading_noise_mrad: self.faults.tracking_heading_noise_mrad,
            latency: Duration::from_millis(self.faults.tracking_latency_ms),
            drop: self.faults.tracking_drop,
        };
        cfg.lbc_faults = self.faults.lbc.into();
        cfg.camera = self.camera_fps.map(|fps| FeedConfig {
            fps,
            seed: self.seed,
            ..FeedConfig::default()
        });
        cfg
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = r#"
name = "two"
duration_s = 30
[[cars]]
id = 1
x = 150
y = 200
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 200
heading_mrad = 1571
[maneuver]
kind = "goto"
[[maneuver.cars]]
id = 1
points = [[150, 500]]
[[maneuver.cars]]
id = 2
points = [[450, 500], [400, 600]]
[faults]
radio_loss = 0.2
[faults.lbc]
drop = 0.001
"#;

    const CARS4: &str = r#"
name = "four"
duration_s = 60
[[cars]]
id = 1
x = 300
y = 300
heading_mrad = 1571
[[cars]]
id = 2
x = 200
y = 150
[[cars]]
id = 3
x = 400
y = 150
[[cars]]
id = 4
x = 300
y = 100
"#;

    const SEQUENCE: &str = r#"
[[phases]]
kind = "formation"
shape = "wedge"
leader = 1
followers = [3, 2, 4]
spacing_units = 100
speed_mm_s = 100
waypoints = [[300, 450], [300, 600]]
timeout_s = 40

[[phases]]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
hold_s = 3

[[phases]]
kind = "circle"
centre = [300, 400]
radius_units = 150
speed_mm_s = -120
start_s = 90
"#;

    fn seq() -> String {
        format!("{CARS4}{SEQUENCE}")
    }

    fn invalid(text: &str) -> Invalid {
        match Experiment::parse(text) {
            Err(ExperimentError::Invalid(i)) => i,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn parses_and_maps_to_a_world() {
        let e = Experiment::parse(TWO).unwrap();
        assert_eq!(e.cars.len(), 2);
        assert_eq!(e.phases.len(), 1);
        assert_eq!(e.phases[0].goto_points(2), vec![[450, 500], [400, 600]]);
        assert_eq!(e.phases[0].start, Start::AfterPrevious);
        assert_eq!(e.phases[0].params_for(1), None);
        let w = e.world_config(Path::new("/fw"));
        assert_eq!(w.cars[1].start.x_mm, 1125.0);
        assert_eq!(w.radio.loss_probability, 0.2);
        assert_eq!(w.lbc_faults.drop, 0.001);
        assert_eq!(w.tracking.rate_hz, 30.0);
        assert!(w.camera.is_none());
    }

    #[test]
    fn camera_feed_from_the_file() {
        let e =
            Experiment::parse(&TWO.replace("duration_s = 30", "duration_s = 30\ncamera_fps = 10"))
                .unwrap();
        let feed = e.world_config(Path::new("/fw")).camera.unwrap();
        assert_eq!(feed.fps, 10.0);
        for v in ["0", "-5", "61", "nan"] {
            let text = TWO.replace(
                "duration_s = 30",
                &format!("duration_s = 30\ncamera_fps = {v}"),
            );
            assert!(matches!(invalid(&text), Invalid::CameraFps { .. }), "{v}");
        }
    }

    #[test]
    fn a_sequence_of_group_phases() {
        let e = Experiment::parse(&seq()).unwrap();
        assert_eq!(e.phases.len(), 3);
        let f = &e.phases[0];
        assert_eq!(f.timeout_s, Some(40.0));
        assert_eq!(f.hold_s, DEFAULT_HOLD_S);
        assert_eq!(f.tolerance_mm, DEFAULT_FORMATION_TOLERANCE_MM);
        // Slots follow the `followers` order; the leader has none.
        let slot = |id| match f.params_for(id) {
            Some(ManeuverParams::Formation {
                slot,
                shape,
                leader,
                spacing_units,
                speed_mm_s,
            }) => {
                assert_eq!(
                    (shape, leader, spacing_units, speed_mm_s),
                    (Shape::Wedge, 1, 100, 100)
                );
                slot
            }
            other => panic!("{other:?}"),
        };
        assert_eq!(
            (slot(1), slot(2), slot(3), slot(4)),
            (None, Some(1), Some(0), Some(2))
        );
        let r = &e.phases[1];
        assert_eq!(
            r.params_for(4),
            Some(ManeuverParams::Rendezvous {
                radius_units: 60,
                speed_mm_s: 200
            })
        );
        assert_eq!(r.tolerance_mm, 475.0);
        assert_eq!(r.hold_s, 3.0);
        let c = &e.phases[2];
        assert_eq!(c.start, Start::At(90.0));
        assert_eq!(
            c.params_for(2),
            Some(ManeuverParams::Circle {
                cx: 300,
                cy: 400,
                radius_units: 150,
                speed_mm_s: -120
            })
        );
        // Every car's parameters encode.
        for p in &e.phases {
            for car in &e.cars {
                p.params_for(car.id).unwrap().encode().unwrap();
            }
        }
    }

    #[test]
    fn goto_with_a_speed_uses_the_group_law() {
        let t = TWO.replace("kind = \"goto\"", "kind = \"goto\"\nspeed_mm_s = 200");
        // One point per car with the group law.
        assert_eq!(invalid(&t), Invalid::Points { phase: 1, id: 2 });
        let t = t.replace("[[450, 500], [400, 600]]", "[[450, 500]]");
        let e = Experiment::parse(&t).unwrap();
        let p = &e.phases[0];
        assert_eq!(
            p.params_for(2),
            Some(ManeuverParams::GoTo {
                x: 450,
                y: 500,
                speed_mm_s: 200
            })
        );
        assert_eq!(p.tolerance_mm, DEFAULT_GOTO_TOLERANCE_MM);
        // Without a speed: the console go-to, no group parameters.
        let e = Experiment::parse(TWO).unwrap();
        assert_eq!(e.phases[0].params_for(2), None);
    }

    #[test]
    fn cars_outside_the_formation_stand_still() {
        let t = seq().replace("followers = [3, 2, 4]", "followers = [3]");
        let e = Experiment::parse(&t).unwrap();
        assert_eq!(e.phases[0].params_for(2), None);
        assert!(e.phases[0].params_for(1).is_some());
        assert!(e.phases[0].params_for(3).is_some());
    }

    #[test]
    fn default_followers_are_the_other_cars_by_id() {
        let t = seq().replace("followers = [3, 2, 4]\n", "");
        let e = Experiment::parse(&t).unwrap();
        match &e.phases[0].kind {
            PhaseKind::Formation(f) => assert_eq!(f.followers, vec![2, 3, 4]),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_experiments_are_rejected_with_reasons() {
        let bad = |from: &str, to: &str| {
            assert!(TWO.contains(from), "{from}");
            Experiment::parse(&TWO.replace(from, to)).unwrap_err()
        };
        assert!(matches!(
            bad("id = 2\nx", "id = 1\nx"),
            ExperimentError::Invalid(Invalid::CarId { id: 1 })
        ));
        assert!(matches!(
            bad("[[150, 500]]", "[[150, 5000]]"),
            ExperimentError::Invalid(Invalid::Points { phase: 1, id: 1 })
        ));
        assert!(matches!(
            bad("radio_loss = 0.2", "radio_loss = 2.0"),
            ExperimentError::Invalid(Invalid::Fault {
                field: "radio_loss",
                ..
            })
        ));
        assert!(matches!(
            bad("duration_s = 30", "duration_s = -1"),
            ExperimentError::Invalid(Invalid::Duration)
        ));
        assert!(matches!(bad("name =", "nom ="), ExperimentError::Parse(_)));
        assert!(matches!(
            bad("x = 150", "x = 70000"),
            ExperimentError::Parse(_)
        ));
        assert!(matches!(
            bad("kind = \"goto\"", "kind = \"orbit\""),
            ExperimentError::Parse(_)
        ));
        assert!(matches!(
            bad(
                "[faults]",
                "[[phases]]\nkind = \"rendezvous\"\nradius_units = 60\nspeed_mm_s = 100\n[faults]"
            ),
            ExperimentError::Invalid(Invalid::Maneuvers)
        ));
        let none = TWO[..TWO.find("[maneuver]").unwrap()].to_owned();
        assert!(matches!(
            Experiment::parse(&none),
            Err(ExperimentError::Invalid(Invalid::Maneuvers))
        ));
        assert!(matches!(
            bad("kind = \"goto\"\n", ""),
            ExperimentError::Invalid(Invalid::MissingKind { phase: 1 })
        ));
    }

    #[test]
    fn bad_phases_name_the_phase_and_the_field() {
        let bad = |from: &str, to: &str| {
            let t = seq();
            assert!(t.contains(from), "{from}");
            invalid(&t.replace(from, to))
        };
        assert_eq!(
            bad("radius_units = 60\n", "radius_units = 0\n"),
            Invalid::OutOfRange {
                phase: 2,
                field: "radius_units",
                value: 0.0,
                min: 1.0,
                max: 511.0
            }
        );
        assert_eq!(
            bad("radius_units = 60\n", ""),
            Invalid::Missing {
                phase: 2,
                kind: "rendezvous",
                field: "radius_units"
            }
        );
        assert_eq!(
            bad("hold_s = 3", "hold_s = 3\nleader = 1"),
            Invalid::NotApplicable {
                phase: 2,
                kind: "rendezvous",
                field: "leader"
            }
        );
        assert_eq!(
            bad("followers = [3, 2, 4]", "followers = [3, 2, 9]"),
            Invalid::Car {
                phase: 1,
                field: "followers",
                id: 9,
                problem: CarProblem::NotInExperiment
            }
        );
        assert_eq!(
            bad("followers = [3, 2, 4]", "followers = [3, 1]"),
            Invalid::Car {
                phase: 1,
                field: "followers",
                id: 1,
                problem: CarProblem::IsLeader
            }
        );
        assert_eq!(
            bad("followers = [3, 2, 4]", "followers = [3, 3]"),
            Invalid::Car {
                phase: 1,
                field: "followers",
                id: 3,
                problem: CarProblem::Duplicate
            }
        );
        assert_eq!(
            bad("leader = 1", "leader = 7"),
            Invalid::Car {
                phase: 1,
                field: "leader",
                id: 7,
                problem: CarProblem::NotInExperiment
            }
        );
        assert_eq!(
            bad("timeout_s = 40", "waypoint_at_s = [0.0]"),
            Invalid::WaypointTimes { phase: 1 }
        );
        assert_eq!(
            bad("timeout_s = 40", "waypoint_at_s = [5.0, 1.0]"),
            Invalid::WaypointTimes { phase: 1 }
        );
        assert!(
            Experiment::parse(&seq().replace("timeout_s = 40", "waypoint_at_s = [0, 8]")).is_ok()
        );
        assert_eq!(
            bad("speed_mm_s = -120", "speed_mm_s = -3000"),
            Invalid::OutOfRange {
                phase: 3,
                field: "speed_mm_s",
                value: -3000.0,
                min: -2048.0,
                max: 2047.0
            }
        );
        assert_eq!(
            bad("speed_mm_s = 200", "speed_mm_s = -1"),
            Invalid::OutOfRange {
                phase: 2,
                field: "speed_mm_s",
                value: -1.0,
                min: 0.0,
                max: 2047.0
            }
        );
        assert_eq!(
            bad("spacing_units = 100", "spacing_units = 600"),
            Invalid::OutOfRange {
                phase: 1,
                field: "spacing_units",
                value: 600.0,
                min: 1.0,
                max: 511.0
            }
        );
        assert_eq!(
            bad("centre = [300, 400]", "centre = [300, 1000]"),
            Invalid::OutOfRange {
                phase: 3,
                field: "centre",
                value: 1000.0,
                min: 0.0,
                max: 960.0
            }
        );
        assert_eq!(
            bad("start_s = 90", "start_s = -1"),
            Invalid::OutOfRange {
                phase: 3,
                field: "start_s",
                value: -1.0,
                min: 0.0,
                max: 1e6
            }
        );
        assert_eq!(
            bad("hold_s = 3", "hold_s = 3\nstart_s = 100"),
            Invalid::StartOrder { phase: 3 }
        );
        assert_eq!(
            bad("kind = \"rendezvous\"\n", ""),
            Invalid::MissingKind { phase: 2 }
        );
        // Every message names the phase and the field.
        let msg = bad("radius_units = 60\n", "radius_units = 0\n").to_string();
        assert_eq!(msg, "phase 2: `radius_units` = 0 is outside 1..=511");
    }

    #[test]
    fn load_names_the_file() {
        let dir = std::env::temp_dir().join(format!("arena-exp-load-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.toml");
        fs::write(
            &p,
            seq().replace("radius_units = 60\n", "radius_units = 0\n"),
        )
        .unwrap();
        let e = Experiment::load(&p).unwrap_err();
        let _ = fs::remove_dir_all(&dir);
        assert!(
            matches!(&e, ExperimentError::InFile { path, source }
                if path == &p && matches!(**source, ExperimentError::Invalid(Invalid::OutOfRange { phase: 2, .. }))),
            "{e:?}"
        );
        assert!(e.to_string().starts_with(&p.display().to_string()));
        assert!(e.to_string().contains("radius_units"));
    }

    #[test]
    fn shipped_experiments_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../experiments");
        let mut n = 0;
        for entry in fs::read_dir(dir).unwrap() {
            let p = entry.unwrap().path();
            if p.extension().is_some_and(|e| e == "toml") {
                Experiment::load(&p).unwrap_or_else(|e| panic!("{e}"));
                n += 1;
            }
        }
        assert!(n >= 3);
    }
}
