//! Runs a sweep's runs on a pool of worker threads, each run a whole arena experiment on one
//! thread (`threads = 1`) in its own directory `runs/<point>-s<seed>/`. Runs already finished
//! with the same experiment file are kept; the others are done (again). Setting the cancel
//! flag stops the pool: no new run starts, running ones end at once and are marked
//! `interrupted`, so a later run of the sweep does them again.

use crate::error::{write_err, SweepError};
use crate::output::{write_outputs, Outputs};
use crate::plan::{RunSpec, Shard};
use crate::spec::Sweep;
use crate::state::{mark_error, mark_interrupted, RunState};
use arena::experiment::{self, Experiment};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How to run a sweep.
#[derive(Debug, Clone)]
pub struct Options {
    /// Runs at the same time (each on one thread).
    pub workers: usize,
    /// The share of the runs to do.
    pub shard: Shard,
    /// The firmware ELF every car runs.
    pub firmware: PathBuf,
}

/// What the pool reports as it goes (on the calling thread).
#[derive(Debug)]
pub enum Event<'a> {
    /// Before the first run.
    Planned {
        /// Runs in this share.
        scope: usize,
        /// Of those, already finished.
        skipped: usize,
        /// Workers that will run the rest.
        workers: usize,
    },
    /// A run started.
    Started(&'a RunSpec),
    /// A run ended.
    Finished {
        /// The run.
        run: &'a RunSpec,
        /// How it ended.
        state: &'a RunState,
        /// Wall-clock time it took.
        wall: Duration,
    },
}

/// What a sweep run did.
#[derive(Debug)]
pub struct Report {
    /// Runs in this share.
    pub scope: usize,
    /// Runs kept from an earlier run of the sweep.
    pub skipped: usize,
    /// Runs done now, to their end.
    pub ran: usize,
    /// Runs cut short by the stop (done again by the next run of the sweep).
    pub interrupted: usize,
    /// The sweep was stopped before every run was done.
    pub stopped: bool,
    /// The outputs, and every run's state.
    pub outputs: Outputs,
}

impl Report {
    /// Runs of the share that are complete.
    pub fn complete(&self) -> usize {
        self.outputs.count(|s| s.is_complete())
    }

    /// Runs of the share that ended without being complete (error, aborted, cancelled).
    pub fn failed(&self) -> usize {
        self.outputs
            .count(|s| !s.is_complete() && (s.is_finished() || matches!(s, RunState::Error(_))))
    }

    /// Runs of the share still to do (interrupted, never started).
    pub fn unfinished(&self) -> usize {
        self.scope - self.complete() - self.failed()
    }
}

/// Runs the sweep's share into `out` (creating it): `plan.json`, `runs/`, then `runs.csv`,
/// `aggregate.csv` and `plots/` over the share's runs.
pub fn run_sweep(
    sweep: &Sweep,
    out: &Path,
    opts: &Options,
    on_event: &mut dyn FnMut(Event<'_>),
    cancel: &AtomicBool,
) -> Result<Report, SweepError> {
    let runs_dir = out.join("runs");
    std::fs::create_dir_all(&runs_dir).map_err(write_err(&runs_dir))?;
    sweep.plan.write(out)?;
    let scope = sweep.plan.share(opts.shard);
    let to_do: Vec<&RunSpec> = scope
        .iter()
        .filter(|r| !is_done(sweep, &runs_dir, r))
        .collect();
    let workers = opts.workers.max(1).min(to_do.len().max(1));
    on_event(Event::Planned {
        scope: scope.len(),
        skipped: scope.len() - to_do.len(),
        workers,
    });
    let next = AtomicUsize::new(0);
    let ran = AtomicUsize::new(0);
    let interrupted = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<(usize, Option<(RunState, Duration)>)>();
    std::thread::scope(|s| {
        for _ in 0..workers {
            let tx = tx.clone();
            let (next, ran, interrupted) = (&next, &ran, &interrupted);
            let (to_do, runs_dir) = (&to_do, &runs_dir);
            s.spawn(move || loop {
                if cancel.load(Ordering::Relaxed) {
                    break;
                }
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(run) = to_do.get(k) else { break };
                let _ = tx.send((k, None));
                let t0 = Instant::now();
                let state = run_one(sweep, run, runs_dir, &opts.firmware, cancel);
                let counter = if state == RunState::Interrupted {
                    interrupted
                } else {
                    ran
                };
                counter.fetch_add(1, Ordering::Relaxed);
                let _ = tx.send((k, Some((state, t0.elapsed()))));
            });
        }
        drop(tx);
        for (k, end) in rx {
            match end {
                None => on_event(Event::Started(to_do[k])),
                Some((state, wall)) => on_event(Event::Finished {
                    run: to_do[k],
                    state: &state,
                    wall,
                }),
            }
        }
    });
    let outputs = write_outputs(&sweep.plan, &scope, out)?;
    let report = Report {
        scope: scope.len(),
        skipped: scope.len() - to_do.len(),
        ran: ran.load(Ordering::Relaxed),
        interrupted: interrupted.load(Ordering::Relaxed),
        stopped: cancel.load(Ordering::Relaxed),
        outputs,
    };
    Ok(report)
}

/// The run has finished with the experiment file it would be run with now.
fn is_done(sweep: &Sweep, runs_dir: &Path, run: &RunSpec) -> bool {
    let dir = runs_dir.join(run.dir_name());
    RunState::read(&dir).is_finished()
        && std::fs::read_to_string(dir.join("experiment.toml"))
            .is_ok_and(|t| t == sweep.experiment_text(run.index))
}

/// Does one run in `runs_dir/<point>-s<seed>` (emptied first); its final state.
fn run_one(
    sweep: &Sweep,
    run: &RunSpec,
    runs_dir: &Path,
    firmware: &Path,
    cancel: &AtomicBool,
) -> RunState {
    let dir = runs_dir.join(run.dir_name());
    let text = sweep.experiment_text(run.index);
    let prepared = (|| {
        if dir.exists() {
            std::fs::remove_dir_all(&dir)?;
        }
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join("experiment.toml"), &text)
    })();
    if let Err(e) = prepared {
        return RunState::Error(format!("{}: {e}", dir.display()));
    }
    let mut exp = match Experiment::parse(&text) {
        Ok(e) => e,
        Err(e) => {
            let _ = mark_error(&dir, &e.to_string());
            return RunState::read(&dir);
        }
    };
    exp.threads = 1;
    exp.realtime = false;
    let result = catch_unwind(AssertUnwindSafe(|| {
        experiment::run(&exp, firmware, &dir, &mut |_| {}, cancel)
    }));
    let stopped = cancel.load(Ordering::Relaxed);
    match result {
        Ok(Ok(summary)) if summary.cancelled && stopped => {
            let _ = mark_interrupted(&dir);
        }
        Ok(Ok(_)) => {}
        Ok(Err(_)) if stopped => {
            let _ = mark_interrupted(&dir);
        }
        Ok(Err(e)) => {
            if !matches!(RunState::read(&dir), RunState::Error(_)) {
                let _ = mark_error(&dir, &e.to_string());
            }
        }
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let _ = mark_error(&dir, &format!("the run panicked: {what}"));
        }
    }
    RunState::read(&dir)
}
