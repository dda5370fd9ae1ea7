//! Plays an [`Experiment`] in a [`World`]: bring-up, then each phase in turn (group maneuvers
//! started with the console's `GroupStart`, a formation leader's waypoints sent with
//! `GroupWaypoint`, go-to points with `ManeuverStart`), sampling every car's true pose every
//! 100 ms, judging each phase's completion from those true poses, printing progress each
//! second, and finally writing the outputs.
//!
//! The loop never blocks on the radio: console requests go out one at a time (the ground
//! station carries one authenticated command at a time) from a queue, commands before status
//! polls, and their replies are picked up as they arrive, so sampling stays on time. Every
//! time in the loop is world time: the loop advances the world by [`TICK`] between two looks,
//! so a run on the virtual-time engine is a function of the experiment and its seed.

mod control;
mod judge;
mod output;
mod record;
#[cfg(test)]
mod tests;

use control::{CarState, Purpose, Runner};
pub use output::round_to;

use crate::experiment::{
    Experiment, ExperimentError, FailurePolicy, FormationPhase, Phase, PhaseKind, Start,
    RENDEZVOUS_STILL_MM_S,
};
use crate::metrics::{self, ErrorStats, Sample};
use crate::recording::{self, Recording, RunOptions};
use crate::world::{CarTruth, PendingReply, World, WorldError, MM_PER_UNIT};
use maneuvers::Formation;
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::VecDeque;
use std::fmt;
use std::fs;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use ubc_app::program::console::{
    flags, Point, Points, Refusal, Reply, Request, StatsPage, Status, MAX_POINTS,
};

/// Trajectory sample period.
const SAMPLE: Duration = Duration::from_millis(100);
/// World time between two camera reports of every car (experiments with a camera).
const CAMERA_EVERY: Duration = Duration::from_secs(20);
/// World time between two looks of the run loop.
const TICK: Duration = Duration::from_millis(10);
/// Blocking console request timeout (bring-up, final statistics).
const REQUEST_TIMEOUT: Duration = Duration::from_secs(8);
/// A queued request without an answer after this long counts as failed.
const INFLIGHT_TIMEOUT: Duration = Duration::from_secs(10);
/// Attempts of a maneuver command before the runner gives up on it.
const COMMAND_ATTEMPTS: u32 = 5;
/// Each car's status is asked for about this often. The polls also keep the firmware's
/// user link alive (3 s without an authenticated command or a ground heartbeat stops the car)
/// on a busy channel.
const STATUS_EVERY: Duration = Duration::from_millis(500);
/// A car of a group go-to has arrived once it is within the tolerance of its point and
/// slower than this, mm/s.
const GOTO_STILL_MM_S: f64 = 20.0;
/// Period of the error series in the summary.
const SERIES_EVERY_S: f64 = 0.5;
/// The bring-up phase code of a running program.
const PHASE_RUNNING: u8 = 2;

/// Per-car results.
#[derive(Debug, Clone, Serialize)]
pub struct CarResult {
    /// Car ID.
    pub id: u8,
    /// Path length, mm.
    pub distance_mm: f64,
    /// Distance from the last go-to point of the last `goto` phase that gave the car points,
    /// when that phase ended, mm (none without points).
    pub final_error_mm: Option<f64>,
    /// The car finished every go-to maneuver it was given (true without any).
    pub arrived: bool,
    /// When it finished its last go-to maneuver, s since the maneuvers started.
    pub arrival_s: Option<f64>,
    /// Times (s) at which the car left the arena.
    #[serde(rename = "wall_violations_s")]
    pub wall_violations: Vec<f64>,
    /// The firmware's console counters.
    pub stats: Value,
    /// The emulated LBC's counters.
    pub lbc: Value,
    /// Tracking fixes delivered and dropped.
    pub tracking: Value,
    /// Radio state broadcasts of this car the ground station heard.
    pub states_heard: u64,
    /// Awake cycles over cycles of the car's processor (virtual-time engine only).
    pub processor_load: Option<f64>,
    /// Frames per second its vision processed during the maneuvers, at its processor's
    /// clock (experiments with a camera).
    pub camera_fps: Option<f64>,
    /// The car's firmware stopped during the maneuvers: when and why.
    pub failed: Option<CarFailure>,
}

/// A car whose firmware stopped running during the maneuvers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CarFailure {
    /// Car ID.
    pub car: u8,
    /// When, s since the maneuvers started.
    pub t_s: f64,
    /// Why (exit code, stuck processor, killed emulator).
    pub reason: String,
}

