//! The run loop's state: the command queue to the cars, the request on its way, what is known
//! of each car, and the phase that runs.

use super::judge::distance_to;
use super::*;

/// Why a request is sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Purpose {
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
    /// Camera report (frames the car's vision processed).
    Camera,
}

/// Frames a car's vision processed, counted from its camera reports (whose count wraps at
/// 65536).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct FrameCount {
    /// World time of the first and of the latest report, s.
    pub(super) first_s: f64,
    pub(super) last_s: f64,
    /// The latest report's count.
    pub(super) last: u16,
    /// Frames between the first and the latest report.
    pub(super) frames: u64,
}

impl FrameCount {
    /// Frames per second between the first and the latest report.
    pub(super) fn fps(&self) -> Option<f64> {
        let dt = self.last_s - self.first_s;
        (dt > 0.5).then(|| self.frames as f64 / dt)
    }
}

#[derive(Debug, Clone)]
pub(super) struct Command {
    pub(super) car: u8,
    pub(super) req: Request,
    pub(super) purpose: Purpose,
    pub(super) attempts: u32,
    pub(super) not_before: Duration,
}

pub(super) struct InFlight {
    pub(super) cmd: Command,
    pub(super) pending: PendingReply,
    pub(super) sent: Duration,
}

/// What the runner knows of one car.
#[derive(Debug, Clone, Default)]
pub(super) struct CarState {
    pub(super) status: Option<Status>,
    /// When the status request that produced `status` was sent.
    pub(super) status_sent: Option<Duration>,
    pub(super) last_poll: Option<Duration>,
    /// The current phase's start was acknowledged at this time.
    pub(super) started_at: Option<Duration>,
    /// A go-to maneuver runs (acknowledged, not yet finished).
    pub(super) goto_running: bool,
    /// When the last go-to finished, s since the maneuvers started.
    pub(super) arrival: Option<f64>,
    /// A go-to the car was given did not finish.
    pub(super) goto_missed: bool,
    /// Distance from its last go-to point when its last `goto` phase ended, mm.
    pub(super) goto_error_mm: Option<f64>,
    /// Index of the first point of the go-to list last sent (after restarts).
    pub(super) goto_offset: usize,
    /// Frames its vision processed (experiments with a camera).
    pub(super) frames: Option<FrameCount>,
}

impl CarState {
    /// A camera report with frame count `frames` at world time `t` (s).
    pub(super) fn count_frames(&mut self, t: f64, frames: u16) {
        let c = self.frames.get_or_insert(FrameCount {
            first_s: t,
            last_s: t,
            last: frames,
            frames: 0,
        });
        c.frames += u64::from(frames.wrapping_sub(c.last));
        c.last = frames;
        c.last_s = t;
    }
}

/// The running phase.
pub(super) struct Active {
    pub(super) index: usize,
    pub(super) start: Duration,
    pub(super) start_s: f64,
    pub(super) started_s: Option<f64>,
    pub(super) acks: usize,
    /// Start commands sent (one per car taking part).
    pub(super) needed_acks: usize,
    /// Completion test holding since (s since the maneuvers started).
    pub(super) holding_since: Option<f64>,
    pub(super) settled_s: Option<f64>,
    pub(super) reported_converged_s: Option<f64>,
    /// `(t, error)` since the phase started, t since the maneuvers started.
    pub(super) errors: Vec<(f64, f64)>,
    pub(super) next_waypoint: usize,
    pub(super) waypoint_acked: usize,
    pub(super) command_retries: u32,
    pub(super) command_failures: u32,
}

impl Active {
    pub(super) fn new(index: usize, start: Duration, start_s: f64) -> Self {
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

/// The experiment's run state.
pub(super) struct Runner<'a> {
    pub(super) exp: &'a Experiment,
    pub(super) world: &'a mut World,
    pub(super) ids: Vec<u8>,
    pub(super) log: EventLog,
    pub(super) t0: Duration,
    pub(super) queue: VecDeque<Command>,
    pub(super) inflight: Option<InFlight>,
    pub(super) cars: Vec<CarState>,
    pub(super) poll_next: usize,
    pub(super) active: Option<Active>,
    pub(super) results: Vec<PhaseResult>,
    pub(super) fatal: Option<ExperimentError>,
    /// Every car's latest true state.
    pub(super) last_sample: Vec<Sample>,
}

impl Runner<'_> {
    pub(super) fn t(&self) -> f64 {
        (self.world.now() - self.t0).as_secs_f64()
    }

    pub(super) fn car_index(&self, id: u8) -> Option<usize> {
        self.ids.iter().position(|&i| i == id)
    }

    pub(super) fn enqueue(&mut self, car: u8, req: Request, purpose: Purpose) {
        self.queue.push_back(Command {
            car,
            req,
            purpose,
            attempts: 0,
            not_before: self.world.now(),
        });
    }

