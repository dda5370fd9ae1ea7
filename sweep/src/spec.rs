//! The sweep file: a base experiment, a grid or a list of points over its fields, seeds,
//! metrics. [`Sweep::load`] reads and checks it, applying every point to the base experiment's
//! TOML document and checking the result as an experiment, so every error shows before the
//! first run. Format: `docs/sweeps.md`.

use crate::error::{PathProblem, SweepError};
use crate::path;
use crate::plan::Plan;
use arena::experiment::{Experiment, ExperimentError};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Value;

/// The sweep file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    name: Option<String>,
    experiment: PathBuf,
    seeds: Option<Value>,
    metrics: Option<Vec<String>>,
    plot_x: Option<String>,
    out: Option<PathBuf>,
    grid: Option<Vec<RawParameter>>,
    parameters: Option<Vec<String>>,
    points: Option<Vec<Vec<Value>>>,
}

/// One `[[grid]]` table.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawParameter {
    path: String,
    values: Vec<Value>,
}

/// A checked sweep, ready to run.
#[derive(Debug, Clone)]
pub struct Sweep {
    /// What is run and reported.
    pub plan: Plan,
    /// The sweep file.
    pub file: PathBuf,
    /// The base experiment file.
    pub base: PathBuf,
    /// Where the outputs go unless told otherwise (the file's `out`, relative to the current
    /// directory, else `sweep-out/<name>`).
    pub out: PathBuf,
    /// Each point's experiment document (the seed is set per run).
    docs: Vec<Value>,
}

impl Sweep {
    /// Reads and checks a sweep file; the base experiment's path is relative to it.
    pub fn load(file: &Path) -> Result<Self, SweepError> {
        let text = std::fs::read_to_string(file).map_err(|source| SweepError::Read {
            path: file.into(),
            source,
        })?;
        let raw: RawSweep = toml::from_str(&text).map_err(|source| SweepError::Parse {
            path: file.into(),
            source,
        })?;
        let base = file
            .parent()
            .unwrap_or(Path::new("."))
            .join(&raw.experiment);
        let base_text = std::fs::read_to_string(&base).map_err(|source| SweepError::Read {
            path: base.clone(),
            source,
        })?;
        let name = raw.name.clone().unwrap_or_else(|| {
            file.file_stem()
                .map_or("sweep".into(), |s| s.to_string_lossy().into_owned())
        });
        let mut sweep = Self::build(raw, name, &base, &base_text)?;
        sweep.file = file.into();
        Ok(sweep)
    }

    /// Checks a sweep given as text, with its base experiment's text; `base` is only named in
    /// errors and in `plan.json`.
    pub fn parse(text: &str, base: &Path, base_text: &str) -> Result<Self, SweepError> {
        let raw: RawSweep = toml::from_str(text).map_err(|source| SweepError::Parse {
            path: "<sweep>".into(),
            source,
        })?;
        let name = raw.name.clone().unwrap_or_else(|| "sweep".into());
        Self::build(raw, name, base, base_text)
    }

    fn build(
        raw: RawSweep,
        name: String,
        base: &Path,
        base_text: &str,
    ) -> Result<Self, SweepError> {
        let base_err = |e: ExperimentError| SweepError::Base {
            path: base.into(),
            source: Box::new(e),
        };
        let base_exp = Experiment::parse(base_text).map_err(base_err)?;
        let base_doc: Value =
            toml::from_str(base_text).map_err(|e| base_err(ExperimentError::Parse(e)))?;
        let (parameters, points) = match (raw.grid, raw.parameters, raw.points) {
            (Some(grid), None, None) => grid_points(grid)?,
            (None, Some(parameters), Some(points)) => list_points(parameters, points)?,
            _ => return Err(SweepError::GridOrPoints),
        };
        let seeds = seeds(raw.seeds.as_ref(), base_exp.seed)?;
        let metrics = match raw.metrics {
            Some(m) => {
                let mut sorted = m.clone();
                sorted.sort();
                sorted.dedup();
                if m.is_empty() || sorted.len() != m.len() || m.iter().any(|s| s.is_empty()) {
                    return Err(SweepError::Metrics);
                }
                m
            }
            None => default_metrics(base_exp.phases.len()),
        };
        let plot_x = match raw.plot_x {
            Some(x) if parameters.contains(&x) => x,
            Some(x) => return Err(SweepError::PlotX { name: x }),
            None => parameters[0].clone(),
        };
        // Each value on its own, so an error names the parameter ...
        for (k, p) in parameters.iter().enumerate() {
            let mut seen: Vec<&Value> = Vec::new();
            for point in &points {
                if seen.contains(&&point[k]) {
                    continue;
                }
                seen.push(&point[k]);
                let mut doc = base_doc.clone();
                apply(&mut doc, p, &point[k])?;
                check(&doc).map_err(|reason| SweepError::Parameter {
                    path: p.clone(),
                    value: point[k].to_string(),
                    problem: PathProblem::Rejected(reason),
                })?;
            }
        }
        // ... then each point as a whole.
        let mut docs = Vec::with_capacity(points.len());
        for (i, point) in points.iter().enumerate() {
            let mut doc = base_doc.clone();
            // The car count first, so paths into the cars see the cars that stay.
            let order = parameters
                .iter()
                .enumerate()
                .filter(|(_, p)| *p == path::CARS)
                .chain(
                    parameters
                        .iter()
                        .enumerate()
                        .filter(|(_, p)| *p != path::CARS),
                );
            for (k, p) in order {
                apply(&mut doc, p, &point[k])?;
            }
            check(&doc).map_err(|reason| SweepError::Point {
                point: i,
                values: describe(&parameters, point),
                reason,
            })?;
            docs.push(doc);
        }
        let plan = Plan {
            name: name.clone(),
            base: base.to_string_lossy().into_owned(),
            parameters,
            points,
            seeds,
            metrics,
            plot_x,
        };
        Ok(Sweep {
            plan,
            file: PathBuf::new(),
            base: base.into(),
            out: raw
                .out
                .unwrap_or_else(|| PathBuf::from("sweep-out").join(&name)),
            docs,
        })
    }

