//! Plays an [`Experiment`] in a [`World`]: bring-up, then each phase in turn (group maneuvers
//! started with the console's `GroupStart`, a formation leader's waypoints sent with
//! `GroupWaypoint`, go-to points with `ManeuverStart`), sampling every car's true pose every
//! 100 ms, judging each phase's completion from those true poses, printing progress each
//! second, and finally writing the outputs.
//!
//! The loop never blocks on the radio: console requests go out one at a time (the ground
//! station carries one authenticated command at a time) from a queue, commands before status
//! polls, and their replies are picked up as they arrive, so sampling stays on time.

use crate::experiment::{
    Experiment, ExperimentError, FormationPhase, Phase, PhaseKind, Start, RENDEZVOUS_STILL_MM_S,
};
use crate::metrics::{self, ErrorStats, Sample};
use crate::plot;
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
use std::time::{Duration, Instant};
use ubc_app::program::console::{
    flags, Point, Points, Refusal, Reply, Request, StatsPage, Status, MAX_POINTS,
};

/// Trajectory sample period.
const SAMPLE: Duration = Duration::from_millis(100);
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
    pub wall_violations: Vec<f64>,
    /// The firmware's console counters.
    pub stats: Value,
    /// The emulated LBC's counters.
    pub lbc: Value,
    /// Tracking fixes delivered and dropped.
    pub tracking: Value,
    /// Radio state broadcasts of this car the ground station heard.
    pub states_heard: u64,
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
    /// `[t, error_mm]` every 0.5 s, t from the phase start.
    pub error_series: Vec<[f64; 2]>,
}

/// What an experiment run measured (`summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Experiment name.
    pub name: String,
    /// Seconds the maneuvers ran.
    pub duration_s: f64,
    /// The run was cancelled.
    pub cancelled: bool,
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

/// Why a request is sent.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Purpose {
    /// Start (or stop before) phase `phase`'s maneuver on the car.
    Start { phase: usize },
    /// Stop whatever runs before phase `phase` starts a go-to.
    Stop { phase: usize },
    /// Start phase `phase`'s maneuver again on a car that aborted it.
    Restart { phase: usize },
    /// Formation waypoint `index` of phase `phase`.
    Waypoint { phase: usize, index: usize },
    /// Status poll.
    Status,
}

#[derive(Debug, Clone)]
struct Command {
    car: u8,
    req: Request,
    purpose: Purpose,
    attempts: u32,
    not_before: Instant,
}

struct InFlight {
    cmd: Command,
    pending: PendingReply,
    sent: Instant,
}

/// What the runner knows of one car.
#[derive(Debug, Clone, Default)]
struct CarState {
    status: Option<Status>,
    /// When the status request that produced `status` was sent.
    status_sent: Option<Instant>,
    last_poll: Option<Instant>,
    /// The current phase's start was acknowledged at this time.
    started_at: Option<Instant>,
    /// A go-to maneuver runs (acknowledged, not yet finished).
    goto_running: bool,
    /// When the last go-to finished, s since the maneuvers started.
    arrival: Option<f64>,
    /// A go-to the car was given did not finish.
    goto_missed: bool,
    /// Distance from its last go-to point when its last `goto` phase ended, mm.
    goto_error_mm: Option<f64>,
    /// Index of the first point of the go-to list last sent (after restarts).
    goto_offset: usize,
}

/// The running phase.
struct Active {
    index: usize,
    start: Instant,
    start_s: f64,
    started_s: Option<f64>,
    acks: usize,
    /// Start commands sent (one per car taking part).
    needed_acks: usize,
    /// Completion test holding since (s since the maneuvers started).
    holding_since: Option<f64>,
    settled_s: Option<f64>,
    reported_converged_s: Option<f64>,
    /// `(t, error)` since the phase started, t since the maneuvers started.
    errors: Vec<(f64, f64)>,
    next_waypoint: usize,
    waypoint_acked: usize,
    command_retries: u32,
    command_failures: u32,
}

impl Active {
    fn new(index: usize, start: Instant, start_s: f64) -> Self {
        Self {
            index,
            start,
            start_s,
            started_s: None,
            acks: 0,
            needed_acks: 0,
            holding_since: None,
            settled_s: None,
            reported_converged_s: None,
            errors: Vec::new(),
            next_waypoint: 0,
            waypoint_acked: 0,
            command_retries: 0,
            command_failures: 0,
        }
    }
}

/// Slot offsets of a formation's followers, mm (forward, left), by car index.
fn slot_offsets(f: &FormationPhase, ids: &[u8]) -> Vec<Option<(f64, f64)>> {
    let law = Formation::new(f.shape, f.leader, None, f.spacing_units, f.speed_mm_s);
    ids.iter()
        .map(|id| {
            f.followers.iter().position(|c| c == id).map(|k| {
                let o = law.slot_offset(u8::try_from(k).unwrap_or(u8::MAX));
                (f64::from(o.x) * MM_PER_UNIT, f64::from(o.y) * MM_PER_UNIT)
            })
        })
        .collect()
}

