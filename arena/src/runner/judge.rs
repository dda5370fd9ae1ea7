//! Judging a phase from the cars' true poses: its error, whether its completion test holds,
//! and its result when it ends.

use super::control::{Active, Runner};
use super::*;

/// Slot offsets of a formation's followers, mm (forward, left), by car index.
pub(super) fn slot_offsets(f: &FormationPhase, ids: &[u8]) -> Vec<Option<(f64, f64)>> {
    let law = Formation::with(f.shape, f.leader, None, f.spacing_units, f.speed_mm_s);
    ids.iter()
        .map(|id| {
            f.followers.iter().position(|c| c == id).map(|k| {
                // In 1/16 tracking unit (`maneuvers::fixed`).
                let o = law.slot_offset(u8::try_from(k).unwrap_or(u8::MAX));
                let mm = |v: i32| f64::from(v) / f64::from(maneuvers::fixed::ONE) * MM_PER_UNIT;
                (mm(o.x), mm(o.y))
            })
        })
        .collect()
}

/// The phase error at one instant (mm), from every car's true pose (`now[k]` = car `ids[k]`);
/// `None` for the kinds judged by the cars' own reports (other laws, programs).
pub(super) fn phase_error(phase: &Phase, ids: &[u8], now: &[Sample]) -> Option<f64> {
    match &phase.kind {
        PhaseKind::Law(_) | PhaseKind::Program(_) => None,
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

pub(super) fn waypoint_mm(w: [u16; 2]) -> (f64, f64) {
    (f64::from(w[0]) * MM_PER_UNIT, f64::from(w[1]) * MM_PER_UNIT)
}

/// Distance of a car's true pose from point `w` (tracking units), mm.
pub(super) fn distance_to(s: &Sample, w: [u16; 2]) -> f64 {
    let (x, y) = waypoint_mm(w);
    (s.x_mm - x).hypot(s.y_mm - y)
}

impl Runner<'_> {
    /// Whether the active phase's completion test holds now.
    pub(super) fn complete_now(
        &self,
        phase: &Phase,
        a: &Active,
        now: &[Sample],
        err: Option<f64>,
    ) -> bool {
        if a.started_s.is_none() {
            return false;
        }
        match &phase.kind {
            PhaseKind::Goto { .. } => self
                .ids
                .iter()
                .enumerate()
                .all(|(k, &id)| phase.goto_points(id).is_empty() || !self.cars[k].goto_running),
            PhaseKind::Formation(_) => {
                self.waypoints_done(phase, a, now) && err.is_some_and(|e| e <= phase.tolerance_mm)
            }
            PhaseKind::Law(_) => {
                self.waypoints_done(phase, a, now)
                    && self.all_reported_converged(phase)
                    && err.is_some_and(|e| e <= phase.tolerance_mm)
            }
            PhaseKind::Program(_) => self
                .ids
                .iter()
                .enumerate()
                .all(|(k, &id)| !phase.runs_program(id) || !self.cars[k].goto_running),
            PhaseKind::Rendezvous { .. } => {
                err.is_some_and(|e| e <= phase.tolerance_mm)
                    && now.iter().all(|s| s.v_mm_s.abs() < RENDEZVOUS_STILL_MM_S)
            }
            PhaseKind::Circle { .. } => err.is_some_and(|e| e <= phase.tolerance_mm),
        }
    }

    /// Every waypoint of the phase was sent and taken, and the first waypoint car is within
    /// the reach distance of the last (true without waypoints).
    fn waypoints_done(&self, phase: &Phase, a: &Active, now: &[Sample]) -> bool {
        let Some(plan) = phase.waypoint_plan() else {
            return true;
        };
        match (plan.waypoints.last(), plan.cars.first()) {
            (Some(&last), Some(&car)) => {
                a.waypoint_acked == plan.waypoints.len()
                    && self.car_index(car).is_some_and(|k| {
                        distance_to(&now[k], last) <= f64::from(plan.reach_units) * MM_PER_UNIT
                    })
            }
            _ => true,
        }
    }

    /// Every car of a group phase reported its law converged in a status asked after its
    /// start was acknowledged.
    fn all_reported_converged(&self, phase: &Phase) -> bool {
        self.ids.iter().enumerate().all(|(k, &id)| {
            let c = &self.cars[k];
            if phase.params_for(id).is_none() {
                return true;
            }
            match (c.status, c.status_sent, c.started_at) {
                (Some(s), Some(sent), Some(started)) => sent >= started && s.group_converged,
                _ => false,
            }
        })
    }

    /// The largest error the cars of a law phase report (mm), from statuses asked after
    /// their starts were acknowledged; `None` until every car reported one.
    fn reported_error(&self, phase: &Phase) -> Option<f64> {
        let mut worst: Option<f64> = None;
        for (k, &id) in self.ids.iter().enumerate() {
            if phase.params_for(id).is_none() {
                continue;
            }
            let c = &self.cars[k];
            match (c.status, c.status_sent, c.started_at) {
                (Some(s), Some(sent), Some(started)) if sent >= started => {
                    let e = f64::from(s.group_error_units) * MM_PER_UNIT;
                    worst = Some(worst.map_or(e, |w| w.max(e)));
                }
                _ => return None,
            }
        }
        worst
    }

    /// Records one sample of the active phase; answers whether it is over (completed or
    /// timed out).
    pub(super) fn judge(&mut self, t: f64, now: &[Sample]) -> Option<bool> {
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
                    self.log.push(
                        self.world.now(),
                        Some(self.ids[k]),
                        "maneuver-finished",
                        json!({}),
                    );
                }
            }
        }
        let a = self.active.as_ref()?;
        let phase = &self.exp.phases[a.index];
        let err = match phase.kind {
            PhaseKind::Law(_) => self.reported_error(phase),
            _ => phase_error(phase, &self.ids, now),
        };
        let complete = self.complete_now(phase, a, now, err);
        // The cars' own convergence reports, from statuses asked after the start was
        // acknowledged.
        let reported = self.all_reported_converged(phase);
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
                } | PhaseKind::Program(_)
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
        // A law that never says it has converged (the camera follow) completes when its time
        // is up.
        let open_ended = matches!(&phase.kind, PhaseKind::Law(l) if !l.law.converges);
        timed_out.then_some(open_ended)
    }

    /// Closes the active phase; `now` is the latest sample of every car.
    pub(super) fn end_phase(&mut self, t: f64, now: &[Sample], completed: bool, timed_out: bool) {
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
            self.world.now(),
            None,
            event,
            json!({ "phase": a.index + 1, "converged_s": converged_s }),
        );
        let waypoints_sent = a.next_waypoint;
        // Times to the run loop's 10 ms, distances to 0.1 mm.
        let s = |v: f64| round_to(v, 2);
        let mm = |v: f64| round_to(v, 1);
        self.results.push(PhaseResult {
            phase: a.index + 1,
            kind: phase.kind.name(),
            start_s: s(a.start_s),
            end_s: s(t),
            completed,
            timed_out,
            started_s: a.started_s.map(s),
            converged_s: converged_s.map(s),
            settled_s: a.settled_s.map(s),
            tolerance_mm: mm(phase.tolerance_mm),
            error_after_settled: metrics::error_stats(&after).map(|e| ErrorStats {
                max_mm: mm(e.max_mm),
                mean_mm: mm(e.mean_mm),
                p95_mm: mm(e.p95_mm),
                samples: e.samples,
            }),
            final_error_mm: a.errors.last().map(|&(_, e)| mm(e)),
            reported_converged_s: a.reported_converged_s.map(s),
            waypoints_sent,
            command_retries: a.command_retries,
            command_failures: a.command_failures,
            error_series: series,
        });
        // Go-to maneuvers and programs of an ended phase that did not finish count as missed.
        if matches!(phase.kind, PhaseKind::Goto { .. } | PhaseKind::Program(_)) {
            for c in &mut self.cars {
                if c.goto_running {
                    c.goto_running = false;
                    c.goto_missed = true;
                }
            }
        }
    }
}
