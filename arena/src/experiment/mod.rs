//! Experiments as files: a TOML document names the cars and their start poses, the maneuvers
//! (one `[maneuver]`, or a sequence of `[[phases]]`) with their parameters, the duration and
//! the faults, the car engine. [`Experiment::load`] reads and checks one; [`run`] plays it in
//! a [`World`](crate::world::World) (by default every car on the soft core's model in virtual
//! time) and writes the results (trajectory CSVs, an event log, a JSON summary and an SVG plot)
//! to a directory. The format and the metrics are described in `docs/experiments.md`.

use crate::camera_feed::FeedConfig;
use crate::radio_medium::MediumParams;
use crate::world::{CarSpec, EngineKind, TrackingParams, WorldConfig, WorldError, MM_PER_UNIT};
use lbc_emu::{FaultConfig, Pose};
use maneuvers::{Circle, Formation, GoTo, LawInfo, ManeuverParams, Overrides, Rendezvous, Shape};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Duration;
use ubc_app::program::console::{Status, MAX_POINTS};

pub use crate::recording::RunOptions;
pub use crate::runner::{run, run_with, CarFailure, CarResult, PhaseResult, Progress, Summary};
pub use error::{CarProblem, ExperimentError, Invalid};

mod check;
mod error;
mod law_phase;
mod raw;
use raw::RawExperiment;
#[cfg(test)]
mod tests;

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
    /// Whether each car's vision unit turns the camera's pixels into runs (`vision_unit`,
    /// default true); false runs the cars as boards without one (the firmware then processes
    /// the pixels).
    pub vision_unit: bool,
    /// What runs the cars' firmware (`engine = "iss"`, the default, or `"qemu"`).
    pub engine: EngineKind,
    /// Threads stepping the cars on the virtual-time engine (the outputs do not depend on
    /// it); default 1.
    pub threads: usize,
    /// Pace the virtual clock to the wall clock (set by `almc experiment run --realtime`;
    /// always so with QEMU).
    pub realtime: bool,
    /// What happens when a car's firmware stops running.
    pub on_car_failure: FailurePolicy,
    /// Cars whose processor time is profiled by function (`profile-car<ID>.txt`; virtual-time
    /// engine only).
    pub profile_cars: Vec<u8>,
    /// The directory relative firmware paths of `[[cars]]` are taken from (the file's
    /// directory; `None`: the current directory).
    pub base_dir: Option<PathBuf>,
}

/// What the world and the run do when a car's firmware stops (trap, exit, stuck processor,
/// killed emulator).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum FailurePolicy {
    /// Stop the car's vehicle at once (as a lab's emergency stop would); the run goes on.
    #[default]
    Stop,
    /// Stop the vehicle and end the run.
    Abort,
    /// Leave the vehicle as the LBC has it.
    Ignore,
}

/// A car and its start pose (tracking units, 2.5 mm; heading mrad counter-clockwise from +X).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
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
    /// This car's firmware: a program's name (`cargo xtask fw --bin NAME` builds it for the
    /// engine's board) or a path to an ELF (containing `/` or ending in `.elf`; relative to
    /// the experiment file). Default: the engine's stock firmware.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub firmware: Option<String>,
    /// The radio channel of the car's module, 0..=15 (default 0). Cars on different channels
    /// neither hear nor disturb each other; each channel in use has its own ground station.
    /// One channel's state schedule has 16 slots: put larger fleets on several channels.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub radio_channel: u8,
}

fn is_zero(v: &u8) -> bool {
    *v == 0
}

/// What runs on a car.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Firmware {
    /// The engine's stock firmware (`--firmware` of the run).
    Stock,
    /// A program built by name for the engine's board.
    Program(String),
    /// An ELF file.
    Elf(PathBuf),
}

impl CarEntry {
    /// What this car runs (relative paths are taken from `base`).
    pub fn firmware(&self, base: Option<&Path>) -> Firmware {
        match self.firmware.as_deref() {
            None | Some("ubc-app") => Firmware::Stock,
            Some(f) if f.contains('/') || f.ends_with(".elf") => {
                let p = Path::new(f);
                Firmware::Elf(match base {
                    Some(b) if p.is_relative() => b.join(p),
                    _ => p.to_path_buf(),
                })
            }
            Some(name) => Firmware::Program(name.to_owned()),
        }
    }
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
    /// Options the group law runs with instead of its defaults (`reverse`, `arrival_units`,
    /// `neighbours`).
    pub overrides: Overrides,
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
    /// Any other registered law, judged by the cars' own reports.
    Law(LawPhase),
    /// Every listed car runs its firmware's program loop.
    Program(ProgramPhase),
}

