//! What a sweep runs, in its fixed order: every point, each with every seed. `plan.json` in an
//! output directory holds it, so shares of a sweep can be checked against each other and merged
//! without the sweep file.

use crate::error::{write_err, SweepError};
use crate::path;
use serde::{Deserialize, Serialize};
use std::path::Path;
use toml::Value;

/// The plan of a sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// The sweep's name.
    pub name: String,
    /// The base experiment file, as given.
    pub base: String,
    /// The parameters' field paths (`cars`: the number of cars).
    pub parameters: Vec<String>,
    /// Each point's values, one per parameter.
    #[serde(with = "json_values")]
    pub points: Vec<Vec<Value>>,
    /// The seeds every point runs with, ascending.
    pub seeds: Vec<u64>,
    /// The metrics aggregated and plotted (columns of `runs.csv`).
    pub metrics: Vec<String>,
    /// The parameter on the plots' x axis.
    pub plot_x: String,
}

/// One run of the plan.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunSpec {
    /// Its position in the plan (point-major, then seed).
    pub index: usize,
    /// Its point.
    pub point: usize,
    /// Its seed.
    pub seed: u64,
}

impl RunSpec {
    /// Its directory under `runs/`: `<point>-s<seed>`.
    pub fn dir_name(&self) -> String {
        format!("{}-s{}", self.point, self.seed)
    }
}

/// One deterministic share of a sweep's runs: run `k` belongs to shard `k mod count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This share, `0..count`.
    pub index: usize,
    /// Number of shares.
    pub count: usize,
}

impl Shard {
    /// The whole sweep.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Checks `0 <= index < count`.
    pub fn new(index: usize, count: usize) -> Result<Self, SweepError> {
        if count == 0 || index >= count {
            return Err(SweepError::Shard { index, count });
        }
        Ok(Shard { index, count })
    }

    /// Parses `I/N`.
    pub fn parse(s: &str) -> Result<Self, SweepError> {
        let bad = SweepError::Shard { index: 0, count: 0 };
        let (i, n) = s.split_once('/').ok_or(bad)?;
        let parse = |x: &str| x.trim().parse::<usize>();
        match (parse(i), parse(n)) {
            (Ok(i), Ok(n)) => Shard::new(i, n),
            _ => Err(SweepError::Shard { index: 0, count: 0 }),
        }
    }

    /// Whether run `k` is in this share.
    pub fn contains(&self, k: usize) -> bool {
        k % self.count == self.index
    }
}

impl Plan {
    /// Number of runs.
    pub fn len(&self) -> usize {
        self.points.len() * self.seeds.len()
    }

    /// No runs (never so for a checked sweep).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Run `k`.
    pub fn run(&self, k: usize) -> RunSpec {
        let n = self.seeds.len().max(1);
        RunSpec {
            index: k,
            point: k / n,
            seed: self.seeds[k % n],
        }
    }

    /// Every run, in order.
    pub fn runs(&self) -> Vec<RunSpec> {
        (0..self.len()).map(|k| self.run(k)).collect()
    }

    /// The runs of one share, in order.
    pub fn share(&self, shard: Shard) -> Vec<RunSpec> {
        (0..self.len())
            .filter(|k| shard.contains(*k))
            .map(|k| self.run(k))
            .collect()
    }

    /// The index of the plot's x parameter.
    pub fn x_index(&self) -> usize {
        self.parameters
            .iter()
            .position(|p| *p == self.plot_x)
            .unwrap_or(0)
    }

    /// The values of point `i` as text, one per parameter.
    pub fn point_labels(&self, i: usize) -> Vec<String> {
        self.points[i].iter().map(path::display).collect()
    }

    /// The same runs and outputs as `other`: everything but where the base experiment was
    /// read from (shares started from different directories name it differently).
    pub fn same_sweep(&self, other: &Plan) -> bool {
        Plan {
            base: other.base.clone(),
            ..self.clone()
        } == *other
    }

    /// Writes `plan.json` in `dir`.
    pub fn write(&self, dir: &Path) -> Result<(), SweepError> {
        let path = dir.join("plan.json");
        let text = serde_json::to_string_pretty(self).unwrap_or_default();
        std::fs::write(&path, text + "\n").map_err(write_err(&path))
    }

    /// Reads `plan.json` from `dir`; one that is not a whole plan (a point of the wrong
    /// width, no seeds, a plot parameter that is none of the parameters) is no sweep.
    pub fn read(dir: &Path) -> Result<Self, SweepError> {
        let not_a_sweep = || SweepError::NotASweep { dir: dir.into() };
        let text = std::fs::read_to_string(dir.join("plan.json")).map_err(|_| not_a_sweep())?;
        let plan: Plan = serde_json::from_str(&text).map_err(|_| not_a_sweep())?;
        let whole = !plan.parameters.is_empty()
            && !plan.seeds.is_empty()
            && plan.points.iter().all(|p| p.len() == plan.parameters.len())
            && plan.parameters.contains(&plan.plot_x);
        if whole {
            Ok(plan)
        } else {
            Err(not_a_sweep())
        }
    }
}