/// The phase error at one instant (mm), from every car's true pose (`now[k]` = car `ids[k]`).
fn phase_error(phase: &Phase, ids: &[u8], now: &[Sample]) -> Option<f64> {
    match &phase.kind {
        PhaseKind::Goto { .. } => ids
            .iter()
            .zip(now)
            .filter_map(|(&id, s)| phase.goto_points(id).last().map(|&p| distance_to(s, p)))
            .reduce(f64::max),
        PhaseKind::Formation(f) => {
            let leader = now[ids.iter().position(|&i| i == f.leader)?];
            slot_offsets(f, ids)
                .iter()
                .zip(now)
                .filter_map(|(o, s)| o.map(|o| metrics::slot_error(&leader, o, s)))
                .reduce(f64::max)
        }
        PhaseKind::Rendezvous { .. } => Some(metrics::spread(now)),
        PhaseKind::Circle {
            centre,
            radius_units,
            ..
        } => {
            let e = metrics::circle_error(
                now,
                waypoint_mm(*centre),
                f64::from(*radius_units) * MM_PER_UNIT,
            );
            Some(e.radius_mm.max(e.spacing_mm))
        }
    }
}

fn waypoint_mm(w: [u16; 2]) -> (f64, f64) {
    (f64::from(w[0]) * MM_PER_UNIT, f64::from(w[1]) * MM_PER_UNIT)
}

/// Distance of a car's true pose from point `w` (tracking units), mm.
fn distance_to(s: &Sample, w: [u16; 2]) -> f64 {
    let (x, y) = waypoint_mm(w);
    (s.x_mm - x).hypot(s.y_mm - y)
}

/// The experiment's run state.
struct Runner<'a> {
    exp: &'a Experiment,
    world: &'a World,
    ids: Vec<u8>,
    log: EventLog,
    t0: Instant,
    queue: VecDeque<Command>,
    inflight: Option<InFlight>,
    cars: Vec<CarState>,
    poll_next: usize,
    active: Option<Active>,
    results: Vec<PhaseResult>,
    fatal: Option<ExperimentError>,
    /// Every car's latest true state.
    last_sample: Vec<Sample>,
}

