//! Joins the shares of a sweep run in different directories (`almc sweep run --shard I/N` on
//! several machines or Slurm tasks): checks they hold the same plan, copies every finished run
//! into one directory and writes the outputs over all runs there.

use crate::error::{write_err, SweepError};
use crate::output::{write_outputs, Outputs};
use crate::plan::Plan;
use crate::state::RunState;
use std::path::{Path, PathBuf};

/// What a merge did.
#[derive(Debug)]
pub struct MergeReport {
    /// Runs copied from the shares.
    pub copied: usize,
    /// Runs in no share's directory, or unfinished in all of them (`<point>-s<seed>`).
    pub missing: Vec<String>,
    /// The outputs over every run of the plan.
    pub outputs: Outputs,
}

/// Merges the sweep directories `shares` into `into` (which may be one of them).
pub fn merge(shares: &[PathBuf], into: &Path) -> Result<MergeReport, SweepError> {
    let Some(first) = shares.first() else {
        return Err(SweepError::NotASweep { dir: into.into() });
    };
    let plan = Plan::read(first)?;
    for other in &shares[1..] {
        if !Plan::read(other)?.same_sweep(&plan) {
            return Err(SweepError::PlanMismatch {
                first: first.clone(),
                other: other.clone(),
            });
        }
    }
    if into.join("plan.json").is_file() && !Plan::read(into)?.same_sweep(&plan) {
        return Err(SweepError::PlanMismatch {
            first: first.clone(),
            other: into.into(),
        });
    }
    let runs_dir = into.join("runs");
    std::fs::create_dir_all(&runs_dir).map_err(write_err(&runs_dir))?;
    plan.write(into)?;
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    let mut copied = 0;
    let mut missing = Vec::new();
    for run in plan.runs() {
        let name = run.dir_name();
        let target = runs_dir.join(&name);
        if RunState::read(&target).is_finished() {
            continue;
        }
        let source = shares
            .iter()
            .map(|s| s.join("runs").join(&name))
            .find(|d| !same(d, &target) && RunState::read(d).is_finished());
        match source {
            Some(src) => {
                copy_dir(&src, &target)?;
                copied += 1;
            }
            None => missing.push(name),
        }
    }
    let outputs = write_outputs(&plan, &plan.runs(), into)?;
    Ok(MergeReport {
        copied,
        missing,
        outputs,
    })
}

/// Replaces `to` with a copy of the files of `from` (a run directory has no subdirectories).
fn copy_dir(from: &Path, to: &Path) -> Result<(), SweepError> {
    if to.exists() {
        std::fs::remove_dir_all(to).map_err(write_err(to))?;
    }
    std::fs::create_dir_all(to).map_err(write_err(to))?;
    let entries = std::fs::read_dir(from).map_err(|source| SweepError::Read {
        path: from.into(),
        source,
    })?;
    for e in entries {
        let e = e.map_err(|source| SweepError::Read {
            path: from.into(),
            source,
        })?;
        if e.file_type().is_ok_and(|t| t.is_file()) {
            let dest = to.join(e.file_name());
            std::fs::copy(e.path(), &dest).map_err(write_err(&dest))?;
        }
    }
    Ok(())
}