/// A phase of a registered law other than the four above.
#[derive(Debug, Clone, PartialEq)]
pub struct LawPhase {
    /// The law.
    pub law: &'static LawInfo,
    /// Every car's group command (all cars of the experiment, each with its overrides from
    /// `[[phases.cars]]` applied).
    pub params: Vec<(u8, ManeuverParams)>,
    /// Waypoints `[[x, y], ...]`, tracking units, given to `waypoint_cars`.
    pub waypoints: Vec<[u16; 2]>,
    /// When each waypoint is sent, s after the phase started (`None`: once the first of
    /// `waypoint_cars` reached the previous one).
    pub waypoint_at_s: Option<Vec<f64>>,
    /// A car has reached a waypoint within this distance, tracking units.
    pub reach_units: u16,
    /// The cars the waypoints go to; the first one's arrival sends the next.
    pub waypoint_cars: Vec<u8>,
}

/// A `program` phase.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgramPhase {
    /// The cars whose program runs.
    pub cars: Vec<u8>,
    /// Its arguments.
    pub args: Vec<i16>,
}

/// Where a phase's waypoints go and when.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaypointPlan<'a> {
    /// The waypoints.
    pub waypoints: &'a [[u16; 2]],
    /// Their times, if given.
    pub at_s: Option<&'a [f64]>,
    /// Reach distance, tracking units.
    pub reach_units: u16,
    /// The cars that get them; the first one's arrival counts.
    pub cars: &'a [u8],
}

impl PhaseKind {
    /// The kind's name in the file.
    pub fn name(&self) -> &'static str {
        match self {
            PhaseKind::Goto { .. } => "goto",
            PhaseKind::Formation(_) => "formation",
            PhaseKind::Rendezvous { .. } => "rendezvous",
            PhaseKind::Circle { .. } => "circle",
            PhaseKind::Law(l) => l.law.name,
            PhaseKind::Program(_) => "program",
        }
    }
}

impl Phase {
    /// The group maneuver parameters car `id` is started with (`None` for a console `goto`,
    /// for a car without a point in a group `goto`, and for a car that is neither leader nor
    /// follower of a formation: these stand still).
    pub fn params_for(&self, id: u8) -> Option<ManeuverParams> {
        self.law_params(id)
            .map(|p| p.with_overrides(merge(p.overrides(), self.overrides)))
    }