    /// The experiment file (TOML) of run `k` of the plan: its point's document with its seed.
    pub fn experiment_text(&self, k: usize) -> String {
        let run = self.plan.run(k);
        let mut doc = self.docs[run.point].clone();
        if let Value::Table(t) = &mut doc {
            // Seeds above i64::MAX do not occur: `seeds` checks them.
            t.insert(
                "seed".into(),
                Value::Integer(i64::try_from(run.seed).unwrap_or(i64::MAX)),
            );
        }
        toml::to_string(&doc).unwrap_or_default()
    }
}

fn apply(doc: &mut Value, p: &str, v: &Value) -> Result<(), SweepError> {
    path::set(doc, p, v).map_err(|problem| SweepError::Parameter {
        path: p.to_owned(),
        value: v.to_string(),
        problem,
    })
}

/// Checks a document as an experiment; the checker's message, short.
fn check(doc: &Value) -> Result<(), String> {
    let text = toml::to_string(doc).map_err(|e| e.to_string())?;
    match Experiment::parse(&text) {
        Ok(_) => Ok(()),
        Err(ExperimentError::Parse(e)) => Err(e.message().to_owned()),
        Err(e) => Err(e.to_string()),
    }
}

/// `path = value, ...` of a point.
pub(crate) fn describe(parameters: &[String], point: &[Value]) -> String {
    parameters
        .iter()
        .zip(point)
        .map(|(p, v)| format!("{p} = {v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

fn check_names(names: &[&str]) -> Result<(), SweepError> {
    for (i, n) in names.iter().enumerate() {
        path::check_syntax(n).map_err(|problem| SweepError::Parameter {
            path: (*n).to_owned(),
            value: String::new(),
            problem,
        })?;
        if names[..i].contains(n) {
            return Err(SweepError::DuplicateParameter {
                path: (*n).to_owned(),
            });
        }
    }
    Ok(())
}

/// The cartesian product of the grid, the first parameter varying slowest.
fn grid_points(grid: Vec<RawParameter>) -> Result<(Vec<String>, Vec<Vec<Value>>), SweepError> {
    if grid.is_empty() {
        return Err(SweepError::EmptyGrid { path: None });
    }
    if let Some(p) = grid.iter().find(|p| p.values.is_empty()) {
        return Err(SweepError::EmptyGrid {
            path: Some(p.path.clone()),
        });
    }
    check_names(&grid.iter().map(|p| p.path.as_str()).collect::<Vec<_>>())?;
    let mut points: Vec<Vec<Value>> = vec![Vec::new()];
    for p in &grid {
        points = points
            .iter()
            .flat_map(|prefix| {
                p.values.iter().map(move |v| {
                    let mut point = prefix.clone();
                    point.push(v.clone());
                    point
                })
            })
            .collect();
    }
    Ok((grid.into_iter().map(|p| p.path).collect(), points))
}

fn list_points(
    parameters: Vec<String>,
    points: Vec<Vec<Value>>,
) -> Result<(Vec<String>, Vec<Vec<Value>>), SweepError> {
    if parameters.is_empty() || points.is_empty() {
        return Err(SweepError::EmptyPoints);
    }
    check_names(&parameters.iter().map(String::as_str).collect::<Vec<_>>())?;
    if let Some((point, p)) = points
        .iter()
        .enumerate()
        .find(|(_, p)| p.len() != parameters.len())
    {
        return Err(SweepError::PointWidth {
            point,
            expected: parameters.len(),
            found: p.len(),
        });
    }
    Ok((parameters, points))
}

/// `seeds = N` (base, base + 1, ...; default 1) or `seeds = [..]`, sorted.
fn seeds(v: Option<&Value>, base: u64) -> Result<Vec<u64>, SweepError> {
    let as_seed = |v: &Value| match v {
        Value::Integer(s) if *s >= 0 => u64::try_from(*s).ok(),
        _ => None,
    };
    let mut list: Vec<u64> = match v {
        None => vec![base],
        Some(Value::Integer(n)) if *n >= 1 => (0..*n)
            .map(|i| {
                base.checked_add(i as u64)
                    .filter(|s| i64::try_from(*s).is_ok())
            })
            .collect::<Option<_>>()
            .ok_or(SweepError::Seeds)?,
        Some(Value::Array(a)) if !a.is_empty() => a
            .iter()
            .map(as_seed)
            .collect::<Option<_>>()
            .ok_or(SweepError::Seeds)?,
        Some(_) => return Err(SweepError::Seeds),
    };
    let n = list.len();
    list.sort_unstable();
    list.dedup();
    if list.len() != n || list.iter().any(|s| i64::try_from(*s).is_err()) {
        return Err(SweepError::Seeds);
    }
    Ok(list)
}

/// Whether every phase completed, the closest approach, the number of collisions, and each
/// phase's time to converge and final error.
pub fn default_metrics(phases: usize) -> Vec<String> {
    let mut m: Vec<String> = ["completed", "min_separation_mm", "collisions.count"]
        .iter()
        .map(|s| (*s).to_owned())
        .collect();
    for i in 0..phases {
        m.push(format!("phases.{i}.converged_s"));
        m.push(format!("phases.{i}.final_error_mm"));
    }
    m
}
