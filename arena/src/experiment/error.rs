//! Why an experiment cannot be loaded or run.

use super::*;

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
    /// A car's firmware (`firmware` of `[[cars]]`) could not be found or built.
    Firmware {
        /// The car.
        id: u8,
        /// Why.
        reason: String,
    },
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
    /// A car's firmware stopped during bring-up, or during the maneuvers with
    /// `on_car_failure = "abort"`.
    CarFailed {
        /// The car.
        id: u8,
        /// When, s of world time.
        t: f64,
        /// Why.
        reason: String,
    },
    /// Cancelled (Ctrl-C) before the maneuvers started.
    Cancelled,
    /// An output could not be written.
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The recording (`run.mcap`, the live view, the plots or the report) failed.
    Recording(String),
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
    /// `name` is not one plain file name (see [`super::check::name_is_safe`]).
    Name {
        /// The name given.
        name: String,
    },
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
    /// A car's radio channel is above the highest one.
    RadioChannel {
        /// The car.
        id: u8,
        /// Its channel.
        channel: u8,
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
    /// A phase's `kind` is neither one of the kinds nor a registered law.
    UnknownKind {
        /// The phase.
        phase: usize,
        /// The kind given.
        kind: String,
    },
    /// A phase table that does not read (a wrong type, an unknown key of a kind with its own
    /// fields).
    PhaseTable {
        /// The phase.
        phase: usize,
        /// What is wrong.
        what: String,
    },
    /// A law's parameter or option is unknown, missing or out of range.
    LawArgument {
        /// The phase.
        phase: usize,
        /// The law.
        law: &'static str,
        /// The car whose `[[phases.cars]]` values are wrong (`None`: the phase's).
        car: Option<u8>,
        /// What is wrong, and what the law takes.
        message: String,
    },
    /// A car's `firmware` names no program (lowercase letters, digits and `_`) and is no path.
    Firmware {
        /// The car.
        id: u8,
        /// The name given.
        name: String,
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
            Self::Name { name } => write!(
                f,
                "`name` = {name:?} must be 1..=100 ASCII letters, digits, '-', '_' or '.', not starting with '.'"
            ),
            Self::CarId { id } => write!(f, "car ID {id} is outside 1..=126 or given twice"),
            Self::StartPose { id } => write!(
                f,
                "car {id}: start pose outside X 0..=640, Y 0..=960, heading 0..=6283"
            ),
            Self::RadioChannel { id, channel } => write!(
                f,
                "car {id}: radio_channel {channel} is outside 0..={}",
                crate::world::MAX_RADIO_CHANNEL
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
            Self::UnknownKind { phase, kind } => {
                let laws: Vec<&str> = maneuvers::LAWS.iter().map(|l| l.name).collect();
                write!(
                    f,
                    "phase {phase}: unknown kind `{kind}`; the kinds are program and the registered laws: {}",
                    laws.join(", ")
                )
            }
            Self::PhaseTable { phase, what } => write!(f, "phase {phase}: {what}"),
            Self::LawArgument {
                phase,
                law,
                car: None,
                message,
            } => write!(f, "phase {phase} ({law}): {message}"),
            Self::LawArgument {
                phase,
                law,
                car: Some(id),
                message,
            } => write!(f, "phase {phase} ({law}), car {id}: {message}"),
            Self::Firmware { id, name } => write!(
                f,
                "car {id}: `firmware` = {name:?} is neither a program name (lowercase letters, digits, '_') nor a path to an ELF"
            ),
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
            Self::Firmware { id, reason } => write!(f, "car {id}'s firmware: {reason}"),
            Self::BringUp { id, last } => {
                write!(
                    f,
                    "car {id} did not complete bring-up (last status {last:?})"
                )
            }
            Self::ManeuverRefused { id, reply } => {
                write!(f, "car {id} did not start the maneuver: {reply}")
            }
            Self::Cancelled => write!(f, "cancelled during bring-up"),
            Self::CarFailed { id, t, reason } => {
                write!(f, "car {id} failed at {t:.3} s: {reason}")
            }
            Self::Write { path, source } => write!(f, "writing {}: {source}", path.display()),
            Self::Recording(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for ExperimentError {}

impl From<WorldError> for ExperimentError {
    fn from(e: WorldError) -> Self {
        Self::World(e)
    }
}
