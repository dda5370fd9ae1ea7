//! The sweep's outputs over a set of its runs: `runs.csv`, `aggregate.csv` and `plots/`.
//! They depend only on the runs' summaries, in plan order, so a sweep run on 1 or 8 workers,
//! or in shares merged afterwards, writes the same bytes.

use crate::error::SweepError;
use crate::plan::{Plan, RunSpec};
use crate::plot::write_plots;
use crate::state::RunState;
use crate::stats::write_aggregate;
use crate::table::{columns, write_runs_csv, RunRow};
use std::path::{Path, PathBuf};

/// What was written.
#[derive(Debug)]
pub struct Outputs {
    /// Every run in scope, in plan order.
    pub rows: Vec<RunRow>,
    /// `runs.csv`.
    pub runs_csv: PathBuf,
    /// `aggregate.csv`.
    pub aggregate_csv: PathBuf,
    /// The plots (SVG and PNG of each metric).
    pub plots: Vec<PathBuf>,
}

impl Outputs {
    /// Runs whose state satisfies `f`.
    pub fn count(&self, f: impl Fn(&RunState) -> bool) -> usize {
        self.rows.iter().filter(|r| f(&r.state)).count()
    }
}

/// Reads the runs `scope` from `out/runs/` and writes the outputs into `out`. A metric that is
/// no column of any run's summary is an error (after `runs.csv` is written, so its columns can
/// be looked up).
pub fn write_outputs(plan: &Plan, scope: &[RunSpec], out: &Path) -> Result<Outputs, SweepError> {
    let runs_dir = out.join("runs");
    let rows: Vec<RunRow> = scope
        .iter()
        .map(|r| RunRow::read(&runs_dir, r.clone()))
        .collect();
    let cols = columns(rows.iter().map(|r| &r.order));
    let runs_csv = out.join("runs.csv");
    write_runs_csv(&runs_csv, plan, &rows, &cols)?;
    if !cols.is_empty() {
        if let Some(m) = plan.metrics.iter().find(|m| !cols.contains(m)) {
            let head = m.split('.').next().unwrap_or("");
            let near: Vec<String> = cols
                .iter()
                .filter(|c| c.split('.').next() == Some(head))
                .take(12)
                .cloned()
                .collect();
            return Err(SweepError::UnknownMetric {
                metric: m.clone(),
                near,
            });
        }
    }
    let aggregate_csv = out.join("aggregate.csv");
    write_aggregate(&aggregate_csv, plan, &rows)?;
    let plots = write_plots(&out.join("plots"), plan, &rows)?;
    Ok(Outputs {
        rows,
        runs_csv,
        aggregate_csv,
        plots,
    })
}