    /// The waypoints of a formation (to its leader) or of a law phase.
    pub fn waypoint_plan(&self) -> Option<WaypointPlan<'_>> {
        match &self.kind {
            PhaseKind::Formation(f) => Some(WaypointPlan {
                waypoints: &f.waypoints,
                at_s: f.waypoint_at_s.as_deref(),
                reach_units: f.reach_units,
                cars: core::slice::from_ref(&f.leader),
            }),
            PhaseKind::Law(l) => Some(WaypointPlan {
                waypoints: &l.waypoints,
                at_s: l.waypoint_at_s.as_deref(),
                reach_units: l.reach_units,
                cars: &l.waypoint_cars,
            }),
            _ => None,
        }
    }

    /// Whether car `id` runs its program loop in this phase.
    pub fn runs_program(&self, id: u8) -> bool {
        matches!(&self.kind, PhaseKind::Program(p) if p.cars.contains(&id))
    }

    fn law_params(&self, id: u8) -> Option<ManeuverParams> {
        match &self.kind {
            PhaseKind::Law(l) => l.params.iter().find(|(c, _)| *c == id).map(|(_, p)| *p),
            PhaseKind::Program(_) => None,
            PhaseKind::Goto {
                speed_mm_s: Some(speed),
                ..
            } => self
                .goto_points(id)
                .first()
                .and_then(|p| GoTo::params(p[0], p[1], *speed).ok()),
            PhaseKind::Goto { .. } => None,
            PhaseKind::Formation(f) if f.leader != id && !f.followers.contains(&id) => None,
            PhaseKind::Formation(f) => Formation::params(
                f.shape,
                f.leader,
                f.followers
                    .iter()
                    .position(|&c| c == id)
                    .and_then(|k| u8::try_from(k).ok()),
                f.spacing_units,
                f.speed_mm_s,
            )
            .ok(),
            PhaseKind::Rendezvous {
                radius_units,
                speed_mm_s,
            } => Rendezvous::params(*radius_units, *speed_mm_s).ok(),
            PhaseKind::Circle {
                centre,
                radius_units,
                speed_mm_s,
            } => Circle::params(centre[0], centre[1], *radius_units, *speed_mm_s).ok(),
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

/// `over` where it sets an option, else `base`.
fn merge(base: Overrides, over: Overrides) -> Overrides {
    Overrides {
        reverse: over.reverse.or(base.reverse),
        arrival_units: over.arrival_units.or(base.arrival_units),
        neighbours: over.neighbours.or(base.neighbours),
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
    /// Cars whose firmware dies during the maneuvers (as `kill -9` of its emulator would).
    pub crash: Vec<Crash>,
}

/// A car's firmware killed at a time, to see what the world and the other cars do.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Crash {
    /// The car.
    pub car: u8,
    /// Seconds after the first phase started.
    pub at_s: f64,
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
            crash: Vec::new(),
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

impl Experiment {
    /// Reads and checks an experiment file; errors name the file.
    pub fn load(path: &Path) -> Result<Self, ExperimentError> {
        let text = fs::read_to_string(path).map_err(|source| ExperimentError::Read {
            path: path.into(),
            source,
        })?;
        let mut e = Self::parse(&text).map_err(|e| ExperimentError::InFile {
            path: path.into(),
            source: Box::new(e),
        })?;
        e.base_dir = path.parent().map(Path::to_path_buf);
        Ok(e)
    }

    /// Every car's firmware for `engine`: `None` for the stock firmware, else the ELF (a
    /// program named in the file is built for the engine's board).
    pub fn car_firmware(
        &self,
        engine: EngineKind,
    ) -> Result<Vec<Option<PathBuf>>, ExperimentError> {
        self.cars
            .iter()
            .map(|c| match c.firmware(self.base_dir.as_deref()) {
                Firmware::Stock => Ok(None),
                Firmware::Elf(p) => {
                    if p.is_file() {
                        Ok(Some(p))
                    } else {
                        Err(ExperimentError::Firmware {
                            id: c.id,
                            reason: format!("{} is not a file", p.display()),
                        })
                    }
                }
                Firmware::Program(name) => engine.program_firmware(&name).map(Some).map_err(|e| {
                    ExperimentError::Firmware {
                        id: c.id,
                        reason: format!("program `{name}`: {e}"),
                    }
                }),
            })
            .collect()
    }

    /// Parses and checks an experiment.
    pub fn parse(text: &str) -> Result<Self, ExperimentError> {
        let raw: RawExperiment = toml::from_str(text).map_err(ExperimentError::Parse)?;
        Self::from_raw(raw).map_err(ExperimentError::Invalid)
    }

    /// The world this experiment runs in.
    pub fn world_config(&self, firmware: &Path) -> WorldConfig {
        let cars = self
            .cars
            .iter()
            .map(|c| {
                let mut spec = CarSpec::new(
                    c.id,
                    Pose {
                        x_mm: f64::from(c.x) * MM_PER_UNIT,
                        y_mm: f64::from(c.y) * MM_PER_UNIT,
                        heading_rad: f64::from(c.heading_mrad) / 1000.0,
                    },
                );
                spec.radio_channel = c.radio_channel;
                spec
            })
            .collect();
        let mut cfg = WorldConfig::new(firmware, cars);
        cfg.seed = self.seed;
        cfg.engine = self.engine;
        cfg.threads = self.threads;
        cfg.realtime = self.realtime;
        cfg.stop_failed_cars = self.on_car_failure != FailurePolicy::Ignore;
        cfg.profile_cars.clone_from(&self.profile_cars);
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
            vision_unit: self.vision_unit,
            ..FeedConfig::default()
        });
        cfg
    }
}