/// Points in `plan.json`: TOML values as JSON (integers stay integers, floats floats, whatever
/// serde_json's number features are).
mod json_values {
    use serde::{Deserialize, Deserializer, Serialize, Serializer};
    use serde_json::Value as Json;
    use toml::Value;

    fn to_json(v: &Value) -> Json {
        match v {
            Value::String(s) => Json::from(s.as_str()),
            Value::Integer(i) => Json::from(*i),
            Value::Float(f) => serde_json::Number::from_f64(*f).map_or(Json::Null, Json::Number),
            Value::Boolean(b) => Json::from(*b),
            Value::Datetime(d) => Json::from(d.to_string()),
            Value::Array(a) => Json::Array(a.iter().map(to_json).collect()),
            Value::Table(t) => {
                Json::Object(t.iter().map(|(k, v)| (k.clone(), to_json(v))).collect())
            }
        }
    }

    fn from_json(j: &Json) -> Value {
        match j {
            Json::Null => Value::String(String::new()),
            Json::Bool(b) => Value::Boolean(*b),
            Json::Number(n) => match n.as_i64() {
                Some(i) => Value::Integer(i),
                None => Value::Float(n.as_f64().unwrap_or(f64::NAN)),
            },
            Json::String(s) => Value::String(s.clone()),
            Json::Array(a) => Value::Array(a.iter().map(from_json).collect()),
            Json::Object(o) => {
                Value::Table(o.iter().map(|(k, v)| (k.clone(), from_json(v))).collect())
            }
        }
    }

    pub fn serialize<S: Serializer>(points: &[Vec<Value>], s: S) -> Result<S::Ok, S::Error> {
        let j: Vec<Vec<Json>> = points
            .iter()
            .map(|p| p.iter().map(to_json).collect())
            .collect();
        j.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<Value>>, D::Error> {
        let j = Vec::<Vec<Json>>::deserialize(d)?;
        Ok(j.iter()
            .map(|p| p.iter().map(from_json).collect())
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> Plan {
        Plan {
            name: "t".into(),
            base: "b.toml".into(),
            parameters: vec!["faults.radio_loss".into(), "cars".into()],
            points: vec![
                vec![Value::Float(0.0), Value::Integer(2)],
                vec![Value::Float(0.25), Value::Integer(3)],
            ],
            seeds: vec![1, 2, 3],
            metrics: vec!["completed".into()],
            plot_x: "cars".into(),
        }
    }

    #[test]
    fn runs_are_point_major_and_shards_partition_them() {
        let p = plan();
        assert_eq!(p.len(), 6);
        assert_eq!(
            p.run(4),
            RunSpec {
                index: 4,
                point: 1,
                seed: 2
            }
        );
        assert_eq!(p.run(4).dir_name(), "1-s2");
        let a = p.share(Shard::parse("0/2").unwrap());
        let b = p.share(Shard::parse("1/2").unwrap());
        assert_eq!(a.iter().map(|r| r.index).collect::<Vec<_>>(), [0, 2, 4]);
        assert_eq!(b.iter().map(|r| r.index).collect::<Vec<_>>(), [1, 3, 5]);
        assert!(Shard::parse("2/2").is_err());
        assert!(Shard::parse("0/0").is_err());
        assert!(Shard::parse("x").is_err());
        assert_eq!(p.x_index(), 1);
    }

    #[test]
    fn shares_from_other_directories_are_the_same_sweep() {
        let p = plan();
        let moved = Plan {
            base: "/elsewhere/b.toml".into(),
            ..p.clone()
        };
        assert!(p.same_sweep(&moved));
        let more_seeds = Plan {
            seeds: vec![1, 2, 3, 4],
            ..p.clone()
        };
        assert!(!p.same_sweep(&more_seeds));
    }

    #[test]
    fn plan_json_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = plan();
        p.write(dir.path()).unwrap();
        assert_eq!(Plan::read(dir.path()).unwrap(), p);
        let mut bad = p.clone();
        bad.points[1].pop();
        bad.write(dir.path()).unwrap();
        assert!(matches!(
            Plan::read(dir.path()),
            Err(SweepError::NotASweep { .. })
        ));
        std::fs::write(dir.path().join("plan.json"), "{").unwrap();
        assert!(Plan::read(dir.path()).is_err());
    }
}