/// Per-phase results. Times are seconds; `*_s` of a phase are counted from its start.
#[derive(Debug, Clone, Serialize)]
pub struct PhaseResult {
    /// Phase number, from 1.
    pub phase: usize,
    /// `goto`, `formation`, `rendezvous` or `circle`.
    pub kind: &'static str,
    /// When it started, s since the maneuvers started.
    pub start_s: f64,
    /// When it ended, s since the maneuvers started.
    pub end_s: f64,
    /// Its completion test held for `hold_s`.
    pub completed: bool,
    /// It was ended by its `timeout_s`.
    pub timed_out: bool,
    /// Every car acknowledged its start, this long after the phase started.
    pub started_s: Option<f64>,
    /// The completion test began to hold (for good), this long after the phase started: the
    /// time to converge.
    pub converged_s: Option<f64>,
    /// The phase error first came within the tolerance.
    pub settled_s: Option<f64>,
    /// The bound of the completion test, mm.
    pub tolerance_mm: f64,
    /// The phase error from `settled_s` to the end of the phase.
    pub error_after_settled: Option<ErrorStats>,
    /// The phase error at the end, mm.
    pub final_error_mm: Option<f64>,
    /// Every car's own status reported its law converged (first time), from the status polls.
    pub reported_converged_s: Option<f64>,
    /// Waypoints sent to a formation leader.
    pub waypoints_sent: usize,
    /// Maneuver commands that had to be sent again (no answer or refused).
    pub command_retries: u32,
    /// Maneuver commands given up on.
    pub command_failures: u32,
    /// `[t, error_mm]` every 0.5 s, t from the phase start (in `summary.json` as columns
    /// `{"t_s": [...], "error_mm": [...]}`).
    #[serde(serialize_with = "output::series_columns")]
    pub error_series: Vec<[f64; 2]>,
}

/// What an experiment run measured (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Experiment name.
    pub name: String,
    /// The car engine (`iss` or `qemu`).
    pub engine: &'static str,
    /// Seconds the maneuvers ran.
    pub duration_s: f64,
    /// The run was cancelled.
    pub cancelled: bool,
    /// The run was ended because a car failed (`on_car_failure = "abort"`).
    pub aborted: bool,
    /// Cars whose firmware stopped during the maneuvers.
    pub failed_cars: Vec<CarFailure>,
    /// Every phase completed.
    pub completed: bool,
    /// Every car with go-to points finished them.
    pub all_arrived: bool,
    /// Each phase.
    pub phases: Vec<PhaseResult>,
    /// Closest approach of two cars' body centres, mm.
    pub min_separation_mm: Option<f64>,
    /// Approaches of body centres closer than [`metrics::COLLISION_MM`].
    pub collisions: Vec<Value>,
    /// Each car.
    pub cars: Vec<CarResult>,
    /// Radio statistics: ground station, channel, nodes.
    pub radio: Value,
}

/// One car in a progress line.
#[derive(Debug, Clone)]
pub struct CarProgress {
    /// Car ID.
    pub id: u8,
    /// True position, tracking units.
    pub x: f64,
    /// True position, tracking units.
    pub y: f64,
    /// True speed, mm/s.
    pub v_mm_s: f64,
    /// The car's latest status (it may be up to a few seconds old).
    pub status: Option<Status>,
}

impl CarProgress {
    fn new(truth: &CarTruth, status: Option<Status>) -> Self {
        CarProgress {
            id: truth.id,
            x: truth.pose.x_mm / MM_PER_UNIT,
            y: truth.pose.y_mm / MM_PER_UNIT,
            v_mm_s: truth.v_mm_s,
            status,
        }
    }
}

/// A progress report: during bring-up each time a car is ready (phase 0, the cars that are
/// ready), then once per second of the maneuvers.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Seconds since the maneuvers started (bring-up: since it started).
    pub t: f64,
    /// Current phase, from 1 (0: bring-up).
    pub phase: usize,
    /// Number of phases.
    pub phases: usize,
    /// The phase's kind.
    pub kind: &'static str,
    /// The phase error now, mm.
    pub error_mm: Option<f64>,
    /// The cars.
    pub cars: Vec<CarProgress>,
    /// Cars whose firmware stopped.
    pub failed: Vec<CarFailure>,
}

