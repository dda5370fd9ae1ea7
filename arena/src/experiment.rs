//! Experiments as files: a TOML document names the cars and their start poses, the maneuver
//! and its parameters, the duration and the faults; [`run`] plays it in a [`World`] of QEMU
//! cars in real time and writes the results (trajectory CSVs, an event log, a JSON summary
//! and an SVG plot) to a directory. The format is described in `docs/experiments.md`.

use crate::metrics::{self, Sample};
use crate::plot;
use crate::radio_medium::MediumParams;
use crate::world::{CarSpec, TrackingParams, World, WorldConfig, WorldError, MM_PER_UNIT};
use lbc_emu::{FaultConfig, Pose};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::fmt;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use ubc_app::program::console::{flags, Point, Points, Reply, Request, Status, MAX_POINTS};

/// Trajectory sample period.
const SAMPLE: Duration = Duration::from_millis(100);
/// Console request timeout.
const REQUEST_TIMEOUT: Duration = Duration::from_secs(8);
/// The console's statistics pages: name and counter names, in page order.
const STATS_PAGES: [(&str, [&str; 7]); 4] = [
    (
        "lbc_requests",
        [
            "sent", "acked", "errors", "timeouts", "retries", "cser", "unkcmd",
        ],
    ),
    (
        "lbc_line",
        [
            "stream_frames",
            "unexpected",
            "decode_errors",
            "garbage_bytes",
            "truncated",
            "missing_checksum",
            "checksum_errors",
        ],
    ),
    (
        "radio",
        [
            "rx_frames",
            "rx_checksum",
            "rx_cobs",
            "rx_malformed",
            "auth_bad_mac",
            "auth_replay",
            "states_sent",
        ],
    ),
    (
        "program",
        [
            "bringups",
            "bringup_failures",
            "streams_lost",
            "user_links_lost",
            "stream_decode_errors",
            "console_requests",
            "console_refusals",
        ],
    ),
];
/// The bring-up phase code of a running program.
const PHASE_RUNNING: u8 = 2;

/// An experiment file.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// Name, used in outputs.
    pub name: String,
    /// Seconds the maneuver may run before the experiment ends.
    pub duration_s: f64,
    /// Seed of every random source.
    #[serde(default = "one")]
    pub seed: u64,
    /// Seconds allowed for every car's bring-up.
    #[serde(default = "bringup_default")]
    pub bringup_s: f64,
    /// The cars.
    pub cars: Vec<CarEntry>,
    /// What the cars do.
    pub maneuver: Maneuver,
    /// Imperfections of the world.
    #[serde(default)]
    pub faults: Faults,
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

fn one() -> u64 {
    1
}

fn bringup_default() -> f64 {
    40.0
}

/// A car and its start pose (tracking units, 2.5 mm; heading mrad counter-clockwise from +X).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CarEntry {
    /// Car ID, 1..=126.
    pub id: u8,
    /// X, 0..=600 inside the arena.
    pub x: u16,
    /// Y, 0..=800 inside the arena.
    pub y: u16,
    /// Heading, 0..=6283 mrad.
    #[serde(default)]
    pub heading_mrad: u16,
}

/// The maneuver. Only `goto` is carried out today; the others are reserved for the group
/// maneuvers and are refused by [`run`].
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Maneuver {
    /// Each car drives through its points in order and stops.
    Goto {
        /// Per-car point lists.
        cars: Vec<GotoCar>,
    },
    /// Hold a formation (reserved).
    Formation {
        /// Parameters.
        #[serde(default)]
        params: toml::Table,
    },
    /// Meet at one place (reserved).
    Rendezvous {
        /// Parameters.
        #[serde(default)]
        params: toml::Table,
    },
    /// Drive on a circle (reserved).
    Circle {
        /// Parameters.
        #[serde(default)]
        params: toml::Table,
    },
}

/// One car's go-to points, tracking units.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GotoCar {
    /// Car ID.
    pub id: u8,
    /// Up to 7 points `[x, y]`.
    pub points: Vec<[u16; 2]>,
}

