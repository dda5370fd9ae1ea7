//! Why a sweep cannot be read, run or merged.

use arena::experiment::ExperimentError;
use std::fmt;
use std::path::PathBuf;

/// What is wrong with a field path or the value put there.
#[derive(Debug, Clone, PartialEq)]
pub enum PathProblem {
    /// The path is empty or has an empty segment (`faults..radio_loss`).
    Syntax,
    /// `seed` is set by the sweep's `seeds`.
    Seed,
    /// A segment indexes an array but is not a number.
    NotAnIndex {
        /// The path up to and including the segment.
        at: String,
    },
    /// An array index past the end of the base experiment's array.
    IndexOutOfRange {
        /// The path up to and including the index.
        at: String,
        /// The array's length.
        len: usize,
    },
    /// A segment goes into a value that is neither a table nor an array.
    NotATable {
        /// The path up to the value.
        at: String,
    },
    /// An array element of something the base experiment does not have.
    NoSuchArray {
        /// The path of the missing array.
        at: String,
    },
    /// The value's TOML type differs from the one in the base experiment.
    WrongType {
        /// The type there.
        expected: &'static str,
        /// The type given.
        found: &'static str,
    },
    /// `cars` is not a whole number of at least 1.
    CarsNotACount,
    /// `cars` asks for more cars than the base experiment has.
    TooFewCars {
        /// `[[cars]]` tables in the base experiment.
        available: usize,
    },
    /// The experiment does not accept the value (an unknown field, a value out of range, an
    /// inconsistent experiment); the message is the experiment checker's.
    Rejected(String),
}

impl fmt::Display for PathProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PathProblem::Syntax => f.write_str("not a field path (segments separated by `.`)"),
            PathProblem::Seed => f.write_str("`seed` is set per run by the sweep's `seeds`"),
            PathProblem::NotAnIndex { at } => write!(f, "`{at}`: an array needs a number here"),
            PathProblem::IndexOutOfRange { at, len } => {
                write!(
                    f,
                    "`{at}`: the base experiment has only {len} elements there"
                )
            }
            PathProblem::NotATable { at } => write!(f, "`{at}` is a value, not a table"),
            PathProblem::NoSuchArray { at } => {
                write!(f, "the base experiment has no `{at}` to index")
            }
            PathProblem::WrongType { expected, found } => {
                let a = |t: &str| if t.starts_with(['a', 'i']) { "an" } else { "a" };
                write!(
                    f,
                    "the base experiment has {} {expected} there, not {} {found}",
                    a(expected),
                    a(found)
                )
            }
            PathProblem::CarsNotACount => f.write_str("`cars` must be a whole number of cars >= 1"),
            PathProblem::TooFewCars { available } => {
                write!(f, "the base experiment has only {available} [[cars]]")
            }
            PathProblem::Rejected(why) => write!(f, "the experiment rejects it: {why}"),
        }
    }
}

