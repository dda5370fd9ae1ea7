//! Checking an experiment file: every field in its range, named in the error.

use super::law_phase::{law_phase, program_phase};
use super::raw::{EngineName, KindName, RawExperiment, RawPhase, ShapeName};
use super::*;
use maneuvers::args::{set_option, Arg};

/// The kinds with fields of their own; every other registered law is read by
/// [`law_phase`].
const OWN_KINDS: [&str; 4] = ["goto", "formation", "rendezvous", "circle"];

/// A phase's start, timeout and hold time, checked.
pub(super) fn timing(
    phase: usize,
    start_s: Option<f64>,
    timeout_s: Option<f64>,
    hold_s: Option<f64>,
) -> Result<(Start, Option<f64>, f64), Invalid> {
    let range = |field, v: f64| {
        if v.is_finite() && (0.0..=1e6).contains(&v) {
            Ok(())
        } else {
            Err(Invalid::OutOfRange {
                phase,
                field,
                value: v,
                min: if field == "timeout_s" { 0.1 } else { 0.0 },
                max: 1e6,
            })
        }
    };
    if let Some(t) = timeout_s {
        range("timeout_s", t)?;
        if t < 0.1 {
            range("timeout_s", f64::NAN)?;
        }
    }
    let hold_s = hold_s.unwrap_or(DEFAULT_HOLD_S);
    range("hold_s", hold_s)?;
    let start = match start_s {
        Some(t) => {
            range("start_s", t)?;
            Start::At(t)
        }
        None => Start::AfterPrevious,
    };
    Ok((start, timeout_s, hold_s))
}

/// Longest `duration_s`: a day of maneuvers.
pub const MAX_DURATION_S: f64 = 86_400.0;
/// Longest `bringup_s`.
pub const MAX_BRINGUP_S: f64 = 3_600.0;
/// Most worker threads.
pub const MAX_THREADS: u64 = 256;

/// A name that is one plain file name: ASCII letters, digits, `-`, `_` and `.`, not starting
/// with a dot, at most 100 characters (outputs go to `<out>/<name>`-like paths).
pub fn name_is_safe(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.'))
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

/// Checks one phase table against its kind.
struct PhaseCheck<'a> {
    n: usize,
    kind: &'static str,
    raw: &'a RawPhase,
    cars: &'a [u8],
}