/// Faults: radio loss, tracking imperfections, LBC link faults.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Faults {
    /// Probability that a radio reception is lost.
    pub radio_loss: f64,
    /// Tracking position noise, standard deviation, mm.
    pub tracking_noise_mm: f64,
    /// Tracking heading noise, standard deviation, mrad.
    pub tracking_heading_noise_mrad: f64,
    /// Probability that a tracking fix is lost.
    pub tracking_drop: f64,
    /// Tracking latency, ms.
    pub tracking_latency_ms: u64,
    /// Tracking rate, Hz.
    pub tracking_rate_hz: f64,
    /// LBC link faults (every car).
    pub lbc: LbcFaults,
}

impl Default for Faults {
    fn default() -> Self {
        Self {
            radio_loss: 0.0,
            tracking_noise_mm: 0.0,
            tracking_heading_noise_mrad: 0.0,
            tracking_drop: 0.0,
            tracking_latency_ms: 10,
            tracking_rate_hz: 30.0,
            lbc: LbcFaults::default(),
        }
    }
}

/// LBC link faults, as `lbc_emu::FaultConfig`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct LbcFaults {
    /// Probability that a byte is lost, each direction.
    pub drop: f64,
    /// Probability that a byte has a bit flipped, each direction.
    pub corrupt: f64,
    /// Extra delay of each outgoing message, us.
    pub delay_us: u64,
    /// Probability that a reply or STREAM frame is never sent.
    pub suppress: f64,
    /// Mean seconds between spontaneous LBC resets (0: none).
    pub reset_every_s: f64,
}

impl From<LbcFaults> for FaultConfig {
    fn from(f: LbcFaults) -> Self {
        FaultConfig {
            drop: f.drop,
            corrupt: f.corrupt,
            delay_us: f.delay_us,
            suppress: f.suppress,
            reset_every_s: f.reset_every_s,
        }
    }
}

/// Why an experiment could not be loaded or run.
#[derive(Debug)]
pub enum ExperimentError {
    /// The file could not be read.
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The TOML does not describe an experiment.
    Parse(toml::de::Error),
    /// The experiment is inconsistent.
    Invalid(Invalid),
    /// The maneuver kind is reserved and not carried out yet.
    UnsupportedManeuver {
        /// Its kind.
        kind: &'static str,
    },
    /// The world failed.
    World(WorldError),
    /// A car did not complete bring-up in time.
    BringUp {
        /// The car.
        id: u8,
        /// Its last status, if any.
        last: Option<Status>,
    },
    /// A car refused or failed the maneuver start.
    ManeuverRefused {
        /// The car.
        id: u8,
        /// What it answered.
        reply: String,
    },
    /// An output could not be written.
    Write {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// What is inconsistent in an experiment.
#[derive(Debug, Clone, PartialEq)]
pub enum Invalid {
    /// No cars.
    NoCars,
    /// A car ID outside 1..=126 or given twice.
    CarId {
        /// The ID.
        id: u8,
    },
    /// A start pose outside the protocol ranges.
    StartPose {
        /// The car.
        id: u8,
    },
    /// Go-to points for a car that is not in the experiment.
    UnknownCar {
        /// The ID.
        id: u8,
    },
    /// A car has no points, more than 7, or one outside X 0..=640, Y 0..=960.
    Points {
        /// The car.
        id: u8,
    },
    /// Duration not positive and finite.
    Duration,
    /// A probability outside 0..=1.
    Probability {
        /// The field.
        field: &'static str,
    },
}

impl fmt::Display for ExperimentError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Read { path, source } => write!(f, "reading {}: {source}", path.display()),
            Self::Parse(e) => write!(f, "{e}"),
            Self::Invalid(i) => write!(f, "invalid experiment: {i:?}"),
            Self::UnsupportedManeuver { kind } => {
                write!(f, "maneuver `{kind}` is not available yet (only `goto`)")
            }
            Self::World(e) => write!(f, "{e}"),
            Self::BringUp { id, last } => {
                write!(
                    f,
                    "car {id} did not complete bring-up (last status {last:?})"
                )
            }
            Self::ManeuverRefused { id, reply } => {
                write!(f, "car {id} did not start the maneuver: {reply}")
            }
            Self::Write { path, source } => write!(f, "writing {}: {source}", path.display()),
        }
    }
}

impl std::error::Error for ExperimentError {}

impl From<WorldError> for ExperimentError {
    fn from(e: WorldError) -> Self {
        Self::World(e)
    }
}