impl fmt::Display for Progress {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.phase == 0 {
            write!(f, "bring-up {:>4.1}s: ready", self.t)?;
            for c in &self.cars {
                write!(f, " car{} ({:.0},{:.0})", c.id, c.x, c.y)?;
            }
            return Ok(());
        }
        write!(
            f,
            "t={:>5.1}s {}/{} {:<10}",
            self.t, self.phase, self.phases, self.kind
        )?;
        match self.error_mm {
            Some(e) => write!(f, " err {e:>4.0} mm")?,
            None => write!(f, "            ")?,
        }
        for c in &self.cars {
            write!(
                f,
                " | car{} ({:>3.0},{:>3.0}) v {:>4.0} ",
                c.id, c.x, c.y, c.v_mm_s
            )?;
            if let Some(fail) = self.failed.iter().find(|x| x.car == c.id) {
                write!(f, "FAILED at {:.1}s ({})", fail.t_s, fail.reason)?;
                continue;
            }
            match c.status {
                None => write!(f, "?")?,
                Some(s) if s.group_kind == 0 => {
                    if s.flags & flags::MANEUVER != 0 {
                        write!(f, "moving {}/{}", s.maneuver_index, s.maneuver_len)?
                    } else {
                        write!(f, "idle")?
                    }
                }
                Some(s) => write!(
                    f,
                    "{}{}",
                    maneuvers::Phase::from_bits(s.group_phase).map_or("?", maneuvers::Phase::name),
                    if s.group_converged { "*" } else { "" }
                )?,
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

/// The event log and the other files a run appends to ([`record::Recorder`]); the first
/// write error is kept and reported when the run ends.
#[derive(Debug)]
struct EventLog {
    rec: record::Recorder,
    error: Option<ExperimentError>,
}

impl EventLog {
    fn create(out: &Path, ids: &[u8]) -> Result<Self, ExperimentError> {
        Ok(EventLog {
            rec: record::Recorder::create(out, ids)?,
            error: None,
        })
    }

    fn keep(&mut self, r: Result<(), ExperimentError>) {
        if let (Err(e), None) = (r, &self.error) {
            self.error = Some(e);
        }
    }

    fn push_at(&mut self, at: Duration, car: Option<u8>, what: &str) {
        self.push(at, car, what, Value::Null);
    }

    fn push(&mut self, at: Duration, car: Option<u8>, what: &str, extra: Value) {
        let mut v = json!({ "t": at.as_secs_f64(), "event": what });
        if let Some(id) = car {
            v["car"] = json!(id);
        }
        if let (Value::Object(m), Value::Object(x)) = (&mut v, extra) {
            m.extend(x);
        }
        let r = self.rec.event(at, &v.to_string());
        self.keep(r);
    }

    fn sample(&mut self, k: usize, s: &Sample) {
        let r = self.rec.sample(k, s);
        self.keep(r);
    }

    fn phase_row(&mut self, t: f64, phase: usize, e: f64) {
        let r = self.rec.phase_row(t, phase, e);
        self.keep(r);
    }

    fn flush(&mut self) {
        let r = self.rec.flush();
        self.keep(r);
    }

    /// Flushes; the first error of the run, if any.
    fn finish(mut self) -> Result<(), ExperimentError> {
        self.flush();
        match self.error {
            Some(e) => Err(e),
            None => Ok(()),
        }
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

/// Runs the experiment in a fresh world with the firmware at `firmware` (a `softcore` build
/// for the virtual-time engine, a `qemu_virt` build for QEMU), reporting a [`Progress`] line
/// each second of world time, and writes `car<ID>.csv`, `phases.csv`, `events.jsonl`,
/// `summary.json`, the plots, `report.html`, `run.mcap` and `run.json` to `out`. Setting `cancel` ends the
/// maneuvers early (outputs are still written, `cancelled` is set in the summary) or aborts
/// bring-up. The world is torn down before this returns, whatever happens.
///
/// With the virtual-time engine every output but `run.json` (wall-clock times, host,
/// versions) is a function of the experiment file and its seed.
pub fn run(
    exp: &Experiment,
    firmware: &Path,
    out: &Path,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Summary, ExperimentError> {
    run_with(exp, firmware, out, &RunOptions::default(), progress, cancel)
}

/// [`run`] with [`RunOptions`] (a live view, which also paces world time to the wall clock).
pub fn run_with(
    exp: &Experiment,
    firmware: &Path,
    out: &Path,
    opts: &RunOptions,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Summary, ExperimentError> {
    let mut exp = exp.clone();
    exp.realtime |= opts.live.is_some();
    let result = run_inner(&exp, firmware, out, opts, progress, cancel);
    if let Err(e) = &result {
        if out.is_dir() {
            let info = json!({ "state": "error", "error": e.to_string() });
            let _ = write_file(
                &out.join("run.json"),
                &serde_json::to_string_pretty(&info).unwrap_or_default(),
            );
        }
    }
    result
}

fn run_inner(
    exp: &Experiment,
    firmware: &Path,
    out: &Path,
    opts: &RunOptions,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Summary, ExperimentError> {
    let wall_start = std::time::SystemTime::now();
    let wall = std::time::Instant::now();
    fs::create_dir_all(out).map_err(|source| ExperimentError::Write {
        path: out.into(),
        source,
    })?;
    record::mark_incomplete(out)?;
    let mut cfg = exp.world_config(firmware);
    for (spec, own) in cfg.cars.iter_mut().zip(exp.car_firmware(exp.engine)?) {
        if own.is_some() {
            spec.firmware = own;
        }
    }
    let mut world = World::start(&cfg)?;
    let mut log = EventLog::create(out, world.ids())?;
    let formats = recording::log_formats(&world);
    let mut rec = Recording::start(&mut world, &formats, out, exp, opts)
        .map_err(|e| ExperimentError::Recording(e.to_string()))?;
    log.rec.attach(rec.channels());
    log.push(
        world.now(),
        None,
        "booted",
        json!({ "name": exp.name, "cars": exp.cars.len(), "engine": world.engine_name() }),
    );
    let ids: Vec<u8> = world.ids().to_vec();
    let mut failures: Vec<CarFailure> = Vec::new();

    // Bring-up: every car's program running, drive enabled, pose valid.
    let started = world.now();
    let deadline = started + Duration::from_secs_f64(exp.bringup_s);
    let mut ready = vec![false; ids.len()];
    let mut last: Vec<Option<Status>> = vec![None; ids.len()];
    while let Some(k) = ready.iter().position(|r| !r) {
        let id = ids[k];
        for ev in world.take_events() {
            log.push_at(ev.at, Some(ev.car), &ev.what);
            if let Some(reason) = ev.what.strip_prefix("car-failed: ") {
                return Err(ExperimentError::CarFailed {
                    id: ev.car,
                    t: ev.at.as_secs_f64(),
                    reason: reason.to_owned(),
                });
            }
        }
        if let Ok(Reply::Status(s)) = world.request(id, &Request::Status, REQUEST_TIMEOUT) {
            last[k] = Some(s);
            let need = flags::DRIVE_ENABLED | flags::POSE_VALID;
            if s.phase == PHASE_RUNNING && s.flags & need == need {
                ready[k] = true;
                log.push(world.now(), Some(id), "ready", json!({}));
                let truth = world.truth();
                progress(&Progress {
                    t: (world.now() - started).as_secs_f64(),
                    phase: 0,
                    phases: exp.phases.len(),
                    kind: "bring-up",
                    error_mm: None,
                    failed: Vec::new(),
                    cars: truth
                        .iter()
                        .zip(&ready)
                        .zip(&last)
                        .filter(|((_, r), _)| **r)
                        .map(|((tr, _), st)| CarProgress::new(tr, *st))
                        .collect(),
                });
                continue;
            }
        }
        if cancel.load(Ordering::Relaxed) {
            return Err(ExperimentError::Cancelled);
        }
        if world.now() > deadline {
            return Err(ExperimentError::BringUp { id, last: last[k] });
        }
        world.run_for(Duration::from_millis(300));
        rec.drain(&mut world);
    }

    let t0 = world.now();
    let mut tracks: Vec<Vec<Sample>> = vec![Vec::new(); ids.len()];
    let mut r = Runner {
        exp,
        world: &mut world,
        ids: ids.clone(),
        log,
        t0,
        queue: VecDeque::new(),
        inflight: None,
        cars: vec![CarState::default(); ids.len()],
        poll_next: 0,
        active: None,
        results: Vec::new(),
        fatal: None,
        last_sample: Vec::new(),
    };
    let mut next_sample = t0;
    let mut next_progress = t0 + Duration::from_secs(1);
    let limit = Duration::from_secs_f64(exp.duration_s);
    let mut next_phase = 0;
    let mut finished = false;
    let mut aborted = false;
    let mut crashed = vec![false; exp.faults.crash.len()];
    let mut next_camera = t0;
    r.begin_phase(0);
    next_phase += 1;
    loop {
        r.collect();
        if let Some(e) = r.fatal.take() {
            return Err(e);
        }
        let now = r.world.now();
        if now >= next_sample {
            next_sample += SAMPLE;
            let t = r.t();
            let sample: Vec<Sample> = r
                .world
                .truth()
                .iter()
                .map(|truth| Sample {
                    t,
                    x_mm: truth.pose.x_mm,
                    y_mm: truth.pose.y_mm,
                    heading_mrad: truth.pose.heading_rad * 1000.0,
                    v_mm_s: truth.v_mm_s,
                })
                .collect();
            for (k, s) in sample.iter().enumerate() {
                tracks[k].push(*s);
                r.log.sample(k, s);
            }
            r.last_sample.clone_from(&sample);
            rec.sample(r.world, &sample);
            for ev in r.world.take_events() {
                if let Some(reason) = ev.what.strip_prefix("car-failed: ") {
                    failures.push(CarFailure {
                        car: ev.car,
                        t_s: round_to(ev.at.saturating_sub(t0).as_secs_f64(), 3),
                        reason: reason.to_owned(),
                    });
                    aborted |= exp.on_car_failure == FailurePolicy::Abort;
                }
                // The firmware aborts its maneuver when it loses its LBC or the user link;
                // the maneuver is started again once the car can drive.
                if ["UserLinkLost", "LbcRecovered", "ManeuverAborted"]
                    .iter()
                    .any(|n| ev.what.contains(n))
                {
                    r.restart(ev.car);
                }
                if ev.what.contains("ManeuverDone") {
                    if let Some(k) = r.car_index(ev.car) {
                        if r.cars[k].goto_running && r.cars[k].started_at.is_some() {
                            r.cars[k].goto_running = false;
                            r.cars[k].arrival = Some(t);
                        }
                    }
                }
                r.log.push_at(ev.at, Some(ev.car), &ev.what);
            }
            r.waypoints(&sample);
            let verdict = r.judge(t, &sample);
            if let Some(a) = &r.active {
                if let Some(&(_, e)) = a.errors.last() {
                    r.log.phase_row(t, a.index + 1, e);
                    rec.phase_error(t, a.index + 1, e);
                }
            }
            // The next phase starts at its time (cutting this one short), or once this one
            // is over.
            let at_time = exp.phases.get(next_phase).map(|p| match p.start {
                Start::At(s) => t >= s,
                Start::AfterPrevious => true,
            });
            if let Some(completed) = verdict {
                r.end_phase(t, &sample, completed, !completed);
            } else if r.active.is_some()
                && exp
                    .phases
                    .get(next_phase)
                    .is_some_and(|p| matches!(p.start, Start::At(_)))
                && at_time == Some(true)
            {
                r.end_phase(t, &sample, false, false);
            }
            if r.active.is_none() {
                match at_time {
                    Some(true) => {
                        r.begin_phase(next_phase);
                        next_phase += 1;
                    }
                    Some(false) => {}
                    None => finished = true,
                }
            }
        }
        for (c, done) in exp.faults.crash.iter().zip(crashed.iter_mut()) {
            if !*done && now >= t0 + Duration::from_secs_f64(c.at_s) {
                *done = true;
                r.world
                    .kill_car(c.car, &format!("crash injected at {:.3} s", c.at_s));
            }
        }
        if exp.camera_fps.is_some() && now >= next_camera {
            // Often enough that the 16-bit frame count cannot wrap in between.
            next_camera += CAMERA_EVERY;
            for &id in &ids {
                r.enqueue(id, Request::Camera { blob: 255 }, Purpose::Camera);
            }
        }
        if now >= next_progress {
            next_progress += Duration::from_secs(1);
            progress(&r.progress(next_phase, &failures));
            r.log.flush();
        }
        if finished || aborted || now - t0 >= limit || cancel.load(Ordering::Relaxed) {
            break;
        }
        r.pump();
        r.world.run_for(TICK);
        rec.drain(r.world);
    }
    let ran = r.t();
    if r.active.is_some() {
        let last: Vec<Sample> = tracks.iter().filter_map(|t| t.last().copied()).collect();
        if last.len() == ids.len() {
            r.end_phase(ran, &last, false, false);
        }
    }
    r.log
        .push(r.world.now(), None, "end", json!({ "t_maneuver": ran }));
    // Let the last request finish so the statistics requests below can go out.
    let settle = r.world.now();
    while r.inflight.is_some() && r.world.now() - settle < INFLIGHT_TIMEOUT {
        r.collect();
        r.world.run_for(TICK);
    }
    let Runner {
        log,
        cars: states,
        results: phases,
        ..
    } = r;
    let run = output::Finished {
        ran,
        aborted,
        cancelled: cancel.load(Ordering::Relaxed),
        log,
        states,
        phases,
        tracks,
        failures,
    };
    let summary = output::finish(exp, &mut world, run, out)?;
    rec.finish(&mut world, &summary, out)
        .map_err(ExperimentError::Recording)?;
    let state = if summary.aborted {
        "aborted"
    } else if summary.cancelled {
        "cancelled"
    } else {
        "complete"
    };
    output::write_run_info(out, &world, &cfg, state, wall_start, wall.elapsed())?;
    world.shutdown();
    Ok(summary)
}