impl PhaseCheck<'_> {
    fn need<T: Clone>(&self, v: &Option<T>, field: &'static str) -> Result<T, Invalid> {
        v.clone().ok_or(Invalid::Missing {
            phase: self.n,
            kind: self.kind,
            field,
        })
    }

    /// Fails if any of `fields` (name, present) is present.
    fn none_of(&self, fields: &[(&'static str, bool)]) -> Result<(), Invalid> {
        match fields.iter().find(|(_, present)| *present) {
            Some((field, _)) => Err(Invalid::NotApplicable {
                phase: self.n,
                kind: self.kind,
                field,
            }),
            None => Ok(()),
        }
    }

    fn range(&self, field: &'static str, v: f64, min: f64, max: f64) -> Result<(), Invalid> {
        if v.is_finite() && (min..=max).contains(&v) {
            Ok(())
        } else {
            Err(Invalid::OutOfRange {
                phase: self.n,
                field,
                value: v,
                min,
                max,
            })
        }
    }

    fn car(&self, field: &'static str, id: u8) -> Result<(), Invalid> {
        if self.cars.contains(&id) {
            Ok(())
        } else {
            Err(Invalid::Car {
                phase: self.n,
                field,
                id,
                problem: CarProblem::NotInExperiment,
            })
        }
    }

    fn check(&self) -> Result<Phase, Invalid> {
        let r = self.raw;
        let n = self.n;
        let (start, timeout_s, hold_s) = timing(n, r.start_s, r.timeout_s, r.hold_s)?;
        let overrides = self.options()?;
        let goto_fields = [("cars", r.cars.is_some())];
        let formation_fields = [
            ("shape", r.shape.is_some()),
            ("leader", r.leader.is_some()),
            ("followers", r.followers.is_some()),
            ("spacing_units", r.spacing_units.is_some()),
            ("waypoints", r.waypoints.is_some()),
            ("waypoint_at_s", r.waypoint_at_s.is_some()),
            ("reach_units", r.reach_units.is_some()),
        ];
        let circle_fields = [("centre", r.centre.is_some())];
        let radius_field = [("radius_units", r.radius_units.is_some())];
        let (kind, default_tolerance) = match r.kind {
            None => return Err(Invalid::MissingKind { phase: n }),
            Some(KindName::Goto) => {
                self.none_of(&formation_fields)?;
                self.none_of(&circle_fields)?;
                self.none_of(&radius_field)?;
                if let Some(v) = r.speed_mm_s {
                    self.range("speed_mm_s", v as f64, 0.0, 2047.0)?;
                }
                let max_points = if r.speed_mm_s.is_some() {
                    1
                } else {
                    MAX_POINTS
                };
                let cars = r.cars.clone().unwrap_or_default();
                let mut seen = Vec::new();
                for g in &cars {
                    self.car("cars", g.id)?;
                    if seen.contains(&g.id) {
                        return Err(Invalid::Car {
                            phase: n,
                            field: "cars",
                            id: g.id,
                            problem: CarProblem::Duplicate,
                        });
                    }
                    seen.push(g.id);
                    if g.points.is_empty()
                        || g.points.len() > max_points
                        || g.points.iter().any(|p| p[0] > 640 || p[1] > 960)
                    {
                        return Err(Invalid::Points { phase: n, id: g.id });
                    }
                }
                (
                    PhaseKind::Goto {
                        cars,
                        speed_mm_s: r.speed_mm_s.map(|v| v as u16),
                    },
                    DEFAULT_GOTO_TOLERANCE_MM,
                )
            }
            Some(KindName::Formation) => {
                self.none_of(&goto_fields)?;
                self.none_of(&circle_fields)?;
                self.none_of(&radius_field)?;
                let leader = self.need(&r.leader, "leader")?;
                self.car("leader", leader)?;
                let followers = match &r.followers {
                    Some(list) => {
                        let mut seen = Vec::new();
                        for &id in list {
                            self.car("followers", id)?;
                            let problem = if id == leader {
                                Some(CarProblem::IsLeader)
                            } else if seen.contains(&id) {
                                Some(CarProblem::Duplicate)
                            } else {
                                None
                            };
                            if let Some(problem) = problem {
                                return Err(Invalid::Car {
                                    phase: n,
                                    field: "followers",
                                    id,
                                    problem,
                                });
                            }
                            seen.push(id);
                        }
                        seen
                    }
                    None => {
                        let mut ids: Vec<u8> =
                            self.cars.iter().copied().filter(|&c| c != leader).collect();
                        ids.sort_unstable();
                        ids
                    }
                };
                self.range(
                    "followers",
                    followers.len() as f64,
                    0.0,
                    MAX_FOLLOWERS as f64,
                )?;
                let spacing_units = self.need(&r.spacing_units, "spacing_units")?;
                self.range("spacing_units", f64::from(spacing_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, 0.0, 2047.0)?;
                let waypoints = r.waypoints.clone().unwrap_or_default();
                for w in &waypoints {
                    self.range("waypoints", f64::from(w[0]), 0.0, 640.0)?;
                    self.range("waypoints", f64::from(w[1]), 0.0, 960.0)?;
                }
                if let Some(at) = &r.waypoint_at_s {
                    if at.len() != waypoints.len()
                        || at.iter().any(|t| !non_negative(*t))
                        || at.windows(2).any(|w| w[1] < w[0])
                    {
                        return Err(Invalid::WaypointTimes { phase: n });
                    }
                }
                let reach_units = r.reach_units.unwrap_or(DEFAULT_REACH_UNITS);
                self.range("reach_units", f64::from(reach_units), 1.0, 200.0)?;
                (
                    PhaseKind::Formation(FormationPhase {
                        shape: match r.shape {
                            Some(ShapeName::Wedge) => Shape::Wedge,
                            Some(ShapeName::Line) | None => Shape::Line,
                        },
                        leader,
                        followers,
                        spacing_units,
                        speed_mm_s: speed as u16,
                        waypoints,
                        waypoint_at_s: r.waypoint_at_s.clone(),
                        reach_units,
                    }),
                    DEFAULT_FORMATION_TOLERANCE_MM,
                )
            }
            Some(KindName::Rendezvous) => {
                self.none_of(&goto_fields)?;
                self.none_of(&formation_fields)?;
                self.none_of(&circle_fields)?;
                let radius_units = self.need(&r.radius_units, "radius_units")?;
                self.range("radius_units", f64::from(radius_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, 0.0, 2047.0)?;
                (
                    PhaseKind::Rendezvous {
                        radius_units,
                        speed_mm_s: speed as u16,
                    },
                    f64::from(radius_units) * MM_PER_UNIT + RENDEZVOUS_MARGIN_MM,
                )
            }
            Some(KindName::Circle) => {
                self.none_of(&goto_fields)?;
                self.none_of(&formation_fields)?;
                let centre = self.need(&r.centre, "centre")?;
                self.range("centre", f64::from(centre[0]), 0.0, 640.0)?;
                self.range("centre", f64::from(centre[1]), 0.0, 960.0)?;
                let radius_units = self.need(&r.radius_units, "radius_units")?;
                self.range("radius_units", f64::from(radius_units), 1.0, 511.0)?;
                let speed = self.need(&r.speed_mm_s, "speed_mm_s")?;
                self.range("speed_mm_s", speed as f64, -2048.0, 2047.0)?;
                (
                    PhaseKind::Circle {
                        centre,
                        radius_units,
                        speed_mm_s: speed as i16,
                    },
                    DEFAULT_CIRCLE_TOLERANCE_MM,
                )
            }
        };
        let tolerance_mm = r.tolerance_mm.unwrap_or(default_tolerance);
        self.range("tolerance_mm", tolerance_mm, 0.0, 5000.0)?;
        if matches!(
            kind,
            PhaseKind::Goto {
                speed_mm_s: None,
                ..
            }
        ) && overrides != Overrides::default()
        {
            let field = ["reverse", "arrival_units", "neighbours"]
                .into_iter()
                .zip([
                    r.reverse.is_some(),
                    r.arrival_units.is_some(),
                    r.neighbours.is_some(),
                ])
                .find_map(|(f, set)| set.then_some(f))
                .unwrap_or("reverse");
            return Err(Invalid::NotApplicable {
                phase: n,
                kind: "goto without speed_mm_s",
                field,
            });
        }
        Ok(Phase {
            kind,
            start,
            timeout_s,
            hold_s,
            tolerance_mm,
            overrides,
        })
    }

    /// The option keys of the group law.
    fn options(&self) -> Result<Overrides, Invalid> {
        let r = self.raw;
        let mut o = Overrides::default();
        let neighbours = match &r.neighbours {
            Some(toml::Value::Integer(i)) => Some(Arg::Int(*i)),
            Some(toml::Value::String(s)) => Some(Arg::Word(s)),
            Some(_) => Some(Arg::Word("?")),
            None => None,
        };
        for (key, value) in [
            ("reverse", r.reverse.as_deref().map(Arg::Word)),
            ("arrival_units", r.arrival_units.map(Arg::Int)),
            ("neighbours", neighbours),
        ] {
            if let Some(v) = value {
                set_option(key, v, &mut o).map_err(|e| Invalid::LawArgument {
                    phase: self.n,
                    law: self.kind,
                    car: None,
                    message: e.to_string(),
                })?;
            }
        }
        Ok(o)
    }
}

impl Experiment {
    pub(super) fn from_raw(raw: RawExperiment) -> Result<Self, Invalid> {
        if raw.cars.is_empty() {
            return Err(Invalid::NoCars);
        }
        let mut ids = Vec::new();
        for c in &raw.cars {
            if !(1..=126).contains(&c.id) || ids.contains(&c.id) {
                return Err(Invalid::CarId { id: c.id });
            }
            ids.push(c.id);
            if c.x > 640 || c.y > 960 || c.heading_mrad > 6283 {
                return Err(Invalid::StartPose { id: c.id });
            }
            if c.radio_channel > crate::world::MAX_RADIO_CHANNEL {
                return Err(Invalid::RadioChannel {
                    id: c.id,
                    channel: c.radio_channel,
                });
            }
        }
        if !name_is_safe(&raw.name) {
            return Err(Invalid::Name { name: raw.name });
        }
        if !positive(raw.duration_s) || !positive(raw.bringup_s) {
            return Err(Invalid::Duration);
        }
        for (field, value, max) in [
            ("duration_s", raw.duration_s, MAX_DURATION_S),
            ("bringup_s", raw.bringup_s, MAX_BRINGUP_S),
        ] {
            if value > max {
                return Err(Invalid::OutOfRange {
                    phase: 0,
                    field,
                    value,
                    min: 0.0,
                    max,
                });
            }
        }
        if let Some(&id) = raw.profile_cars.iter().find(|id| !ids.contains(id)) {
            return Err(Invalid::CarId { id });
        }
        for c in &raw.cars {
            if let Firmware::Program(name) = c.firmware(None) {
                let ok = name.len() <= 40
                    && name.starts_with(|ch: char| ch.is_ascii_lowercase())
                    && name
                        .bytes()
                        .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_');
                if !ok {
                    return Err(Invalid::Firmware { id: c.id, name });
                }
            }
        }
        let threads = raw.threads.unwrap_or(1);
        if !(1..=MAX_THREADS).contains(&threads) {
            return Err(Invalid::OutOfRange {
                phase: 0,
                field: "threads",
                value: threads as f64,
                min: 1.0,
                max: MAX_THREADS as f64,
            });
        }
        if let Some(value) = raw.camera_fps {
            if !positive(value) || value > 60.0 {
                return Err(Invalid::CameraFps { value });
            }
        }
        let tables: Vec<toml::Table> = match (raw.maneuver, raw.phases.is_empty()) {
            (Some(m), true) => vec![m],
            (None, false) => raw.phases,
            _ => return Err(Invalid::Maneuvers),
        };
        let mut phases = Vec::new();
        let mut last_start = 0.0;
        for (i, t) in tables.iter().enumerate() {
            let n = i + 1;
            let kind = match t.get("kind") {
                None => return Err(Invalid::MissingKind { phase: n }),
                Some(toml::Value::String(k)) => k.as_str(),
                Some(_) => {
                    return Err(Invalid::PhaseTable {
                        phase: n,
                        what: "`kind` must be a string".into(),
                    })
                }
            };
            let p = if let Some(&own) = OWN_KINDS.iter().find(|k| **k == kind) {
                let r: RawPhase =
                    toml::Value::Table(t.clone())
                        .try_into()
                        .map_err(|e: toml::de::Error| Invalid::PhaseTable {
                            phase: n,
                            what: e.to_string(),
                        })?;
                PhaseCheck {
                    n,
                    kind: own,
                    raw: &r,
                    cars: &ids,
                }
                .check()?
            } else if kind == "program" {
                program_phase(n, t, &ids)?
            } else if let Some(law) = maneuvers::registry::find(kind) {
                law_phase(n, law, t, &ids)?
            } else {
                return Err(Invalid::UnknownKind {
                    phase: n,
                    kind: kind.to_owned(),
                });
            };
            if let Start::At(t) = p.start {
                if t < last_start || (i == 0 && t != 0.0) {
                    return Err(Invalid::StartOrder { phase: i + 1 });
                }
                last_start = t;
            }
            phases.push(p);
        }
        let e = Experiment {
            name: raw.name,
            duration_s: raw.duration_s,
            seed: raw.seed,
            bringup_s: raw.bringup_s,
            cars: raw.cars,
            phases,
            faults: raw.faults,
            camera_fps: raw.camera_fps,
            vision_unit: raw.vision_unit.unwrap_or(true),
            engine: match raw.engine {
                None | Some(EngineName::Iss) => EngineKind::Iss,
                Some(EngineName::Qemu) => EngineKind::Qemu,
            },
            threads: threads as usize,
            realtime: false,
            on_car_failure: raw.on_car_failure.unwrap_or_default(),
            profile_cars: raw.profile_cars,
            base_dir: None,
        };
        e.check_faults()?;
        Ok(e)
    }

    fn check_faults(&self) -> Result<(), Invalid> {
        let f = &self.faults;
        for c in &f.crash {
            if !self.cars.iter().any(|e| e.id == c.car) {
                return Err(Invalid::CarId { id: c.car });
            }
            if !non_negative(c.at_s) || c.at_s > MAX_DURATION_S {
                return Err(Invalid::Fault {
                    field: "crash.at_s",
                    value: c.at_s,
                });
            }
        }
        for (field, p) in [
            ("radio_loss", f.radio_loss),
            ("tracking_drop", f.tracking_drop),
            ("lbc.drop", f.lbc.drop),
            ("lbc.corrupt", f.lbc.corrupt),
            ("lbc.suppress", f.lbc.suppress),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(Invalid::Fault { field, value: p });
            }
        }
        for (field, v, ok) in [
            (
                "tracking_latency_ms",
                f.tracking_latency_ms as f64,
                f.tracking_latency_ms <= 10_000,
            ),
            (
                "lbc.delay_us",
                f.lbc.delay_us as f64,
                f.lbc.delay_us <= 10_000_000,
            ),
            (
                "tracking_rate_hz",
                f.tracking_rate_hz,
                positive(f.tracking_rate_hz) && f.tracking_rate_hz <= 1000.0,
            ),
            (
                "tracking_noise_mm",
                f.tracking_noise_mm,
                non_negative(f.tracking_noise_mm) && f.tracking_noise_mm <= 10_000.0,
            ),
            (
                "tracking_heading_noise_mrad",
                f.tracking_heading_noise_mrad,
                non_negative(f.tracking_heading_noise_mrad)
                    && f.tracking_heading_noise_mrad <= 10_000.0,
            ),
            (
                "lbc.reset_every_s",
                f.lbc.reset_every_s,
                non_negative(f.lbc.reset_every_s) && f.lbc.reset_every_s <= 1e7,
            ),
        ] {
            if !ok {
                return Err(Invalid::Fault { field, value: v });
            }
        }
        Ok(())
    }
}
