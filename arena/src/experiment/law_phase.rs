//! Phases of any registered law (other than the four kinds with their own fields) and
//! `program` phases, read from their TOML tables.
//!
//! A law phase takes the law's parameters by name as keys of the phase table (checked against
//! the registration list: an unknown key is an error that lists the law's parameters),
//! per-car values in `[[phases.cars]]` tables (`id` and the keys to change for that car), the
//! options `reverse`, `arrival_units`, `neighbours`, and waypoints for `waypoint_cars`.

use maneuvers::args::{Arg, RESERVED_KEYS};
use toml::{Table, Value};
use ubc_app::program::user::MAX_ARGS;

use super::check::timing;
use super::raw::RawProgramPhase;
use super::*;

/// Keys of a law phase that are not the law's.
const PHASE_KEYS: [&str; 10] = [
    "kind",
    "start_s",
    "timeout_s",
    "hold_s",
    "tolerance_mm",
    "cars",
    "waypoints",
    "waypoint_at_s",
    "reach_units",
    "waypoint_cars",
];

/// Default completion bound of a law phase on the error the cars report, mm.
pub const DEFAULT_LAW_TOLERANCE_MM: f64 = 75.0;

fn parse_error(phase: usize, what: String) -> Invalid {
    Invalid::PhaseTable { phase, what }
}

fn number(phase: usize, t: &Table, key: &str) -> Result<Option<f64>, Invalid> {
    match t.get(key) {
        None => Ok(None),
        Some(Value::Integer(i)) => Ok(Some(*i as f64)),
        Some(Value::Float(f)) => Ok(Some(*f)),
        Some(_) => Err(parse_error(phase, format!("`{key}` must be a number"))),
    }
}

fn typed<T: serde::de::DeserializeOwned>(
    phase: usize,
    t: &Table,
    key: &str,
) -> Result<Option<T>, Invalid> {
    t.get(key)
        .map(|v| {
            v.clone()
                .try_into()
                .map_err(|e: toml::de::Error| parse_error(phase, format!("`{key}`: {e}")))
        })
        .transpose()
}

/// A TOML value as a law argument (numbers and words only).
fn arg<'a>(phase: usize, key: &str, v: &'a Value) -> Result<Arg<'a>, Invalid> {
    match v {
        Value::Integer(i) => Ok(Arg::Int(*i)),
        Value::String(s) => Ok(Arg::Word(s)),
        _ => Err(parse_error(
            phase,
            format!("`{key}` must be an integer or a word"),
        )),
    }
}

/// Whole-car checks of a list of car IDs.
fn car_list(phase: usize, field: &'static str, list: &[u8], cars: &[u8]) -> Result<(), Invalid> {
    for (i, &id) in list.iter().enumerate() {
        let problem = if !cars.contains(&id) {
            Some(CarProblem::NotInExperiment)
        } else if list[..i].contains(&id) {
            Some(CarProblem::Duplicate)
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(Invalid::Car {
                phase,
                field,
                id,
                problem,
            });
        }
    }
    Ok(())
}

