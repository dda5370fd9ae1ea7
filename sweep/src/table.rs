//! `runs.csv`: one row per run, in plan order (point, then seed): the run's point, seed and
//! state, its parameter values, and every number and boolean of its `summary.json` as a column.
//!
//! A summary is flattened in the order of the file: nested objects give dotted names
//! (`radio.medium.collisions`), the `phases` and `cars` arrays give one group per element
//! (`phases.0.converged_s`, `cars.1.distance_mm`), every other array gives its length
//! (`collisions.count`, `cars.0.wall_violations.count`); strings are left out and `null` is an
//! empty cell. The columns are those of every run together, each where it first appears.

use crate::error::{write_err, SweepError};
use crate::plan::{Plan, RunSpec};
use crate::state::RunState;
use serde::de::{DeserializeSeed, Deserializer, IgnoredAny, MapAccess, SeqAccess, Visitor};
use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::Path;

/// One cell of a flattened summary.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    /// A number, as written in `runs.csv`.
    Num(String),
    /// A boolean.
    Bool(bool),
    /// `null`.
    Null,
}

impl Cell {
    /// The cell as a number (booleans are 0 and 1).
    pub fn value(&self) -> Option<f64> {
        match self {
            Cell::Num(s) => s.parse().ok(),
            Cell::Bool(b) => Some(if *b { 1.0 } else { 0.0 }),
            Cell::Null => None,
        }
    }

    fn text(&self) -> String {
        match self {
            Cell::Num(s) => s.clone(),
            Cell::Bool(b) => b.to_string(),
            Cell::Null => String::new(),
        }
    }
}

/// A flattened summary: columns in the file's order.
pub type Flat = Vec<(String, Cell)>;

/// Flattens a summary (`summary.json` text).
pub fn flatten(json: &str) -> Result<Flat, serde_json::Error> {
    let mut out = Vec::new();
    let mut de = serde_json::Deserializer::from_str(json);
    Walker {
        prefix: String::new(),
        out: &mut out,
    }
    .deserialize(&mut de)?;
    de.end()?;
    Ok(out)
}

/// With serde_json's `arbitrary_precision` feature (which a dependency of the arena turns on)
/// a number reaches a visitor as a map of this one key to the number's text.
const NUMBER_TOKEN: &str = "$serde_json::private::Number";

/// A number's text as the plain visitor would give it: integers as they are, others through
/// `f64` (`3.0` is `3`).
fn number_text(text: &str) -> String {
    if text.parse::<i64>().is_ok() || text.parse::<u64>().is_ok() {
        return text.to_owned();
    }
    text.parse::<f64>()
        .map_or_else(|_| text.to_owned(), |v| format!("{v}"))
}

struct Walker<'a> {
    prefix: String,
    out: &'a mut Flat,
}

impl Walker<'_> {
    fn child(&mut self, key: &str) -> Walker<'_> {
        let prefix = if self.prefix.is_empty() {
            key.to_owned()
        } else {
            format!("{}.{key}", self.prefix)
        };
        Walker {
            prefix,
            out: self.out,
        }
    }

    fn push(self, cell: Cell) {
        self.out.push((self.prefix, cell));
    }
}

impl<'de> DeserializeSeed<'de> for Walker<'_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walker<'_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a JSON value")
    }

    fn visit_bool<E>(self, v: bool) -> Result<(), E> {
        self.push(Cell::Bool(v));
        Ok(())
    }

    fn visit_i64<E>(self, v: i64) -> Result<(), E> {
        self.push(Cell::Num(v.to_string()));
        Ok(())
    }

    fn visit_u64<E>(self, v: u64) -> Result<(), E> {
        self.push(Cell::Num(v.to_string()));
        Ok(())
    }

    fn visit_f64<E>(self, v: f64) -> Result<(), E> {
        self.push(Cell::Num(format!("{v}")));
        Ok(())
    }

    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }

    fn visit_unit<E>(self) -> Result<(), E> {
        self.push(Cell::Null);
        Ok(())
    }

    fn visit_none<E>(self) -> Result<(), E> {
        self.push(Cell::Null);
        Ok(())
    }

    fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }

    fn visit_map<A: MapAccess<'de>>(mut self, mut map: A) -> Result<(), A::Error> {
        while let Some(key) = map.next_key::<String>()? {
            if key == NUMBER_TOKEN {
                let text: String = map.next_value()?;
                self.push(Cell::Num(number_text(&text)));
                return Ok(());
            }
            map.next_value_seed(self.child(&key))?;
        }
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(mut self, mut seq: A) -> Result<(), A::Error> {
        if self.prefix == "phases" || self.prefix == "cars" {
            let mut i = 0usize;
            while seq.next_element_seed(self.child(&i.to_string()))?.is_some() {
                i += 1;
            }
        } else {
            let mut n = 0u64;
            while seq.next_element::<IgnoredAny>()?.is_some() {
                n += 1;
            }
            self.child("count").push(Cell::Num(n.to_string()));
        }
        Ok(())
    }
}