impl Runner<'_> {
    fn t(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    fn car_index(&self, id: u8) -> Option<usize> {
        self.ids.iter().position(|&i| i == id)
    }

    fn enqueue(&mut self, car: u8, req: Request, purpose: Purpose) {
        self.queue.push_back(Command {
            car,
            req,
            purpose,
            attempts: 0,
            not_before: Instant::now(),
        });
    }

    /// Starts phase `index` now.
    fn begin_phase(&mut self, index: usize) {
        let phase = &self.exp.phases[index];
        let now = Instant::now();
        let start_s = self.t();
        // Commands of the previous phase are obsolete; status polls may stay.
        self.queue.retain(|c| c.purpose == Purpose::Status);
        for c in &mut self.cars {
            c.started_at = None;
        }
        self.active = Some(Active::new(index, now, start_s));
        self.log.push(
            None,
            "phase-started",
            json!({ "phase": index + 1, "kind": phase.kind.name() }),
        );
        let ids = self.ids.clone();
        let needed = ids
            .iter()
            .filter(|&&id| match phase.kind {
                PhaseKind::Goto {
                    speed_mm_s: None, ..
                } => !phase.goto_points(id).is_empty(),
                _ => phase.params_for(id).is_some(),
            })
            .count();
        if let Some(a) = self.active.as_mut() {
            a.needed_acks = needed;
        }
        if let PhaseKind::Goto { .. } = phase.kind {
            for (k, &id) in ids.iter().enumerate() {
                self.cars[k].goto_offset = 0;
                if !phase.goto_points(id).is_empty() {
                    self.cars[k].goto_running = true;
                    self.cars[k].arrival = None;
                }
            }
        }
        match &phase.kind {
            PhaseKind::Goto {
                speed_mm_s: None, ..
            } => {
                for &id in &ids {
                    let pts = phase.goto_points(id);
                    if index > 0 {
                        self.enqueue(id, Request::ManeuverStop, Purpose::Stop { phase: index });
                    }
                    if !pts.is_empty() {
                        self.enqueue(
                            id,
                            Request::ManeuverStart(to_points(&pts)),
                            Purpose::Start { phase: index },
                        );
                    }
                }
            }
            kind => {
                // Followers first, so that the leader starts with its group already listening.
                let mut order = ids.clone();
                if let PhaseKind::Formation(f) = kind {
                    order.retain(|&i| i != f.leader);
                    order.push(f.leader);
                }
                for id in order {
                    match phase.params_for(id) {
                        Some(p) => self.enqueue(
                            id,
                            Request::GroupStart(p),
                            Purpose::Start { phase: index },
                        ),
                        // A car without a point in a group go-to stands still.
                        None if index > 0 => {
                            self.enqueue(id, Request::ManeuverStop, Purpose::Stop { phase: index })
                        }
                        None => {}
                    }
                }
            }
        }
    }

    /// Starts the active phase's maneuver again on car `id`: a group maneuver from the
    /// start (a formation leader also gets its current waypoint again), a go-to with the
    /// points it had not reached yet.
    fn restart(&mut self, id: u8) {
        let Some(a) = &self.active else { return };
        let index = a.index;
        let Some(k) = self.car_index(id) else { return };
        let queued = self
            .queue
            .iter()
            .any(|c| c.car == id && c.purpose == Purpose::Restart { phase: index });
        if queued {
            return;
        }
        let phase = &self.exp.phases[index];
        let req = match phase.params_for(id) {
            Some(params) => Request::GroupStart(params),
            None => {
                let points = phase.goto_points(id);
                if !self.cars[k].goto_running || points.is_empty() {
                    return;
                }
                let c = &mut self.cars[k];
                let from = (c.goto_offset + c.status.map_or(0, |s| usize::from(s.maneuver_index)))
                    .min(points.len() - 1);
                c.goto_offset = from;
                // Its index counts from the new list's start.
                c.status = None;
                Request::ManeuverStart(to_points(&points[from..]))
            }
        };
        self.cars[k].started_at = None;
        let waypoint = match &phase.kind {
            PhaseKind::Formation(f) if f.leader == id && a.next_waypoint > 0 => {
                Some((a.next_waypoint - 1, f.waypoints[a.next_waypoint - 1]))
            }
            _ => None,
        };
        self.log.push(
            Some(id),
            "maneuver-restarted",
            json!({ "phase": index + 1 }),
        );
        self.enqueue(id, req, Purpose::Restart { phase: index });
        if let Some((i, [x, y])) = waypoint {
            self.enqueue(
                id,
                Request::GroupWaypoint { x, y },
                Purpose::Waypoint {
                    phase: index,
                    index: i,
                },
            );
        }
    }

    /// Sends the next request if none is on its way.
    fn pump(&mut self) {
        if self.inflight.is_some() {
            return;
        }
        let now = Instant::now();
        let cmd = match self.queue.iter().position(|c| c.not_before <= now) {
            Some(i) => self.queue.remove(i),
            None => self.next_poll(now),
        };
        let Some(mut cmd) = cmd else { return };
        match self.world.try_request(cmd.car, &cmd.req) {
            Ok(Some(pending)) => {
                cmd.attempts += 1;
                if cmd.purpose == Purpose::Status {
                    if let Some(k) = self.car_index(cmd.car) {
                        self.cars[k].last_poll = Some(now);
                    }
                }
                self.inflight = Some(InFlight {
                    cmd,
                    pending,
                    sent: now,
                });
            }
            Ok(None) => self.queue.push_front(cmd),
            Err(e) => self.failed(cmd, &e.to_string()),
        }
    }

    /// A status poll for the car asked least recently, if it is due.
    fn next_poll(&mut self, now: Instant) -> Option<Command> {
        let n = self.ids.len();
        for step in 0..n {
            let k = (self.poll_next + step) % n;
            let due = self.cars[k]
                .last_poll
                .is_none_or(|t| now.duration_since(t) >= STATUS_EVERY);
            if due {
                self.poll_next = (k + 1) % n;
                return Some(Command {
                    car: self.ids[k],
                    req: Request::Status,
                    purpose: Purpose::Status,
                    attempts: 0,
                    not_before: now,
                });
            }
        }
        None
    }

    /// Picks up the answer of the request on its way.
    fn collect(&mut self) {
        let Some(f) = &self.inflight else { return };
        let outcome = match f.pending.poll() {
            Some(o) => o,
            None if f.sent.elapsed() > INFLIGHT_TIMEOUT => {
                Err(WorldError::Timeout { id: f.cmd.car })
            }
            None => return,
        };
        let Some(InFlight { cmd, sent, .. }) = self.inflight.take() else {
            return;
        };
        match outcome {
            Ok(reply) => self.answered(cmd, sent, reply),
            Err(e) => self.failed(cmd, &e.to_string()),
        }
    }

    /// Whether car `k` is within the phase's tolerance of its last go-to point (true pose).
    fn at_last_point(&self, k: usize) -> bool {
        let Some(a) = &self.active else { return false };
        let last = self.exp.phases[a.index]
            .goto_points(self.ids[k])
            .last()
            .copied();
        match (last, self.last_sample.get(k)) {
            (Some(p), Some(s)) => distance_to(s, p) <= self.exp.phases[a.index].tolerance_mm,
            _ => false,
        }
    }

    fn current(&self, phase: usize) -> bool {
        self.active.as_ref().is_some_and(|a| a.index == phase)
    }

    fn answered(&mut self, cmd: Command, sent: Instant, reply: Reply) {
        let k = self.car_index(cmd.car);
        match (cmd.purpose, reply) {
            (Purpose::Status, Reply::Status(s)) => {
                let t = self.t();
                if let Some(k) = k {
                    let c = &mut self.cars[k];
                    c.status = Some(s);
                    c.status_sent = Some(sent);
                    // A console go-to that was running when this was asked has ended:
                    // finished if the car is at its last point, else aborted (started again).
                    let console_goto = self.active.as_ref().is_some_and(|a| {
                        matches!(
                            self.exp.phases[a.index].kind,
                            PhaseKind::Goto {
                                speed_mm_s: None,
                                ..
                            }
                        )
                    });
                    if console_goto
                        && c.goto_running
                        && c.started_at.is_some_and(|a| a <= sent)
                        && s.flags & flags::MANEUVER == 0
                    {
                        if self.at_last_point(k) {
                            let c = &mut self.cars[k];
                            c.goto_running = false;
                            c.arrival = Some(t);
                            self.log.push(Some(cmd.car), "maneuver-finished", json!({}));
                        } else {
                            self.restart(cmd.car);
                        }
                    }
                }
            }
            (Purpose::Status, _) => {}
            (Purpose::Stop { .. }, _) => {}
            (Purpose::Restart { phase }, Reply::GroupStarted | Reply::ManeuverStarted(_))
                if self.current(phase) =>
            {
                if let Some(k) = k {
                    self.cars[k].started_at = Some(Instant::now());
                }
            }
            (Purpose::Start { phase }, Reply::GroupStarted | Reply::ManeuverStarted(_))
                if self.current(phase) =>
            {
                if let Some(k) = k {
                    self.cars[k].started_at = Some(Instant::now());
                }
                self.log.push(
                    Some(cmd.car),
                    "maneuver-started",
                    json!({ "phase": phase + 1 }),
                );
                let t = self.t();
                if let Some(a) = self.active.as_mut() {
                    a.acks += 1;
                    if a.acks >= a.needed_acks && a.started_s.is_none() {
                        a.started_s = Some(t - a.start_s);
                    }
                }
            }
            (Purpose::Waypoint { phase, index }, Reply::GroupWaypointSet)
                if self.current(phase) =>
            {
                if let Some(a) = self.active.as_mut() {
                    a.waypoint_acked = a.waypoint_acked.max(index + 1);
                }
            }
            (
                Purpose::Start { phase }
                | Purpose::Restart { phase }
                | Purpose::Waypoint { phase, .. },
                _,
            ) if !self.current(phase) => {}
            (_, Reply::Refused(r @ (Refusal::UnknownRequest | Refusal::Malformed))) => {
                // The firmware does not know the request: nothing to retry.
                self.fatal = Some(ExperimentError::ManeuverRefused {
                    id: cmd.car,
                    reply: format!("{r:?} (does the firmware support group maneuvers?)"),
                });
            }
            (_, other) => self.failed(cmd, &format!("{other:?}")),
        }
    }

    /// A request got no (useful) answer: retry maneuver commands a few times.
    fn failed(&mut self, mut cmd: Command, why: &str) {
        match cmd.purpose {
            Purpose::Status => {}
            Purpose::Start { phase }
            | Purpose::Stop { phase }
            | Purpose::Restart { phase }
            | Purpose::Waypoint { phase, .. } => {
                if !self.current(phase) {
                    return;
                }
                self.log.push(
                    Some(cmd.car),
                    "request-failed",
                    json!({ "request": format!("{:?}", cmd.req.tag()), "why": why, "attempt": cmd.attempts }),
                );
                let Some(a) = self.active.as_mut() else {
                    return;
                };
                if cmd.attempts < COMMAND_ATTEMPTS {
                    a.command_retries += 1;
                    cmd.not_before = Instant::now() + Duration::from_millis(300);
                    self.queue.push_front(cmd);
                } else {
                    a.command_failures += 1;
                    if let Some(k) = self.car_index(cmd.car) {
                        if matches!(cmd.req, Request::ManeuverStart(_)) {
                            self.cars[k].goto_running = false;
                            self.cars[k].goto_missed = true;
                        }
                    }
                }
            }
        }
    }

    /// Formation waypoints: the next one once the leader reached the previous one (or at its
    /// time).
    fn waypoints(&mut self, now: &[Sample]) {
        let Some(a) = &self.active else { return };
        let index = a.index;
        let PhaseKind::Formation(f) = &self.exp.phases[index].kind else {
            return;
        };
        let next = a.next_waypoint;
        if next >= f.waypoints.len() {
            return;
        }
        let leader_started = self
            .car_index(f.leader)
            .is_some_and(|k| self.cars[k].started_at.is_some());
        if !leader_started {
            return;
        }
        let due = match &f.waypoint_at_s {
            Some(at) => a.start.elapsed().as_secs_f64() >= at[next],
            None => {
                next == 0 || {
                    // Reached the previous waypoint (acknowledged before).
                    let Some(k) = self.car_index(f.leader) else {
                        return;
                    };
                    a.waypoint_acked >= next
                        && distance_to(&now[k], f.waypoints[next - 1])
                            <= f64::from(f.reach_units) * MM_PER_UNIT
                }
            }
        };
        if !due {
            return;
        }
        let [x, y] = f.waypoints[next];
        let leader = f.leader;
        if next > 0 && f.waypoint_at_s.is_none() {
            self.log.push(
                Some(leader),
                "waypoint-reached",
                json!({ "phase": index + 1, "index": next - 1 }),
            );
        }
        self.log.push(
            Some(leader),
            "waypoint-sent",
            json!({ "phase": index + 1, "index": next, "x": x, "y": y }),
        );
        if let Some(a) = self.active.as_mut() {
            a.next_waypoint = next + 1;
        }
        self.enqueue(
            leader,
            Request::GroupWaypoint { x, y },
            Purpose::Waypoint {
                phase: index,
                index: next,
            },
        );
    }

    /// Whether the active phase's completion test holds now.
    fn complete_now(&self, phase: &Phase, a: &Active, now: &[Sample], err: Option<f64>) -> bool {
        if a.started_s.is_none() {
            return false;
        }
        match &phase.kind {
            PhaseKind::Goto { .. } => self
                .ids
                .iter()
                .enumerate()
                .all(|(k, &id)| phase.goto_points(id).is_empty() || !self.cars[k].goto_running),
            PhaseKind::Formation(f) => {
                let leader_done = match f.waypoints.last() {
                    None => true,
                    Some(&last) => {
                        a.waypoint_acked == f.waypoints.len()
                            && self.car_index(f.leader).is_some_and(|k| {
                                distance_to(&now[k], last) <= f64::from(f.reach_units) * MM_PER_UNIT
                            })
                    }
                };
                leader_done && err.is_some_and(|e| e <= phase.tolerance_mm)
            }
            PhaseKind::Rendezvous { .. } => {
                err.is_some_and(|e| e <= phase.tolerance_mm)
                    && now.iter().all(|s| s.v_mm_s.abs() < RENDEZVOUS_STILL_MM_S)
            }
            PhaseKind::Circle { .. } => err.is_some_and(|e| e <= phase.tolerance_mm),
        }
    }

    /// Records one sample of the active phase; answers whether it is over (completed or
    /// timed out).
    fn judge(&mut self, t: f64, now: &[Sample]) -> Option<bool> {
        let a = self.active.as_ref()?;
        let phase = &self.exp.phases[a.index];
        // A group go-to car has arrived when it stands at its point.
        if let PhaseKind::Goto {
            speed_mm_s: Some(_),
            ..
        } = phase.kind
        {
            for (k, s) in now.iter().enumerate() {
                let c = &self.cars[k];
                if c.goto_running
                    && c.started_at.is_some()
                    && s.v_mm_s.abs() < GOTO_STILL_MM_S
                    && self.at_last_point(k)
                {
                    let c = &mut self.cars[k];
                    c.goto_running = false;
                    c.arrival = Some(t);
                    self.log
                        .push(Some(self.ids[k]), "maneuver-finished", json!({}));
                }
            }
        }
        let a = self.active.as_ref()?;
        let phase = &self.exp.phases[a.index];
        let err = phase_error(phase, &self.ids, now);
        let complete = self.complete_now(phase, a, now, err);
        // The cars' own convergence reports, from statuses asked after the start was
        // acknowledged.
        let reported = self.ids.iter().enumerate().all(|(k, &id)| {
            let c = &self.cars[k];
            if phase.params_for(id).is_none() {
                return true;
            }
            match (c.status, c.status_sent, c.started_at) {
                (Some(s), Some(sent), Some(started)) => sent >= started && s.group_converged,
                _ => false,
            }
        });
        let a = self.active.as_mut()?;
        if let Some(e) = err {
            a.errors.push((t, e));
            if a.settled_s.is_none() && a.started_s.is_some() && e <= phase.tolerance_mm {
                a.settled_s = Some(t - a.start_s);
            }
        }
        if reported
            && a.reported_converged_s.is_none()
            && !matches!(
                phase.kind,
                PhaseKind::Goto {
                    speed_mm_s: None,
                    ..
                }
            )
        {
            a.reported_converged_s = Some(t - a.start_s);
        }
        if complete {
            let since = *a.holding_since.get_or_insert(t);
            if t - since >= phase.hold_s {
                return Some(true);
            }
        } else {
            a.holding_since = None;
        }
        let timed_out = phase.timeout_s.is_some_and(|limit| t - a.start_s >= limit);
        timed_out.then_some(false)
    }

    /// Closes the active phase; `now` is the latest sample of every car.
    fn end_phase(&mut self, t: f64, now: &[Sample], completed: bool, timed_out: bool) {
        let Some(a) = self.active.take() else { return };
        let phase = &self.exp.phases[a.index];
        for ((c, s), &id) in self.cars.iter_mut().zip(now).zip(&self.ids) {
            if let Some(&last) = phase.goto_points(id).last() {
                c.goto_error_mm = Some(distance_to(s, last));
            }
        }
        let converged_s = if completed {
            a.holding_since.map(|h| h - a.start_s)
        } else {
            None
        };
        let after: Vec<f64> = match a.settled_s {
            Some(s) => a
                .errors
                .iter()
                .filter(|(te, _)| te - a.start_s >= s)
                .map(|&(_, e)| e)
                .collect(),
            None => Vec::new(),
        };
        let mut series = Vec::new();
        let mut next = 0.0;
        for &(te, e) in &a.errors {
            let rel = te - a.start_s;
            if rel + 1e-9 >= next {
                series.push([(rel * 10.0).round() / 10.0, e.round()]);
                next = (rel / SERIES_EVERY_S).floor() * SERIES_EVERY_S + SERIES_EVERY_S;
            }
        }
        let event = if completed {
            "phase-complete"
        } else if timed_out {
            "phase-timeout"
        } else {
            "phase-ended"
        };
        self.log.push(
            None,
            event,
            json!({ "phase": a.index + 1, "converged_s": converged_s }),
        );
        let waypoints_sent = a.next_waypoint;
        self.results.push(PhaseResult {
            phase: a.index + 1,
            kind: phase.kind.name(),
            start_s: a.start_s,
            end_s: t,
            completed,
            timed_out,
            started_s: a.started_s,
            converged_s,
            settled_s: a.settled_s,
            tolerance_mm: phase.tolerance_mm,
            error_after_settled: metrics::error_stats(&after),
            final_error_mm: a.errors.last().map(|&(_, e)| e),
            reported_converged_s: a.reported_converged_s,
            waypoints_sent,
            command_retries: a.command_retries,
            command_failures: a.command_failures,
            error_series: series,
        });
        // Go-to maneuvers of an ended phase that did not finish count as missed.
        if matches!(phase.kind, PhaseKind::Goto { .. }) {
            for c in &mut self.cars {
                if c.goto_running {
                    c.goto_running = false;
                    c.goto_missed = true;
                }
            }
        }
    }
}