/// A phase of `law` from its table `t` (phase `n`, the experiment's cars `cars`).
pub(super) fn law_phase(
    n: usize,
    law: &'static LawInfo,
    t: &Table,
    cars: &[u8],
) -> Result<Phase, Invalid> {
    let (start, timeout_s, hold_s) = timing(
        n,
        number(n, t, "start_s")?,
        number(n, t, "timeout_s")?,
        number(n, t, "hold_s")?,
    )?;
    let mut base: Vec<(&str, Arg<'_>)> = Vec::new();
    for (k, v) in t {
        if !PHASE_KEYS.contains(&k.as_str()) {
            base.push((k, arg(n, k, v)?));
        }
    }
    let bad_arg = |car: Option<u8>, e: maneuvers::args::ArgError<'_>| Invalid::LawArgument {
        phase: n,
        law: law.name,
        car,
        message: e.to_string(),
    };
    // The phase's own values first, so that their errors are reported without a car.
    law.build(&base).map_err(|e| bad_arg(None, e))?;
    let per_car: Vec<Table> = typed(n, t, "cars")?.unwrap_or_default();
    let mut seen = Vec::new();
    for c in &per_car {
        let id = match c.get("id") {
            Some(Value::Integer(i)) => u8::try_from(*i).unwrap_or(0),
            _ => return Err(parse_error(n, "every [[phases.cars]] needs an `id`".into())),
        };
        car_list(n, "cars", &[id], cars)?;
        if seen.contains(&id) {
            return Err(Invalid::Car {
                phase: n,
                field: "cars",
                id,
                problem: CarProblem::Duplicate,
            });
        }
        seen.push(id);
    }
    let mut params = Vec::new();
    for &id in cars {
        let mut args = base.clone();
        if let Some(c) = per_car
            .iter()
            .find(|c| c.get("id").and_then(Value::as_integer) == Some(i64::from(id)))
        {
            for (k, v) in c.iter().filter(|(k, _)| k.as_str() != "id") {
                if RESERVED_KEYS.contains(&k.as_str()) {
                    return Err(parse_error(n, format!("`{k}` cannot be set per car")));
                }
                let a = arg(n, k, v)?;
                match args.iter_mut().find(|(key, _)| *key == k.as_str()) {
                    Some(slot) => slot.1 = a,
                    None => args.push((k, a)),
                }
            }
        }
        params.push((id, law.build(&args).map_err(|e| bad_arg(Some(id), e))?));
    }
    let waypoints: Vec<[u16; 2]> = typed(n, t, "waypoints")?.unwrap_or_default();
    for w in &waypoints {
        if w[0] > 640 || w[1] > 960 {
            return Err(Invalid::OutOfRange {
                phase: n,
                field: "waypoints",
                value: f64::from(w[0].max(w[1])),
                min: 0.0,
                max: 960.0,
            });
        }
    }
    let waypoint_at_s: Option<Vec<f64>> = typed(n, t, "waypoint_at_s")?;
    if let Some(at) = &waypoint_at_s {
        if at.len() != waypoints.len()
            || at.iter().any(|t| !t.is_finite() || *t < 0.0)
            || at.windows(2).any(|w| w[1] < w[0])
        {
            return Err(Invalid::WaypointTimes { phase: n });
        }
    }
    let reach_units: u16 = typed(n, t, "reach_units")?.unwrap_or(DEFAULT_REACH_UNITS);
    if !(1..=200).contains(&reach_units) {
        return Err(Invalid::OutOfRange {
            phase: n,
            field: "reach_units",
            value: f64::from(reach_units),
            min: 1.0,
            max: 200.0,
        });
    }
    let waypoint_cars: Vec<u8> = typed(n, t, "waypoint_cars")?.unwrap_or_else(|| cars.to_vec());
    car_list(n, "waypoint_cars", &waypoint_cars, cars)?;
    if waypoint_cars.is_empty() && !waypoints.is_empty() {
        return Err(parse_error(n, "`waypoint_cars` is empty".into()));
    }
    let tolerance_mm = number(n, t, "tolerance_mm")?.unwrap_or(DEFAULT_LAW_TOLERANCE_MM);
    if !(0.0..=5000.0).contains(&tolerance_mm) {
        return Err(Invalid::OutOfRange {
            phase: n,
            field: "tolerance_mm",
            value: tolerance_mm,
            min: 0.0,
            max: 5000.0,
        });
    }
    Ok(Phase {
        kind: PhaseKind::Law(LawPhase {
            law,
            params,
            waypoints,
            waypoint_at_s,
            reach_units,
            waypoint_cars,
        }),
        start,
        timeout_s,
        hold_s,
        tolerance_mm,
        overrides: Overrides::default(),
    })
}

/// A `program` phase from its table `t`.
pub(super) fn program_phase(n: usize, t: &Table, cars: &[u8]) -> Result<Phase, Invalid> {
    let r: RawProgramPhase = Value::Table(t.clone())
        .try_into()
        .map_err(|e: toml::de::Error| parse_error(n, e.to_string()))?;
    let (start, timeout_s, hold_s) = timing(n, r.start_s, r.timeout_s, r.hold_s)?;
    let list = r.cars.unwrap_or_else(|| cars.to_vec());
    car_list(n, "cars", &list, cars)?;
    if r.args.len() > MAX_ARGS {
        return Err(Invalid::OutOfRange {
            phase: n,
            field: "args",
            value: r.args.len() as f64,
            min: 0.0,
            max: MAX_ARGS as f64,
        });
    }
    let mut args = Vec::new();
    for a in r.args {
        args.push(i16::try_from(a).map_err(|_| Invalid::OutOfRange {
            phase: n,
            field: "args",
            value: a as f64,
            min: f64::from(i16::MIN),
            max: f64::from(i16::MAX),
        })?);
    }
    Ok(Phase {
        kind: PhaseKind::Program(ProgramPhase { cars: list, args }),
        start,
        timeout_s,
        hold_s,
        tolerance_mm: 0.0,
        overrides: Overrides::default(),
    })
}