/// Why a sweep could not be read, run, merged or written.
#[derive(Debug)]
pub enum SweepError {
    /// A file could not be read.
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The sweep file is not valid TOML or has an unknown or mistyped key.
    Parse {
        /// The sweep file.
        path: PathBuf,
        /// The TOML error.
        source: toml::de::Error,
    },
    /// The base experiment does not load.
    Base {
        /// The base experiment file.
        path: PathBuf,
        /// Why.
        source: Box<ExperimentError>,
    },
    /// Neither `[[grid]]` nor `points` is given, or both are.
    GridOrPoints,
    /// `[[grid]]` has no parameter, or a parameter has no value.
    EmptyGrid {
        /// The parameter without values, if that is the problem.
        path: Option<String>,
    },
    /// `points` is empty (or `parameters` is).
    EmptyPoints,
    /// A point has a different number of values than `parameters` has names.
    PointWidth {
        /// The point, from 0.
        point: usize,
        /// Values it should have.
        expected: usize,
        /// Values it has.
        found: usize,
    },
    /// A parameter is named twice.
    DuplicateParameter {
        /// Its path.
        path: String,
    },
    /// A field path or a value for it is wrong.
    Parameter {
        /// The path.
        path: String,
        /// The value, as TOML (empty when the path itself is wrong).
        value: String,
        /// What is wrong.
        problem: PathProblem,
    },
    /// Every value is acceptable on its own but a point's combination is not an experiment.
    Point {
        /// The point, from 0.
        point: usize,
        /// Its values, `path = value, ...`.
        values: String,
        /// The experiment checker's message.
        reason: String,
    },
    /// `seeds` is neither a count >= 1 nor a non-empty list of distinct seeds >= 0.
    Seeds,
    /// `metrics` is empty or names a metric twice.
    Metrics,
    /// A metric is not a column of the runs' summaries.
    UnknownMetric {
        /// The metric.
        metric: String,
        /// Columns that start the same way, as hints.
        near: Vec<String>,
    },
    /// `plot_x` is not one of the parameters.
    PlotX {
        /// The name given.
        name: String,
    },
    /// `--shard I/N` with N = 0 or I >= N.
    Shard {
        /// I.
        index: usize,
        /// N.
        count: usize,
    },
    /// A directory given to merge holds no sweep (`plan.json`).
    NotASweep {
        /// The directory.
        dir: PathBuf,
    },
    /// Directories given to merge hold different sweeps.
    PlanMismatch {
        /// The first directory.
        first: PathBuf,
        /// The one that differs.
        other: PathBuf,
    },
    /// A file or directory could not be written.
    Write {
        /// The path.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A plot could not be drawn.
    Plot {
        /// The file.
        path: PathBuf,
        /// The drawing library's message.
        reason: String,
    },
}

impl fmt::Display for SweepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SweepError::Read { path, source } => write!(f, "{}: {source}", path.display()),
            SweepError::Parse { path, source } => write!(f, "{}: {source}", path.display()),
            SweepError::Base { path, source } => {
                write!(f, "base experiment {}: {source}", path.display())
            }
            SweepError::GridOrPoints => f.write_str(
                "give either [[grid]] tables (path, values) or `parameters` with `points`, not both",
            ),
            SweepError::EmptyGrid { path: Some(p) } => {
                write!(f, "empty grid: parameter `{p}` has no values")
            }
            SweepError::EmptyGrid { path: None } => f.write_str("empty grid: no [[grid]] parameter"),
            SweepError::EmptyPoints => {
                f.write_str("no points: `parameters` and `points` must not be empty")
            }
            SweepError::PointWidth {
                point,
                expected,
                found,
            } => write!(
                f,
                "point {point} has {found} values but `parameters` names {expected}"
            ),
            SweepError::DuplicateParameter { path } => {
                write!(f, "parameter `{path}` is given twice")
            }
            SweepError::Parameter {
                path,
                value,
                problem,
            } if value.is_empty() => write!(f, "parameter `{path}`: {problem}"),
            SweepError::Parameter {
                path,
                value,
                problem,
            } => write!(f, "parameter `{path}` = {value}: {problem}"),
            SweepError::Point {
                point,
                values,
                reason,
            } => write!(f, "point {point} ({values}): the experiment rejects it: {reason}"),
            SweepError::Seeds => f.write_str(
                "`seeds` must be a count >= 1 (seeds base, base+1, ...) or a non-empty list of distinct seeds >= 0",
            ),
            SweepError::Metrics => f.write_str("`metrics` must be a non-empty list of distinct names"),
            SweepError::UnknownMetric { metric, near } => {
                write!(f, "metric `{metric}` is not a column of the runs' summaries")?;
                if !near.is_empty() {
                    write!(f, " (columns: {})", near.join(", "))?;
                }
                Ok(())
            }
            SweepError::PlotX { name } => write!(f, "`plot_x` = `{name}` is not a parameter"),
            SweepError::Shard { index, count } => {
                write!(f, "shard {index}/{count}: needs 0 <= I < N")
            }
            SweepError::NotASweep { dir } => {
                write!(f, "{}: no plan.json, not a sweep's output", dir.display())
            }
            SweepError::PlanMismatch { first, other } => write!(
                f,
                "{} and {} hold different sweeps (plan.json differs)",
                first.display(),
                other.display()
            ),
            SweepError::Write { path, source } => write!(f, "{}: {source}", path.display()),
            SweepError::Plot { path, reason } => write!(f, "{}: {reason}", path.display()),
        }
    }
}

impl std::error::Error for SweepError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            SweepError::Read { source, .. } | SweepError::Write { source, .. } => Some(source),
            SweepError::Parse { source, .. } => Some(source),
            SweepError::Base { source, .. } => Some(source.as_ref()),
            _ => None,
        }
    }
}

/// An I/O error writing `path`.
pub(crate) fn write_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> SweepError + '_ {
    move |source| SweepError::Write {
        path: path.into(),
        source,
    }
}