/// The columns of several flattened summaries together, each inserted after the column that
/// precedes it in the first summary that has it; a column that is `null` in some run and an
/// object in another keeps only the object's fields.
pub fn columns<'a>(flats: impl IntoIterator<Item = &'a Flat>) -> Vec<String> {
    let mut order: Vec<String> = Vec::new();
    let mut seen: HashSet<String> = HashSet::new();
    for flat in flats {
        let mut at = 0usize;
        for (name, _) in flat {
            if seen.contains(name) {
                at = order.iter().position(|c| c == name).map_or(at, |p| p + 1);
            } else {
                order.insert(at, name.clone());
                seen.insert(name.clone());
                at += 1;
            }
        }
    }
    let parents: HashSet<&str> = order
        .iter()
        .filter_map(|c| c.rsplit_once('.').map(|(p, _)| p))
        .flat_map(|p| {
            p.match_indices('.')
                .map(move |(i, _)| &p[..i])
                .chain(std::iter::once(p))
        })
        .collect();
    order
        .iter()
        .filter(|c| !parents.contains(c.as_str()))
        .cloned()
        .collect()
}

/// One run as read from its directory.
#[derive(Debug, Clone)]
pub struct RunRow {
    /// The run.
    pub run: RunSpec,
    /// Its state.
    pub state: RunState,
    /// Its flattened summary (empty without one).
    pub flat: HashMap<String, Cell>,
    /// The summary's columns in order.
    pub order: Flat,
}

impl RunRow {
    /// Reads run `run` from `runs_dir/<point>-s<seed>`.
    pub fn read(runs_dir: &Path, run: RunSpec) -> RunRow {
        let dir = runs_dir.join(run.dir_name());
        let state = RunState::read(&dir);
        let order = if state.is_finished() {
            std::fs::read_to_string(dir.join("summary.json"))
                .ok()
                .and_then(|t| flatten(&t).ok())
                .unwrap_or_default()
        } else {
            Vec::new()
        };
        RunRow {
            run,
            state,
            flat: order.iter().cloned().collect(),
            order,
        }
    }

    /// The value of a metric (`None`: no summary, `null`, or not a column of this run).
    pub fn metric(&self, name: &str) -> Option<f64> {
        self.flat.get(name).and_then(Cell::value)
    }
}

/// Writes `runs.csv`.
pub fn write_runs_csv(
    path: &Path,
    plan: &Plan,
    rows: &[RunRow],
    cols: &[String],
) -> Result<(), SweepError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| csv_err(path, e))?;
    let mut header: Vec<String> = vec!["point".into(), "seed".into(), "status".into()];
    header.extend(plan.parameters.iter().cloned());
    header.extend(cols.iter().cloned());
    w.write_record(&header).map_err(|e| csv_err(path, e))?;
    for r in rows {
        let mut rec: Vec<String> = vec![
            r.run.point.to_string(),
            r.run.seed.to_string(),
            r.state.name().to_owned(),
        ];
        rec.extend(plan.point_labels(r.run.point));
        rec.extend(
            cols.iter()
                .map(|c| r.flat.get(c).map(Cell::text).unwrap_or_default()),
        );
        w.write_record(&rec).map_err(|e| csv_err(path, e))?;
    }
    w.flush().map_err(write_err(path))
}

pub(crate) fn csv_err(path: &Path, e: csv::Error) -> SweepError {
    SweepError::Write {
        path: path.into(),
        source: std::io::Error::other(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flattens_in_file_order() {
        let f = flatten(
            r#"{"name":"x","duration_s":3.0,"completed":true,"phases":[{"converged_s":null,
            "error_after_settled":{"max_mm":2.5}}],"collisions":[{"t":1},{"t":2}],
            "cars":[{"id":1,"wall_violations":[]}],"radio":{"ground":{"requests":7}}}"#,
        )
        .unwrap();
        let names: Vec<&str> = f.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "duration_s",
                "completed",
                "phases.0.converged_s",
                "phases.0.error_after_settled.max_mm",
                "collisions.count",
                "cars.0.id",
                "cars.0.wall_violations.count",
                "radio.ground.requests"
            ]
        );
        assert_eq!(f[0].1, Cell::Num("3".into()));
        assert_eq!(f[4].1.value(), Some(2.0));
        assert_eq!(f[1].1.value(), Some(1.0));
    }

    #[test]
    fn columns_merge_in_order_and_drop_null_parents() {
        let a = flatten(r#"{"a":1,"x":null,"c":3}"#).unwrap();
        let b = flatten(r#"{"a":1,"b":2,"x":{"y":1},"c":3}"#).unwrap();
        assert_eq!(columns([&a, &b]), ["a", "b", "x.y", "c"]);
        assert_eq!(columns([&b, &a]), ["a", "b", "x.y", "c"]);
    }
}