    /// Starts phase `index` now.
    pub(super) fn begin_phase(&mut self, index: usize) {
        let phase = &self.exp.phases[index];
        let now = self.world.now();
        let start_s = self.t();
        // Commands of the previous phase are obsolete; status polls may stay.
        self.queue.retain(|c| c.purpose == Purpose::Status);
        for c in &mut self.cars {
            c.started_at = None;
        }
        self.active = Some(Active::new(index, now, start_s));
        self.log.push(
            self.world.now(),
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
                PhaseKind::Program(_) => phase.runs_program(id),
                _ => phase.params_for(id).is_some(),
            })
            .count();
        if let Some(a) = self.active.as_mut() {
            a.needed_acks = needed;
        }
        if let PhaseKind::Goto { .. } | PhaseKind::Program(_) = phase.kind {
            for (k, &id) in ids.iter().enumerate() {
                self.cars[k].goto_offset = 0;
                if !phase.goto_points(id).is_empty() || phase.runs_program(id) {
                    self.cars[k].goto_running = true;
                    self.cars[k].arrival = None;
                }
            }
        }
        match &phase.kind {
            PhaseKind::Program(p) => {
                for &id in &ids {
                    if phase.runs_program(id) {
                        self.enqueue(
                            id,
                            Request::ProgramStart(p.args.iter().copied().collect()),
                            Purpose::Start { phase: index },
                        );
                    } else if index > 0 {
                        self.enqueue(id, Request::ManeuverStop, Purpose::Stop { phase: index });
                    }
                }
            }
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
    pub(super) fn restart(&mut self, id: u8) {
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
        let req = match (phase.params_for(id), &phase.kind) {
            (Some(params), _) => Request::GroupStart(params),
            (None, PhaseKind::Program(p)) => {
                if !phase.runs_program(id) || !self.cars[k].goto_running {
                    return;
                }
                Request::ProgramStart(p.args.iter().copied().collect())
            }
            (None, _) => {
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
        let waypoint = match phase.waypoint_plan() {
            Some(plan) if plan.cars.contains(&id) && a.next_waypoint > 0 => plan
                .waypoints
                .get(a.next_waypoint - 1)
                .map(|&w| (a.next_waypoint - 1, w)),
            _ => None,
        };
        self.log.push(
            self.world.now(),
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
    pub(super) fn pump(&mut self) {
        if self.inflight.is_some() {
            return;
        }
        let now = self.world.now();
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
    pub(super) fn next_poll(&mut self, now: Duration) -> Option<Command> {
        let n = self.ids.len();
        for step in 0..n {
            let k = (self.poll_next + step) % n;
            let due = self.cars[k]
                .last_poll
                .is_none_or(|t| now.saturating_sub(t) >= STATUS_EVERY);
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
    pub(super) fn collect(&mut self) {
        let Some(f) = &self.inflight else { return };
        let outcome = match self.world.poll_reply(&f.pending) {
            Some(o) => o,
            None if self.world.now().saturating_sub(f.sent) > INFLIGHT_TIMEOUT => {
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
    pub(super) fn at_last_point(&self, k: usize) -> bool {
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

    pub(super) fn current(&self, phase: usize) -> bool {
        self.active.as_ref().is_some_and(|a| a.index == phase)
    }

    pub(super) fn answered(&mut self, cmd: Command, sent: Duration, reply: Reply) {
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
                    let (console_goto, program) =
                        self.active.as_ref().map_or((false, false), |a| {
                            match self.exp.phases[a.index].kind {
                                PhaseKind::Goto {
                                    speed_mm_s: None, ..
                                } => (true, false),
                                PhaseKind::Program(_) => (false, true),
                                _ => (false, false),
                            }
                        });
                    if (console_goto || program)
                        && c.goto_running
                        && c.started_at.is_some_and(|a| a <= sent)
                        && s.flags & flags::MANEUVER == 0
                    {
                        // A program that is no longer running has finished (an aborted one
                        // is started again on its ManeuverAborted-like notices).
                        if program || self.at_last_point(k) {
                            let c = &mut self.cars[k];
                            c.goto_running = false;
                            c.arrival = Some(t);
                            self.log.push(
                                self.world.now(),
                                Some(cmd.car),
                                "maneuver-finished",
                                json!({}),
                            );
                        } else {
                            self.restart(cmd.car);
                        }
                    }
                }
            }
            (Purpose::Camera, Reply::Camera(r)) => {
                let t = self.world.now().as_secs_f64();
                if let Some(k) = k {
                    self.cars[k].count_frames(t, r.frames);
                }
            }
            (Purpose::Status | Purpose::Camera, _) => {}
            (Purpose::Stop { .. }, _) => {}
            (
                Purpose::Restart { phase },
                Reply::GroupStarted | Reply::ManeuverStarted(_) | Reply::ProgramStarted,
            ) if self.current(phase) => {
                if let Some(k) = k {
                    self.cars[k].started_at = Some(self.world.now());
                }
            }
            (
                Purpose::Start { phase },
                Reply::GroupStarted | Reply::ManeuverStarted(_) | Reply::ProgramStarted,
            ) if self.current(phase) => {
                if let Some(k) = k {
                    self.cars[k].started_at = Some(self.world.now());
                }
                self.log.push(
                    self.world.now(),
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
            (_, Reply::Refused(r @ (Refusal::UnknownLaw | Refusal::NoProgram))) => {
                self.fatal = Some(ExperimentError::ManeuverRefused {
                    id: cmd.car,
                    reply: match r {
                        Refusal::UnknownLaw => "UnknownLaw (the car's firmware was built \
                            without this law: rebuild it)"
                            .to_owned(),
                        _ => "NoProgram (the car runs firmware without a program loop: give \
                            it `firmware = \"NAME\"` in [[cars]])"
                            .to_owned(),
                    },
                });
            }
            (_, other) => self.failed(cmd, &format!("{other:?}")),
        }
    }

    /// A request got no (useful) answer: retry maneuver commands a few times.
    pub(super) fn failed(&mut self, mut cmd: Command, why: &str) {
        match cmd.purpose {
            Purpose::Status | Purpose::Camera => {}
            Purpose::Start { phase }
            | Purpose::Stop { phase }
            | Purpose::Restart { phase }
            | Purpose::Waypoint { phase, .. } => {
                if !self.current(phase) {
                    return;
                }
                self.log.push(
            self.world.now(),
                    Some(cmd.car),
                    "request-failed",
                    json!({ "request": format!("{:?}", cmd.req.tag()), "why": why, "attempt": cmd.attempts }),
                );
                let Some(a) = self.active.as_mut() else {
                    return;
                };
                if cmd.attempts < COMMAND_ATTEMPTS {
                    a.command_retries += 1;
                    cmd.not_before = self.world.now() + Duration::from_millis(300);
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

    /// Waypoints of a formation (to its leader) or of a law phase (to its waypoint cars): the
    /// next one once the first of them reached the previous one (or at its time).
    pub(super) fn waypoints(&mut self, now: &[Sample]) {
        let Some(a) = &self.active else { return };
        let index = a.index;
        let phase = &self.exp.phases[index];
        let Some(plan) = phase.waypoint_plan() else {
            return;
        };
        let next = a.next_waypoint;
        let (Some(&[x, y]), Some(&first)) = (plan.waypoints.get(next), plan.cars.first()) else {
            return;
        };
        let started = self
            .car_index(first)
            .is_some_and(|k| self.cars[k].started_at.is_some());
        if !started {
            return;
        }
        let due = match plan.at_s {
            Some(at) => (self.world.now() - a.start).as_secs_f64() >= at[next],
            None => {
                next == 0 || {
                    // Reached the previous waypoint (acknowledged before).
                    let Some(k) = self.car_index(first) else {
                        return;
                    };
                    a.waypoint_acked >= next
                        && distance_to(&now[k], plan.waypoints[next - 1])
                            <= f64::from(plan.reach_units) * MM_PER_UNIT
                }
            }
        };
        if !due {
            return;
        }
        let cars = plan.cars.to_vec();
        if next > 0 && plan.at_s.is_none() {
            self.log.push(
                self.world.now(),
                Some(first),
                "waypoint-reached",
                json!({ "phase": index + 1, "index": next - 1 }),
            );
        }
        self.log.push(
            self.world.now(),
            Some(first),
            "waypoint-sent",
            json!({ "phase": index + 1, "index": next, "x": x, "y": y }),
        );
        if let Some(a) = self.active.as_mut() {
            a.next_waypoint = next + 1;
        }
        for car in cars {
            self.enqueue(
                car,
                Request::GroupWaypoint { x, y },
                Purpose::Waypoint {
                    phase: index,
                    index: next,
                },
            );
        }
    }

    /// The progress line now.
    pub(super) fn progress(&self, next_phase: usize, failed: &[CarFailure]) -> Progress {
        let truth = self.world.truth();
        let (phase, kind, error_mm) = match &self.active {
            Some(a) => (
                a.index + 1,
                self.exp.phases[a.index].kind.name(),
                a.errors.last().map(|&(_, e)| e),
            ),
            None if next_phase < self.exp.phases.len() => (next_phase, "waiting", None),
            None => (self.exp.phases.len(), "done", None),
        };
        Progress {
            t: self.t(),
            phase,
            phases: self.exp.phases.len(),
            kind,
            error_mm,
            cars: truth
                .iter()
                .zip(&self.cars)
                .map(|(tr, c)| CarProgress::new(tr, c.status))
                .collect(),
            failed: failed.to_vec(),
        }
    }
}