impl Experiment {
    /// Reads and checks an experiment file.
    pub fn load(path: &Path) -> Result<Self, ExperimentError> {
        let text = fs::read_to_string(path).map_err(|source| ExperimentError::Read {
            path: path.into(),
            source,
        })?;
        Self::parse(&text)
    }

    /// Parses and checks an experiment.
    pub fn parse(text: &str) -> Result<Self, ExperimentError> {
        let e: Experiment = toml::from_str(text).map_err(ExperimentError::Parse)?;
        e.validate().map_err(ExperimentError::Invalid)?;
        Ok(e)
    }

    /// Checks IDs, ranges and probabilities.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.cars.is_empty() {
            return Err(Invalid::NoCars);
        }
        let mut seen = Vec::new();
        for c in &self.cars {
            if !(1..=126).contains(&c.id) || seen.contains(&c.id) {
                return Err(Invalid::CarId { id: c.id });
            }
            seen.push(c.id);
            if c.x > 640 || c.y > 960 || c.heading_mrad > 6283 {
                return Err(Invalid::StartPose { id: c.id });
            }
        }
        if !positive(self.duration_s) || !positive(self.bringup_s) {
            return Err(Invalid::Duration);
        }
        if let Maneuver::Goto { cars } = &self.maneuver {
            for g in cars {
                if !seen.contains(&g.id) {
                    return Err(Invalid::UnknownCar { id: g.id });
                }
                if g.points.is_empty()
                    || g.points.len() > MAX_POINTS
                    || g.points.iter().any(|p| p[0] > 640 || p[1] > 960)
                {
                    return Err(Invalid::Points { id: g.id });
                }
            }
        }
        let f = &self.faults;
        for (field, p) in [
            ("radio_loss", f.radio_loss),
            ("tracking_drop", f.tracking_drop),
            ("lbc.drop", f.lbc.drop),
            ("lbc.corrupt", f.lbc.corrupt),
            ("lbc.suppress", f.lbc.suppress),
        ] {
            if !(0.0..=1.0).contains(&p) {
                return Err(Invalid::Probability { field });
            }
        }
        if !positive(f.tracking_rate_hz)
            || !non_negative(f.tracking_noise_mm)
            || !non_negative(f.tracking_heading_noise_mrad)
            || !non_negative(f.lbc.reset_every_s)
        {
            return Err(Invalid::Probability {
                field: "tracking/lbc rates",
            });
        }
        Ok(())
    }

    /// The world this experiment runs in.
    pub fn world_config(&self, firmware: &Path) -> WorldConfig {
        let cars = self
            .cars
            .iter()
            .map(|c| CarSpec {
                id: c.id,
                start: Pose {
                    x_mm: f64::from(c.x) * MM_PER_UNIT,
                    y_mm: f64::from(c.y) * MM_PER_UNIT,
                    heading_rad: f64::from(c.heading_mrad) / 1000.0,
                },
            })
            .collect();
        let mut cfg = WorldConfig::new(firmware, cars);
        cfg.seed = self.seed;
        cfg.radio = MediumParams {
            loss_probability: self.faults.radio_loss,
            ..MediumParams::default()
        };
        cfg.tracking = TrackingParams {
            rate_hz: self.faults.tracking_rate_hz,
            noise_mm: self.faults.tracking_noise_mm,
            heading_noise_mrad: self.faults.tracking_heading_noise_mrad,
            latency: Duration::from_millis(self.faults.tracking_latency_ms),
            drop: self.faults.tracking_drop,
        };
        cfg.lbc_faults = self.faults.lbc.into();
        cfg
    }

    fn goto_points(&self, id: u8) -> Vec<[u16; 2]> {
        match &self.maneuver {
            Maneuver::Goto { cars } => cars
                .iter()
                .find(|g| g.id == id)
                .map(|g| g.points.clone())
                .unwrap_or_default(),
            _ => Vec::new(),
        }
    }
}

/// Per-car results.
#[derive(Debug, Clone, Serialize)]
pub struct CarResult {
    /// Car ID.
    pub id: u8,
    /// Path length, mm.
    pub distance_mm: f64,
    /// Distance from the final pose to the last target, mm (none without targets).
    pub final_error_mm: Option<f64>,
    /// The car reported its maneuver done.
    pub arrived: bool,
    /// Seconds from the maneuver start to the car reporting it done.
    pub arrival_s: Option<f64>,
    /// Times (s) the car left the arena.
    pub wall_violations: Vec<f64>,
    /// The car's console `stats` pages by name (`lbc_requests`, `lbc_line`, `radio`,
    /// `program`); a page that got no answer is missing.
    pub stats: Value,
    /// The emulated LBC's counters.
    pub lbc: Value,
    /// Tracking fixes delivered and dropped.
    pub tracking: Value,
}