/// Runs the experiment in a fresh world with the firmware at `firmware`, reporting a
/// [`Progress`] line each second, and writes `car<ID>.csv`, `phases.csv`, `events.jsonl`,
/// `summary.json` and `trajectories.svg` to `out`. Setting `cancel` ends the maneuvers early
/// (outputs are still written, `cancelled` is set in the summary) or aborts bring-up. The
/// world is torn down before this returns, whatever happens.
pub fn run(
    exp: &Experiment,
    firmware: &Path,
    out: &Path,
    progress: &mut dyn FnMut(&Progress),
    cancel: &AtomicBool,
) -> Result<Summary, ExperimentError> {
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
    let started = Instant::now();
    let deadline = started + Duration::from_secs_f64(exp.bringup_s);
    let mut ready = vec![false; ids.len()];
    let mut last: Vec<Option<Status>> = vec![None; ids.len()];
    while let Some(k) = ready.iter().position(|r| !r) {
        let id = ids[k];
        if let Ok(Reply::Status(s)) = world.request(id, &Request::Status, REQUEST_TIMEOUT) {
            last[k] = Some(s);
            let need = flags::DRIVE_ENABLED | flags::POSE_VALID;
            if s.phase == PHASE_RUNNING && s.flags & need == need {
                ready[k] = true;
                log.push(Some(id), "ready", json!({}));
                let truth = world.truth();
                progress(&Progress {
                    t: started.elapsed().as_secs_f64(),
                    phase: 0,
                    phases: exp.phases.len(),
                    kind: "bring-up",
                    error_mm: None,
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
        if Instant::now() > deadline || cancel.load(Ordering::Relaxed) {
            return Err(ExperimentError::BringUp { id, last: last[k] });
        }
        std::thread::sleep(Duration::from_millis(300));
    }

    let t0 = Instant::now();
    let mut r = Runner {
        exp,
        world: &world,
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
    let mut tracks: Vec<Vec<Sample>> = vec![Vec::new(); ids.len()];
    let mut phase_rows: Vec<(f64, usize, f64)> = Vec::new();
    let mut next_sample = t0;
    let mut next_progress = t0 + Duration::from_secs(1);
    let limit = Duration::from_secs_f64(exp.duration_s);
    let mut next_phase = 0;
    let mut finished = false;
    r.begin_phase(0);
    next_phase += 1;
    loop {
        r.collect();
        if let Some(e) = r.fatal.take() {
            return Err(e);
        }
        let now = Instant::now();
        if now >= next_sample {
            next_sample += SAMPLE;
            let t = r.t();
            let sample: Vec<Sample> = world
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
            }
            r.last_sample.clone_from(&sample);
            for ev in world.take_events() {
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
                    phase_rows.push((t, a.index + 1, e));
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
        if now >= next_progress {
            next_progress += Duration::from_secs(1);
            let truth = world.truth();
            let (phase, kind, error_mm) = match &r.active {
                Some(a) => (
                    a.index + 1,
                    exp.phases[a.index].kind.name(),
                    a.errors.last().map(|&(_, e)| e),
                ),
                None if next_phase < exp.phases.len() => (next_phase, "waiting", None),
                None => (exp.phases.len(), "done", None),
            };
            let line = Progress {
                t: r.t(),
                phase,
                phases: exp.phases.len(),
                kind,
                error_mm,
                cars: truth
                    .iter()
                    .zip(&r.cars)
                    .map(|(tr, c)| CarProgress::new(tr, c.status))
                    .collect(),
            };
            progress(&line);
        }
        if finished || t0.elapsed() >= limit || cancel.load(Ordering::Relaxed) {
            break;
        }
        r.pump();
        std::thread::sleep(Duration::from_millis(10));
    }
    let ran = r.t();
    if r.active.is_some() {
        let last: Vec<Sample> = tracks.iter().filter_map(|t| t.last().copied()).collect();
        if last.len() == ids.len() {
            r.end_phase(ran, &last, false, false);
        }
    }
    r.log.push(None, "end", json!({ "t_maneuver": ran }));
    // Let the last request finish so the statistics requests below can go out.
    let settle = Instant::now();
    while r.inflight.is_some() && settle.elapsed() < INFLIGHT_TIMEOUT {
        r.collect();
        std::thread::sleep(Duration::from_millis(10));
    }
    let Runner {
        mut log,
        cars: states,
        results: phases,
        ..
    } = r;

    // Link statistics: each car's console stats, the LBC emulators, the ground station, the hub.
    let mut stats = Vec::new();
    for &id in &ids {
        let mut pages = serde_json::Map::new();
        for page in StatsPage::ALL {
            if let Ok(Reply::Stats { values, .. }) =
                world.request(id, &Request::Stats(page as u8), Duration::from_secs(3))
            {
                let counters: serde_json::Map<String, Value> = page
                    .counters()
                    .iter()
                    .zip(values.iter())
                    .map(|(n, v)| ((*n).to_owned(), json!(v)))
                    .collect();
                pages.insert(page.name().to_owned(), Value::Object(counters));
            }
        }
        stats.push(Value::Object(pages));
    }
    for ev in world.take_events() {
        log.push_at(ev.at, Some(ev.car), &ev.what);
    }
    let truth = world.truth();
    let ground = world.ground_counters();
    let gstats = world.ground_stats();
    let hub = world.shutdown();

    // The last go-to points each car was given.
    let last_points = |id: u8| -> Vec<[u16; 2]> {
        exp.phases
            .iter()
            .rev()
            .map(|p| p.goto_points(id))
            .find(|p| !p.is_empty())
            .unwrap_or_default()
    };
    let mut cars = Vec::new();
    for (k, &id) in ids.iter().enumerate() {
        let targets = last_points(id);
        let t = &truth[k];
        let s = &states[k];
        cars.push(CarResult {
            id,
            distance_mm: metrics::distance_travelled(&tracks[k]),
            final_error_mm: s.goto_error_mm,
            arrived: targets.is_empty()
                || (!s.goto_missed && !s.goto_running && s.arrival.is_some()),
            arrival_s: s.arrival,
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
            states_heard: t.states_heard,
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
    let phase_at = |t: f64| {
        phases
            .iter()
            .find(|p| t >= p.start_s && t <= p.end_s)
            .map(|p| p.phase)
    };
    let summary = Summary {
        name: exp.name.clone(),
        duration_s: ran,
        cancelled: cancel.load(Ordering::Relaxed),
        completed: phases.len() == exp.phases.len() && phases.iter().all(|p| p.completed),
        all_arrived: cars.iter().all(|c| c.arrived),
        min_separation_mm: metrics::min_separation(&tracks).map(|e| e.distance_mm),
        collisions: metrics::collisions(&tracks)
            .iter()
            .map(|e| {
                json!({
                    "cars": [ids[e.cars.0], ids[e.cars.1]], "t": e.t, "distance_mm": e.distance_mm,
                    "phase": phase_at(e.t),
                })
            })
            .collect(),
        phases,
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
    let mut csv = String::from("t,phase,error_mm\n");
    for (t, p, e) in &phase_rows {
        csv.push_str(&format!("{t:.3},{p},{e:.1}\n"));
    }
    write_file(&out.join("phases.csv"), &csv)?;
    let mut jsonl = log.lines.join("\n");
    jsonl.push('\n');
    write_file(&out.join("events.jsonl"), &jsonl)?;
    let text = serde_json::to_string_pretty(&summary).unwrap_or_default();
    write_file(&out.join("summary.json"), &text)?;
    write_file(
        &out.join("trajectories.svg"),
        &plot_document(exp, &ids, &tracks, &summary.phases),
    )?;
    Ok(summary)
}

/// The plot: tracks, go-to points and formation waypoints as crosses, circles drawn, phase
/// starts numbered on every track.
fn plot_document(
    exp: &Experiment,
    ids: &[u8],
    tracks: &[Vec<Sample>],
    phases: &[PhaseResult],
) -> String {
    let targets: Vec<Vec<(f64, f64)>> = ids
        .iter()
        .map(|&id| {
            let mut pts = Vec::new();
            for p in &exp.phases {
                pts.extend(p.goto_points(id).into_iter().map(waypoint_mm));
                if let PhaseKind::Formation(f) = &p.kind {
                    if f.leader == id {
                        pts.extend(f.waypoints.iter().copied().map(waypoint_mm));
                    }
                }
            }
            pts
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
    let overlay = plot::Overlay {
        phase_starts: phases.iter().map(|p| (p.phase, p.start_s)).collect(),
        circles: exp
            .phases
            .iter()
            .filter_map(|p| match &p.kind {
                PhaseKind::Circle {
                    centre,
                    radius_units,
                    ..
                } => Some((waypoint_mm(*centre), f64::from(*radius_units) * MM_PER_UNIT)),
                _ => None,
            })
            .collect(),
    };
    plot::svg_with(&exp.name, &plot_tracks, &overlay)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f64, y: f64, heading_mrad: f64, v: f64) -> Sample {
        Sample {
            t: 0.0,
            x_mm: x,
            y_mm: y,
            heading_mrad,
            v_mm_s: v,
        }
    }

    const FORMATION: &str = r#"
name = "f"
duration_s = 60
[[cars]]
id = 1
x = 300
y = 400
heading_mrad = 1571
[[cars]]
id = 2
x = 300
y = 300
[[cars]]
id = 3
x = 300
y = 200
[[phases]]
kind = "formation"
shape = "line"
leader = 1
spacing_units = 100
speed_mm_s = 100
[[phases]]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
[[phases]]
kind = "circle"
centre = [300, 400]
radius_units = 100
speed_mm_s = 0
"#;

    #[test]
    fn phase_errors_from_true_poses() {
        let exp = Experiment::parse(FORMATION).unwrap();
        let ids = [1, 2, 3];
        // Leader at (750, 1000) mm facing +Y; slots 250 and 500 mm behind it.
        let now = [
            at(750.0, 1000.0, 1570.796, 0.0),
            at(750.0, 750.0, 0.0, 0.0),
            at(780.0, 460.0, 0.0, 0.0),
        ];
        let e = phase_error(&exp.phases[0], &ids, &now).unwrap();
        assert!((e - 50.0).abs() < 0.01, "{e}");
        // Rendezvous: spread from the centroid (750, 736.7).
        let e = phase_error(&exp.phases[1], &ids, &now).unwrap();
        assert!((e - metrics::spread(&now)).abs() < 1e-9);
        // Circle of 250 mm about (750, 1000): the leader sits on the centre.
        let e = phase_error(&exp.phases[2], &ids, &now).unwrap();
        assert!(e >= 250.0, "{e}");
    }

    #[test]
    fn progress_line() {
        let p = Progress {
            t: 3.0,
            phase: 1,
            phases: 2,
            kind: "formation",
            error_mm: Some(48.4),
            cars: vec![
                CarProgress {
                    id: 1,
                    x: 300.2,
                    y: 512.0,
                    v_mm_s: 99.6,
                    status: Some(Status {
                        group_kind: 1,
                        group_phase: 2,
                        group_converged: true,
                        ..Status::default()
                    }),
                },
                CarProgress {
                    id: 2,
                    x: 300.0,
                    y: 400.0,
                    v_mm_s: 0.0,
                    status: None,
                },
                CarProgress {
                    id: 3,
                    x: 100.0,
                    y: 100.0,
                    v_mm_s: 250.0,
                    status: Some(Status {
                        flags: flags::MANEUVER,
                        maneuver_index: 1,
                        maneuver_len: 2,
                        ..Status::default()
                    }),
                },
            ],
        };
        assert_eq!(
            p.to_string(),
            "t=  3.0s 1/2 formation  err   48 mm | car1 (300,512) v  100 track* | car2 (300,400) v    0 ? | car3 (100,100) v  250 moving 1/2"
        );
    }
}
