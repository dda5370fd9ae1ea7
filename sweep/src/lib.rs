//! Parameter studies over arena experiments.
//!
//! A sweep file ([`Sweep::load`]) names a base experiment, a grid (cartesian product) or a list
//! of points over any of its fields (TOML field paths such as `faults.radio_loss` or
//! `phases.0.speed_mm_s`, and `cars`, the number of cars), and seeds. [`run_sweep`] runs every
//! point with every seed on a pool of workers, each run an arena experiment on the
//! virtual-time engine (a function of its file and seed) in `runs/<point>-s<seed>/`, keeping
//! runs an earlier, interrupted run of the sweep finished; then writes `runs.csv` (every run's
//! summary metrics), `aggregate.csv` (mean, standard deviation and 95 % confidence interval
//! per point) and plots. A sweep can be split into shares ([`Shard`]) run on different
//! machines and joined by [`merge`]; [`slurm::script`] submits one as a Slurm job array.
//! `docs/sweeps.md` describes the file and the outputs.

#![forbid(unsafe_code)]

pub mod error;
pub mod exec;
pub mod merge;
pub mod output;
pub mod path;
pub mod plan;
pub mod plot;
pub mod slurm;
pub mod spec;
pub mod state;
pub mod stats;
pub mod table;

pub use error::{PathProblem, SweepError};
pub use exec::{run_sweep, Event, Options, Report};
pub use merge::{merge, MergeReport};
pub use output::Outputs;
pub use plan::{Plan, RunSpec, Shard};
pub use spec::Sweep;
pub use state::RunState;