/// Results of a run (written as `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Experiment name.
    pub name: String,
    /// Seconds the maneuver ran.
    pub duration_s: f64,
    /// Every car reported its maneuver done.
    pub all_arrived: bool,
    /// The run was interrupted.
    pub cancelled: bool,
    /// Per car.
    pub cars: Vec<CarResult>,
    /// Closest approach of two cars, mm.
    pub min_separation_mm: Option<f64>,
    /// Approaches closer than 100 mm.
    pub collisions: Vec<Value>,
    /// Radio medium and ground-station counters.
    pub radio: Value,
}

/// A progress line: seconds since the maneuver start and each car's status.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Seconds since the maneuver start.
    pub t: f64,
    /// Car ID, status (none if the request failed).
    pub cars: Vec<(u8, Option<Status>)>,
}

impl fmt::Display for Progress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "t={:>5.1}s", self.t)?;
        for (id, s) in &self.cars {
            match s {
                Some(s) => write!(
                    f,
                    " | car{id} ({:>3},{:>3}) hd {:>4} v {:>4} {}{}",
                    s.x,
                    s.y,
                    s.heading_mrad,
                    s.velocity_mm_s,
                    if s.flags & flags::MANEUVER != 0 {
                        "moving "
                    } else {
                        "idle "
                    },
                    format_args!("{}/{}", s.maneuver_index, s.maneuver_len)
                )?,
                None => write!(f, " | car{id} (no answer)")?,
            }
        }
        Ok(())
    }
}

fn to_points(list: &[[u16; 2]]) -> Points {
    let mut p = Points::new();
    for &[x, y] in list.iter().take(MAX_POINTS) {
        let _ = p.push(Point { x, y });
    }
    p
}

struct EventLog {
    lines: Vec<String>,
    t0: Instant,
}

impl EventLog {
    fn push_at(&mut self, at: Duration, car: Option<u8>, what: &str) {
        let mut v = json!({ "t": at.as_secs_f64(), "event": what });
        if let Some(id) = car {
            v["car"] = json!(id);
        }
        self.lines.push(v.to_string());
    }

    fn push(&mut self, car: Option<u8>, what: &str, extra: Value) {
        let mut v = json!({ "t": self.t0.elapsed().as_secs_f64(), "event": what });
        if let Some(id) = car {
            v["car"] = json!(id);
        }
        if let (Value::Object(m), Value::Object(x)) = (&mut v, extra) {
            m.extend(x);
        }
        self.lines.push(v.to_string());
    }
}

