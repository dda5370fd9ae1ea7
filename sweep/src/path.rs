//! Field paths into an experiment's TOML document: `faults.radio_loss`, `phases.0.speed_mm_s`,
//! `cars.2.x`. A segment that is a number indexes an array; tables the base experiment does not
//! have are created on the way (so `faults.lbc.drop` works on a file without `[faults]`),
//! arrays never are. A value replacing one the base experiment has must have its TOML type
//! (integers and floats stand for each other). Everything else (unknown keys, integer or
//! fraction, ranges, consistency) is the experiment checker's job, run on the result.
//!
//! The path `cars` alone is special: the number of cars, taking the first N `[[cars]]`.

use crate::error::PathProblem;
use toml::Value;

/// The special parameter: the number of cars.
pub const CARS: &str = "cars";

/// The TOML type name of a value.
pub fn type_name(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "string",
        Value::Integer(_) => "integer",
        Value::Float(_) => "float",
        Value::Boolean(_) => "boolean",
        Value::Datetime(_) => "datetime",
        Value::Array(_) => "array",
        Value::Table(_) => "table",
    }
}

/// A value as written in a table cell or a label: strings bare, everything else as TOML.
pub fn display(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Float(f) => format!("{f}"),
        other => other.to_string(),
    }
}

/// Checks a path's syntax (not whether the experiment has the field).
pub fn check_syntax(path: &str) -> Result<(), PathProblem> {
    if path.split('.').any(str::is_empty) {
        return Err(PathProblem::Syntax);
    }
    if path == "seed" {
        return Err(PathProblem::Seed);
    }
    Ok(())
}

/// Sets `path` to `value` in `doc` (the experiment's document, a table).
pub fn set(doc: &mut Value, path: &str, value: &Value) -> Result<(), PathProblem> {
    check_syntax(path)?;
    if path == CARS {
        return set_car_count(doc, value);
    }
    let segments: Vec<&str> = path.split('.').collect();
    let mut cur = doc;
    for (i, seg) in segments.iter().enumerate() {
        let at = segments[..=i].join(".");
        let last = i + 1 == segments.len();
        let next_is_index = segments
            .get(i + 1)
            .is_some_and(|s| s.bytes().all(|b| b.is_ascii_digit()));
        cur = match cur {
            Value::Table(t) => {
                if last {
                    if let Some(old) = t.get(*seg) {
                        check_type(old, value)?;
                    }
                    t.insert((*seg).to_owned(), value.clone());
                    return Ok(());
                }
                if !t.contains_key(*seg) {
                    if next_is_index {
                        return Err(PathProblem::NoSuchArray { at });
                    }
                    t.insert((*seg).to_owned(), Value::Table(toml::Table::new()));
                }
                t.get_mut(*seg).ok_or(PathProblem::NoSuchArray { at })?
            }
            Value::Array(a) => {
                let k: usize = seg
                    .parse()
                    .map_err(|_| PathProblem::NotAnIndex { at: at.clone() })?;
                let len = a.len();
                let slot = a
                    .get_mut(k)
                    .ok_or(PathProblem::IndexOutOfRange { at, len })?;
                if last {
                    check_type(slot, value)?;
                    *slot = value.clone();
                    return Ok(());
                }
                slot
            }
            _ => {
                return Err(PathProblem::NotATable {
                    at: segments[..i].join("."),
                })
            }
        };
    }
    Ok(())
}

/// The value may replace `old`: the same TOML type, or a number for a number (a file may
/// write `duration_s = 3`; whether the field takes a fraction is the experiment checker's to
/// say).
fn check_type(old: &Value, new: &Value) -> Result<(), PathProblem> {
    let same = std::mem::discriminant(old) == std::mem::discriminant(new);
    let numbers = matches!(old, Value::Float(_) | Value::Integer(_))
        && matches!(new, Value::Float(_) | Value::Integer(_));
    if same || numbers {
        Ok(())
    } else {
        Err(PathProblem::WrongType {
            expected: type_name(old),
            found: type_name(new),
        })
    }
}

/// `cars = N`: keeps the first N `[[cars]]`.
fn set_car_count(doc: &mut Value, value: &Value) -> Result<(), PathProblem> {
    let n = match value {
        Value::Integer(n) if *n >= 1 => {
            usize::try_from(*n).map_err(|_| PathProblem::CarsNotACount)?
        }
        _ => return Err(PathProblem::CarsNotACount),
    };
    let cars = match doc.get_mut(CARS) {
        Some(Value::Array(a)) => a,
        _ => return Err(PathProblem::TooFewCars { available: 0 }),
    };
    if cars.len() < n {
        return Err(PathProblem::TooFewCars {
            available: cars.len(),
        });
    }
    cars.truncate(n);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc() -> Value {
        toml::from_str(
            r#"
name = "x"
duration_s = 5
[[cars]]
id = 1
x = 10
y = 20
[[cars]]
id = 2
x = 30
y = 40
[[phases]]
kind = "rendezvous"
speed_mm_s = 100
"#,
        )
        .unwrap()
    }

    #[test]
    fn sets_nested_fields_creating_tables() {
        let mut d = doc();
        set(&mut d, "faults.lbc.drop", &Value::Float(0.01)).unwrap();
        assert_eq!(d["faults"]["lbc"]["drop"], Value::Float(0.01));
        set(&mut d, "phases.0.speed_mm_s", &Value::Integer(50)).unwrap();
        assert_eq!(d["phases"][0]["speed_mm_s"], Value::Integer(50));
        set(&mut d, "cars.1.x", &Value::Integer(99)).unwrap();
        assert_eq!(d["cars"][1]["x"], Value::Integer(99));
        set(&mut d, "duration_s", &Value::Float(2.5)).unwrap();
        set(&mut d, "duration_s", &Value::Integer(3)).unwrap();
        set(&mut d, "duration_s", &Value::String("3".into())).unwrap_err();
    }

    #[test]
    fn car_count_truncates() {
        let mut d = doc();
        set(&mut d, "cars", &Value::Integer(1)).unwrap();
        assert_eq!(d["cars"].as_array().unwrap().len(), 1);
        let mut d = doc();
        assert_eq!(
            set(&mut d, "cars", &Value::Integer(3)),
            Err(PathProblem::TooFewCars { available: 2 })
        );
        assert_eq!(
            set(&mut d, "cars", &Value::Float(1.0)),
            Err(PathProblem::CarsNotACount)
        );
    }

    #[test]
    fn bad_paths_are_named() {
        let mut d = doc();
        let v = Value::Integer(1);
        assert_eq!(set(&mut d, "a..b", &v), Err(PathProblem::Syntax));
        assert_eq!(set(&mut d, "seed", &v), Err(PathProblem::Seed));
        assert_eq!(
            set(&mut d, "phases.3.speed_mm_s", &v),
            Err(PathProblem::IndexOutOfRange {
                at: "phases.3".into(),
                len: 1
            })
        );
        assert_eq!(
            set(&mut d, "phases.x.speed_mm_s", &v),
            Err(PathProblem::NotAnIndex {
                at: "phases.x".into()
            })
        );
        assert_eq!(
            set(&mut d, "maneuver.0.speed_mm_s", &v),
            Err(PathProblem::NoSuchArray {
                at: "maneuver".into()
            })
        );
        assert_eq!(
            set(&mut d, "duration_s.x", &v),
            Err(PathProblem::NotATable {
                at: "duration_s".into()
            })
        );
        assert_eq!(
            set(&mut d, "name", &v),
            Err(PathProblem::WrongType {
                expected: "string",
                found: "integer"
            })
        );
    }
}