fn write_file(path: &Path, text: &str) -> Result<(), ExperimentError> {
    fs::File::create(path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .map_err(|source| ExperimentError::Write {
            path: path.into(),
            source,
        })
}

/// Runs the experiment in a fresh world with the firmware at `firmware`, reporting a
/// [`Progress`] line each second, and writes `car<ID>.csv`, `events.jsonl`, `summary.json` and
/// `trajectories.svg` to `out`. Setting `cancel` ends the maneuver phase early (outputs are
/// still written, `cancelled` is set in the summary) or aborts bring-up. The world is torn
/// down before this returns, whatever happens.
pub fn run(
    exp: &Experiment,
    firmware: &Path,
    out: &Path,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Summary, ExperimentError> {
    exp.validate().map_err(ExperimentError::Invalid)?;
    let kind = match exp.maneuver {
        Maneuver::Goto { .. } => "goto",
        Maneuver::Formation { .. } => "formation",
        Maneuver::Rendezvous { .. } => "rendezvous",
        Maneuver::Circle { .. } => "circle",
    };
    if kind != "goto" {
        return Err(ExperimentError::UnsupportedManeuver { kind });
    }
    fs::create_dir_all(out).map_err(|source| ExperimentError::Write {
        path: out.into(),
        source,
    })?;
    let world = World::start(&exp.world_config(firmware))?;
    // Event times are seconds since the world started.
    let mut log = EventLog {
        lines: Vec::new(),
        t0: Instant::now() - world.elapsed(),
    };
    log.push(
        None,
        "booted",
        json!({ "name": exp.name, "cars": exp.cars.len() }),
    );
    let ids: Vec<u8> = world.ids().to_vec();

    // Bring-up: every car's program running, drive enabled, pose valid.
    let deadline = Instant::now() + Duration::from_secs_f64(exp.bringup_s);
    for &id in &ids {
        let mut last = None;
        loop {
            if let Ok(Reply::Status(s)) = world.request(id, &Request::Status, REQUEST_TIMEOUT) {
                last = Some(s);
                let need = flags::DRIVE_ENABLED | flags::POSE_VALID;
                if s.phase == PHASE_RUNNING && s.flags & need == need {
                    break;
                }
            }
            if Instant::now() > deadline || cancel.load(Ordering::Relaxed) {
                return Err(ExperimentError::BringUp { id, last });
            }
            std::thread::sleep(Duration::from_millis(300));
        }
        log.push(Some(id), "ready", json!({}));
    }

    // Start every car's maneuver.
    for &id in &ids {
        let pts = exp.goto_points(id);
        if pts.is_empty() {
            continue;
        }
        let req = Request::ManeuverStart(to_points(&pts));
        match world.request(id, &req, REQUEST_TIMEOUT) {
            Ok(Reply::ManeuverStarted(n)) => {
                log.push(Some(id), "maneuver-started", json!({ "points": n }))
            }
            Ok(other) => {
                return Err(ExperimentError::ManeuverRefused {
                    id,
                    reply: format!("{other:?}"),
                })
            }
            Err(e) => {
                return Err(ExperimentError::ManeuverRefused {
                    id,
                    reply: e.to_string(),
                })
            }
        }
    }

    let t0 = Instant::now();
    let mut tracks: Vec<Vec<Sample>> = vec![Vec::new(); ids.len()];
    let mut arrival: Vec<Option<f64>> = vec![None; ids.len()];
    let mut next_sample = t0;
    let mut next_progress = t0 + Duration::from_secs(1);
    let limit = Duration::from_secs_f64(exp.duration_s);
    let moving: Vec<bool> = ids
        .iter()
        .map(|&id| !exp.goto_points(id).is_empty())
        .collect();
    let mut done_at: Option<Instant> = None;
    loop {
        let now = Instant::now();
        if now >= next_sample {
            next_sample += SAMPLE;
            let t = t0.elapsed().as_secs_f64();
            for (k, truth) in world.truth().iter().enumerate() {
                tracks[k].push(Sample {
                    t,
                    x_mm: truth.pose.x_mm,
                    y_mm: truth.pose.y_mm,
                    heading_mrad: truth.pose.heading_rad * 1000.0,
                    v_mm_s: truth.v_mm_s,
                });
            }
            for ev in world.take_events() {
                if ev.what.contains("ManeuverDone") {
                    if let Some(k) = ids.iter().position(|&i| i == ev.car) {
                        arrival[k].get_or_insert(t0.elapsed().as_secs_f64());
                    }
                }
                log.push_at(ev.at, Some(ev.car), &ev.what);
            }
        }
        if now >= next_progress {
            next_progress += Duration::from_secs(1);
            let mut line = Progress {
                t: t0.elapsed().as_secs_f64(),
                cars: Vec::new(),
            };
            for (k, &id) in ids.iter().enumerate() {
                let s = match world.request(id, &Request::Status, Duration::from_secs(2)) {
                    Ok(Reply::Status(s)) => Some(s),
                    _ => None,
                };
                if let Some(s) = s {
                    if moving[k] && s.flags & flags::MANEUVER == 0 && arrival[k].is_none() {
                        arrival[k] = Some(t0.elapsed().as_secs_f64());
                        log.push(Some(id), "maneuver-finished", json!({}));
                    }
                }
                line.cars.push((id, s));
            }
            progress(&line);
        }
        let all = moving.iter().zip(&arrival).all(|(m, a)| !m || a.is_some());
        if all && done_at.is_none() {
            done_at = Some(Instant::now());
        }
        if done_at.is_some_and(|d| d.elapsed() >= Duration::from_secs(1))
            || t0.elapsed() >= limit
            || cancel.load(Ordering::Relaxed)
        {
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let ran = t0.elapsed().as_secs_f64();
    log.push(None, "end", json!({ "t_maneuver": ran }));

    // Link statistics: each car's console stats, the LBC emulators, the ground station, the hub.
    let mut stats = Vec::new();
    for &id in &ids {
        let mut pages = serde_json::Map::new();
        for (page, (title, names)) in (0u8..).zip(STATS_PAGES) {
            if let Ok(Reply::Stats { values, .. }) =
                world.request(id, &Request::Stats(page), Duration::from_secs(3))
            {
                let counters: serde_json::Map<String, Value> = names
                    .iter()
                    .zip(values.iter())
                    .map(|(n, v)| ((*n).to_owned(), json!(v)))
                    .collect();
                pages.insert(title.to_owned(), Value::Object(counters));
            }
        }
        stats.push(Value::Object(pages));
    }
    let truth = world.truth();
    let ground = world.ground_counters();
    let gstats = world.ground_stats();
    let hub = world.shutdown();

    let mut cars = Vec::new();
    for (k, &id) in ids.iter().enumerate() {
        let targets = exp.goto_points(id);
        let last = targets
            .last()
            .map(|p| (f64::from(p[0]) * MM_PER_UNIT, f64::from(p[1]) * MM_PER_UNIT));
        let t = &truth[k];
        cars.push(CarResult {
            id,
            distance_mm: metrics::distance_travelled(&tracks[k]),
            final_error_mm: last.and_then(|p| metrics::final_error(&tracks[k], p)),
            arrived: arrival[k].is_some(),
            arrival_s: arrival[k],
            wall_violations: metrics::wall_violations(&tracks[k]),
            stats: stats[k].clone(),
            lbc: json!({
                "rx_bytes": t.lbc.rx_bytes, "tx_bytes": t.lbc.tx_bytes,
                "commands": t.lbc.commands, "replies": t.lbc.replies, "errors": t.lbc.errors,
                "cser": t.lbc.cser, "unkcmd": t.lbc.unkcmd,
                "stream_frames": t.lbc.stream_frames, "tx_overflow": t.lbc.tx_overflow,
                "resets": t.lbc.resets,
                "fault_dropped": t.lbc_faults.dropped, "fault_corrupted": t.lbc_faults.corrupted,
                "fault_suppressed": t.lbc_faults.suppressed, "fault_resets": t.lbc_faults.resets,
            }),
            tracking: json!({ "delivered": t.fixes_delivered, "dropped": t.fixes_dropped }),
        });
    }
    let radio = json!({
        "ground": {
            "requests": ground.requests, "replies": ground.replies, "failed": ground.failed,
            "states_heard": ground.states_heard, "notices": ground.notices,
            "retries": gstats.retries, "rx_frames": gstats.rx_frames,
        },
        "medium": hub.as_ref().map(|h| json!({
            "packets_sent": h.medium.packets_sent, "deliveries": h.medium.deliveries,
            "collisions": h.medium.collisions, "half_duplex": h.medium.half_duplex,
            "random_losses": h.medium.random_losses, "distance_losses": h.medium.distance_losses,
            "rx_overflows": h.medium.rx_overflows, "csma_drops": h.medium.csma_drops,
        })),
        "nodes": hub.as_ref().map(|h| h.nodes.iter().map(|(n, s)| json!({
            "node": n, "frames_in": s.frames_in, "frames_out": s.frames_out,
            "bytes_in": s.bytes_in, "bytes_out": s.bytes_out,
            "bytes_discarded": s.bytes_discarded, "disconnects": s.disconnects,
        })).collect::<Vec<_>>()),
    });
    let summary = Summary {
        name: exp.name.clone(),
        duration_s: ran,
        cancelled: cancel.load(Ordering::Relaxed),
        all_arrived: arrival.iter().zip(&moving).all(|(a, m)| !m || a.is_some()),
        min_separation_mm: metrics::min_separation(&tracks).map(|e| e.distance_mm),
        collisions: metrics::collisions(&tracks)
            .iter()
            .map(|e| json!({ "cars": [ids[e.cars.0], ids[e.cars.1]], "t": e.t, "distance_mm": e.distance_mm }))
            .collect(),
        cars,
        radio,
    };

    for (k, &id) in ids.iter().enumerate() {
        let mut csv = String::from("t,x_mm,y_mm,heading,v\n");
        for s in &tracks[k] {
            csv.push_str(&format!(
                "{:.3},{:.1},{:.1},{:.0},{:.1}\n",
                s.t, s.x_mm, s.y_mm, s.heading_mrad, s.v_mm_s
            ));
        }
        write_file(&out.join(format!("car{id}.csv")), &csv)?;
    }
    let mut jsonl = log.lines.join("\n");
    jsonl.push('\n');
    write_file(&out.join("events.jsonl"), &jsonl)?;
    let text = serde_json::to_string_pretty(&summary).unwrap_or_default();
    write_file(&out.join("summary.json"), &text)?;
    let targets: Vec<Vec<(f64, f64)>> = ids
        .iter()
        .map(|&id| {
            exp.goto_points(id)
                .iter()
                .map(|p| (f64::from(p[0]) * MM_PER_UNIT, f64::from(p[1]) * MM_PER_UNIT))
                .collect()
        })
        .collect();
    let plot_tracks: Vec<plot::Track<'_>> = ids
        .iter()
        .enumerate()
        .map(|(k, &id)| plot::Track {
            id,
            samples: &tracks[k],
            targets: &targets[k],
        })
        .collect();
    write_file(
        &out.join("trajectories.svg"),
        &plot::svg(&exp.name, &plot_tracks),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO: &str = r#"
name = "two"
duration_s = 30
[[cars]]
id = 1
x = 150
y = 200
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 200
heading_mrad = 1571
[maneuver]
kind = "goto"
[[maneuver.cars]]
id = 1
points = [[150, 500]]
[[maneuver.cars]]
id = 2
points = [[450, 500], [400, 600]]
[faults]
radio_loss = 0.2
[faults.lbc]
drop = 0.001
"#;

    #[test]
    fn parses_and_maps_to_a_world() {
        let e = Experiment::parse(TWO).unwrap();
        assert_eq!(e.cars.len(), 2);
        assert_eq!(e.goto_points(2), vec![[450, 500], [400, 600]]);
        let w = e.world_config(Path::new("/fw"));
        assert_eq!(w.cars[1].start.x_mm, 1125.0);
        assert_eq!(w.radio.loss_probability, 0.2);
        assert_eq!(w.lbc_faults.drop, 0.001);
        assert_eq!(w.tracking.rate_hz, 30.0);
    }

    #[test]
    fn reserved_maneuvers_parse() {
        let t = TWO.replace(
            "kind = \"goto\"",
            "kind = \"circle\"\nparams = { radius = 100 }",
        );
        let t = t.split("[[maneuver.cars]]").next().unwrap().to_owned() + "\n";
        let e = Experiment::parse(&t).unwrap();
        assert!(matches!(e.maneuver, Maneuver::Circle { .. }));
    }

    #[test]
    fn bad_experiments_are_rejected_with_reasons() {
        let bad = |from: &str, to: &str| Experiment::parse(&TWO.replace(from, to)).unwrap_err();
        assert!(matches!(
            bad("id = 2\nx", "id = 1\nx"),
            ExperimentError::Invalid(Invalid::CarId { id: 1 })
        ));
        assert!(matches!(
            bad("[[150, 500]]", "[[150, 5000]]"),
            ExperimentError::Invalid(Invalid::Points { id: 1 })
        ));
        assert!(matches!(
            bad("radio_loss = 0.2", "radio_loss = 2.0"),
            ExperimentError::Invalid(Invalid::Probability { .. })
        ));
        assert!(matches!(
            bad("duration_s = 30", "duration_s = -1"),
            ExperimentError::Invalid(Invalid::Duration)
        ));
        assert!(matches!(bad("name =", "nom ="), ExperimentError::Parse(_)));
        assert!(matches!(
            bad("x = 150", "x = 70000"),
            ExperimentError::Parse(_)
        ));
    }

    #[test]
    fn shipped_experiments_parse() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../experiments");
        let mut n = 0;
        for entry in fs::read_dir(dir).unwrap() {
            let p = entry.unwrap().path();
            if p.extension().is_some_and(|e| e == "toml") {
                Experiment::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
                n += 1;
            }
        }
        assert!(n >= 1);
    }
}
