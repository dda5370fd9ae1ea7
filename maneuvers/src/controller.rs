//! The per-period entry point: selects the law, applies avoidance, produces the LBC command.

use heapless::Vec;

use crate::drive::{Drive, DriveConfig, Sv, STEER_LIMIT};
use crate::fmath::{cos, round};
use crate::geom::{clampf, mrad_to_rad, Vec2};
use crate::safety::{field, gate, Conflict, Obstacle, SafetyConfig};
use crate::{
    Circle, Command, Formation, GoTo, Guidance, Inputs, Maneuver, ManeuverParams, Me, Neighbour,
    Output, Phase, Plan, Rendezvous, Status, MM_PER_UNIT, STEER_LIMIT_MRAD,
};

/// Neighbours considered per period; more are ignored (16 cars share the radio schedule).
pub const MAX_NEIGHBOURS: usize = 16;
/// Slow-down gain towards a [`Guidance::Point`], 1/s.
const POINT_GAIN: f32 = 1.0;
/// How long a reverse manoeuvre chosen by the avoidance is kept, control periods (0.5 s).
const ESCAPE_PERIODS: u8 = 15;
/// Weight of the heading improvement against the distance gained when a refused command is
/// replaced, tracking units per unit of cosine.
const ALIGN_WEIGHT_UNITS: f32 = 60.0;
/// A car that wants to move but makes no progress for this long is stuck, us.
const STUCK_US: u64 = 3_000_000;
/// Drop of the law's error that counts as progress, tracking units (20 mm).
const STUCK_PROGRESS_UNITS: f32 = 8.0;
/// LBC limit on `MOVE_SV` velocity, mm/s.
const MAX_SV_MM_S: f32 = 2000.0;

/// Controller configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[non_exhaustive]
pub struct ControllerConfig {
    /// Avoidance.
    pub safety: SafetyConfig,
    /// Velocity tracker.
    pub drive: DriveConfig,
    /// Hand fixed goals to the LBC's own path generator (`MOVE_XY`) while no avoidance is
    /// needed, instead of steering them with `MOVE_SV`.
    pub use_move_xy: bool,
}

/// The active law.
#[derive(Debug, Clone, PartialEq)]
enum Active {
    Idle,
    /// Stand still (the law is carried out outside the controller, e.g. camera follow).
    Hold,
    Formation(Formation),
    Rendezvous(Rendezvous),
    Circle(Circle),
    GoTo(GoTo),
}

/// What the deadlock breaker watches.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Progress {
    /// Smallest law error since `since_us`.
    best: f32,
    since_us: u64,
    /// Periods since `since_us`, and how many of them the avoidance changed.
    periods: u16,
    avoided: u16,
    /// Escapes so far (picks the side).
    tries: u8,
}

impl Default for Progress {
    fn default() -> Self {
        Self {
            best: f32::MAX,
            since_us: 0,
            periods: 0,
            avoided: 0,
            tries: 0,
        }
    }
}

/// Runs one maneuver for one car.
#[derive(Debug, Clone)]
pub struct Controller {
    cfg: ControllerConfig,
    active: Active,
    drive: Drive,
    /// A committed reverse manoeuvre: periods left and its command.
    escape: Option<(u8, Sv)>,
    /// Progress watch of the deadlock breaker.
    progress: Progress,
}

impl Controller {
    /// An idle controller.
    pub fn new(cfg: ControllerConfig) -> Self {
        Self {
            cfg,
            active: Active::Idle,
            drive: Drive::default(),
            escape: None,
            progress: Progress::default(),
        }
    }

    /// Switch to the maneuver described by `params` (from the radio or the application).
    pub fn start(&mut self, params: ManeuverParams) {
        self.active = match params {
            ManeuverParams::Idle => Active::Idle,
            ManeuverParams::Formation {
                shape,
                leader,
                slot,
                spacing_units,
                speed_mm_s,
            } => Active::Formation(Formation::new(
                shape,
                leader,
                slot,
                spacing_units,
                speed_mm_s,
            )),
            ManeuverParams::Rendezvous {
                radius_units,
                speed_mm_s,
            } => Active::Rendezvous(Rendezvous::new(radius_units, speed_mm_s)),
            ManeuverParams::Circle {
                cx,
                cy,
                radius_units,
                speed_mm_s,
            } => Active::Circle(Circle::new(cx, cy, radius_units, speed_mm_s)),
            ManeuverParams::GoTo { x, y, speed_mm_s } => {
                let (x, y) = self.clamp(x, y);
                Active::GoTo(GoTo::new(x, y, speed_mm_s))
            }
            ManeuverParams::CameraFollow { .. } => Active::Hold,
        };
        self.drive = Drive::default();
        self.escape = None;
        self.progress = Progress::default();
    }

    /// Stop the maneuver.
    pub fn stop(&mut self) {
        self.start(ManeuverParams::Idle);
    }

    /// A goal moved inside the walls (see [`SafetyConfig::clamp_goal`]).
    fn clamp(&self, x: u16, y: u16) -> (u16, u16) {
        let p = self
            .cfg
            .safety
            .clamp_goal(Vec2::new(f32::from(x), f32::from(y)));
        // Clamped inside the arena: the casts are exact.
        (round(p.x) as u16, round(p.y) as u16)
    }

    /// Next waypoint of a formation leader (ignored by other laws and by followers); moved
    /// inside the walls like every goal.
    pub fn set_waypoint(&mut self, x: u16, y: u16) {
        let (x, y) = self.clamp(x, y);
        if let Active::Formation(f) = &mut self.active {
            f.set_waypoint(x, y);
        }
    }

    /// One control period.
    pub fn step(&mut self, inputs: &Inputs<'_>) -> Output {
        let me = Me {
            id: inputs.id,
            pos: Vec2::new(f32::from(inputs.own.x), f32::from(inputs.own.y)),
            heading: mrad_to_rad(inputs.own.heading_mrad),
            speed: f32::from(inputs.own.velocity_mm_s),
        };
        let mut fresh: Vec<Neighbour, MAX_NEIGHBOURS> = Vec::new();
        let mut obstacles: Vec<Obstacle, MAX_NEIGHBOURS> = Vec::new();
        for n in inputs.neighbours {
            if n.id != inputs.id && n.age_us <= self.cfg.safety.stale_after_us {
                // Full: the rest are ignored, as documented on MAX_NEIGHBOURS.
                if fresh.push(*n).is_ok() {
                    let _ = obstacles.push(self.cfg.safety.obstacle(n));
                }
            }
        }
        let plan = match &mut self.active {
            Active::Idle => Plan {
                guidance: Guidance::Hold,
                phase: Phase::Idle,
                converged: false,
                error_units: 0.0,
            },
            Active::Hold => Plan {
                guidance: Guidance::Hold,
                phase: Phase::Hold,
                converged: false,
                error_units: 0.0,
            },
            Active::Formation(m) => m.plan(&me, &fresh),
            Active::Rendezvous(m) => m.plan(&me, &fresh),
            Active::Circle(m) => m.plan(&me, &fresh),
            Active::GoTo(m) => m.plan(&me, &fresh),
        };
        let (command, avoided) = self.command(&me, &obstacles, &plan, inputs.now_us);
        let p = &mut self.progress;
        p.periods = p.periods.saturating_add(1);
        p.avoided = p.avoided.saturating_add(u16::from(avoided));
        Output {
            command,
            status: Status {
                phase: if avoided { Phase::Avoid } else { plan.phase },
                converged: plan.converged,
                error_units: clampf(plan.error_units, 0.0, f32::from(u16::MAX)) as u16,
            },
        }
    }

    /// The command for `plan`, and whether avoidance changed it.
    /// Deadlock breaker: a car whose law asks it to move, whose commands the avoidance has
    /// changed in at least a quarter of the periods, and whose error has not dropped by
    /// [`STUCK_PROGRESS_UNITS`] for [`STUCK_US`] backs out on a curve for a second, turning to
    /// alternate sides on successive attempts (starting by the parity of its ID, so that two
    /// stuck cars do not mirror each other).
    fn watch_progress(
        &mut self,
        me: &Me,
        fresh: &[Obstacle],
        plan: &Plan,
        desired: Vec2,
        now_us: u64,
    ) {
        let p = &mut self.progress;
        let idle = desired.norm() < self.cfg.drive.creep_mm_s || self.escape.is_some();
        if idle || plan.error_units < p.best - STUCK_PROGRESS_UNITS {
            *p = Progress {
                best: plan.error_units,
                since_us: now_us,
                periods: 0,
                avoided: 0,
                ..*p
            };
            return;
        }
        if now_us.saturating_sub(p.since_us) < STUCK_US || 4 * p.avoided < p.periods {
            return;
        }
        let tries = p.tries;
        *p = Progress {
            best: plan.error_units,
            since_us: now_us,
            periods: 0,
            avoided: 0,
            tries: tries.wrapping_add(1),
        };
        let side = if (me.id ^ tries).is_multiple_of(2) {
            1.0
        } else {
            -1.0
        };
        let creep = self.cfg.drive.creep_mm_s;
        let options = [
            Sv {
                steering: side * STEER_LIMIT,
                velocity: -creep,
            },
            Sv {
                steering: -side * STEER_LIMIT,
                velocity: -creep,
            },
            Sv {
                steering: side * STEER_LIMIT,
                velocity: creep,
            },
            Sv {
                steering: -side * STEER_LIMIT,
                velocity: creep,
            },
        ];
        if let Some(c) = options
            .into_iter()
            .find(|c| gate(&self.cfg.safety, me, fresh, *c).is_ok())
        {
            self.escape = Some((2 * ESCAPE_PERIODS, c));
        }
    }

    fn command(
        &mut self,
        me: &Me,
        fresh: &[Obstacle],
        plan: &Plan,
        now_us: u64,
    ) -> (Command, bool) {
        let cfg = self.cfg;
        let safety = &cfg.safety;
        let (desired, holding) = match plan.guidance {
            Guidance::Hold => (Vec2::ZERO, true),
            Guidance::Velocity(v) => (v, false),
            Guidance::Point { at, speed_mm_s } => {
                let at = safety.clamp_goal(at);
                let err = at - me.pos;
                let speed = speed_mm_s.min(err.norm() * POINT_GAIN * MM_PER_UNIT);
                (err.unit() * speed, false)
            }
        };
        let v = field(safety, me, fresh, desired, holding);
        let pushed = (v - desired).norm() > 0.2 * desired.norm().max(50.0);
        if holding && !pushed {
            return (Command::Stop, false);
        }
        self.watch_progress(me, fresh, plan, desired, now_us);
        if let Some((left, c)) = self.escape.take() {
            if left > 0 && gate(safety, me, fresh, c).is_ok() {
                self.escape = Some((left - 1, c));
                return (to_command(c), true);
            }
        }
        let sv = self.drive.track(&self.cfg.drive, me.heading, v);
        if sv == Sv::default() {
            return (Command::Stop, pushed);
        }
        let refused = gate(safety, me, fresh, sv);
        if refused.is_ok() {
            if let (Guidance::Point { at, .. }, true, false) =
                (plan.guidance, self.cfg.use_move_xy, pushed)
            {
                let at = safety.clamp_goal(at);
                // The clamp keeps both inside the arena, so the casts are exact.
                return (
                    Command::MoveXy {
                        x: round(at.x) as u16,
                        y: round(at.y) as u16,
                    },
                    false,
                );
            }
            return (to_command(sv), pushed);
        }
        // Refused: the alternative that is safe and goes furthest in the desired direction.
        let speed = sv.velocity.abs().max(self.cfg.drive.creep_mm_s);
        let reverse = speed.min(self.cfg.drive.max_reverse_mm_s);
        let candidates = [
            Sv {
                steering: STEER_LIMIT,
                velocity: speed,
            },
            Sv {
                steering: -STEER_LIMIT,
                velocity: speed,
            },
            Sv {
                steering: 0.0,
                velocity: -reverse,
            },
            Sv {
                steering: STEER_LIMIT,
                velocity: -reverse,
            },
            Sv {
                steering: -STEER_LIMIT,
                velocity: -reverse,
            },
        ];
        // Without a way forward, priority goes to the lower ID: a car blocked by a lower-ID car
        // makes room (the safe move that most increases the distance to it, kept for a while);
        // the lower-ID car, or a car blocked by a wall, holds still. One pass over the
        // candidates scores both.
        let yield_to = match refused {
            Err(Conflict::Car(id)) if id < me.id => fresh.iter().find(|n| n.id == id),
            _ => None,
        };
        let other = yield_to.map(|o| {
            let nb = o.at(safety.horizon_s);
            (nb, (nb - safety.body(me.pos, me.heading)).norm())
        });
        let psi = v.angle();
        let align_now = cos(psi - me.heading);
        let mut best: Option<(f32, Sv)> = None;
        let mut room: Option<(f32, Sv)> = None;
        for c in candidates {
            if gate(safety, me, fresh, c).is_err() {
                continue;
            }
            let (p, h) = crate::drive::predict(me.pos, me.heading, c, safety.horizon_s);
            let score =
                (p - me.pos).dot(v.unit()) + ALIGN_WEIGHT_UNITS * (cos(psi - h) - align_now);
            if score > 0.0 && best.is_none_or(|(s, _)| score > s) {
                best = Some((score, c));
            }
            if let Some((nb, d0)) = other {
                let gain = (nb - safety.body(p, h)).norm() - d0;
                if gain > 0.5 && room.is_none_or(|(g, _)| gain > g) {
                    room = Some((gain, c));
                }
            }
        }
        if let Some((_, c)) = best {
            if c.velocity < 0.0 {
                // Back out for a while (the first leg of a three-point turn) instead of
                // alternating with the refused forward command every period.
                self.escape = Some((ESCAPE_PERIODS, c));
            }
            return (to_command(c), true);
        }
        if let Some((_, c)) = room {
            self.escape = Some((ESCAPE_PERIODS, c));
            return (to_command(c), true);
        }
        (Command::Stop, true)
    }
}

/// Rounded and clamped to what the LBC accepts.
fn to_command(sv: Sv) -> Command {
    let lim = f32::from(STEER_LIMIT_MRAD);
    Command::MoveSv {
        // Both clamped into i16 range first, so the casts are exact.
        steering_mrad: round(clampf(sv.steering * 1000.0, -lim, lim)) as i16,
        velocity_mm_s: round(clampf(sv.velocity, -MAX_SV_MM_S, MAX_SV_MM_S)) as i16,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{CarPose, Shape};

    fn inputs<'a>(own: CarPose, neighbours: &'a [Neighbour]) -> Inputs<'a> {
        Inputs {
            now_us: 0,
            id: 2,
            own,
            neighbours,
        }
    }

    fn pose(x: u16, y: u16, heading_mrad: u16) -> CarPose {
        CarPose {
            x,
            y,
            heading_mrad,
            velocity_mm_s: 0,
        }
    }

    #[test]
    fn idle_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        let out = c.step(&inputs(pose(300, 400, 0), &[]));
        assert_eq!(out.command, Command::Stop);
        assert_eq!(out.status.phase, Phase::Idle);
    }

    #[test]
    fn camera_follow_holds() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::CameraFollow {
            marker: 1,
            distance_units: 80,
            speed_mm_s: 200,
        });
        let out = c.step(&inputs(pose(300, 400, 0), &[]));
        assert_eq!(out.command, Command::Stop);
        assert_eq!(out.status.phase, Phase::Hold);
    }

    #[test]
    fn goto_drives_then_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::GoTo {
            x: 300,
            y: 600,
            speed_mm_s: 250,
        });
        let out = c.step(&inputs(pose(300, 400, 1571), &[]));
        assert_eq!(
            out.command,
            Command::MoveSv {
                steering_mrad: 0,
                velocity_mm_s: 250
            }
        );
        assert_eq!(out.status.phase, Phase::Approach);
        assert_eq!(out.status.error_units, 200);
        let out = c.step(&inputs(pose(300, 597, 1571), &[]));
        assert_eq!(out.command, Command::Stop);
        assert!(out.status.converged);
    }

    #[test]
    fn goto_uses_move_xy_when_asked() {
        let cfg = ControllerConfig {
            use_move_xy: true,
            ..ControllerConfig::default()
        };
        let mut c = Controller::new(cfg);
        // A target beyond the wall is clamped into the keep-in area.
        c.start(ManeuverParams::GoTo {
            x: 300,
            y: 1000,
            speed_mm_s: 250,
        });
        let out = c.step(&inputs(pose(300, 400, 1571), &[]));
        assert_eq!(out.command, Command::MoveXy { x: 300, y: 742 });
    }

    #[test]
    fn blocked_car_avoids_or_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::GoTo {
            x: 300,
            y: 700,
            speed_mm_s: 300,
        });
        // A lower-ID car stands right in front.
        let n = [Neighbour {
            id: 1,
            pose: pose(300, 465, 1571),
            age_us: 0,
        }];
        let out = c.step(&inputs(pose(300, 400, 1571), &n));
        assert_eq!(out.status.phase, Phase::Avoid);
        match out.command {
            Command::Stop => {}
            Command::MoveSv { velocity_mm_s, .. } => assert!(velocity_mm_s < 100),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn stale_neighbours_are_ignored() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::GoTo {
            x: 300,
            y: 700,
            speed_mm_s: 300,
        });
        let n = [Neighbour {
            id: 1,
            pose: pose(300, 465, 1571),
            age_us: 600_000,
        }];
        let out = c.step(&inputs(pose(300, 400, 1571), &n));
        assert_eq!(out.status.phase, Phase::Approach);
    }

    #[test]
    fn follower_without_leader_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::Formation {
            shape: Shape::Line,
            leader: 1,
            slot: None,
            spacing_units: 60,
            speed_mm_s: 100,
        });
        let out = c.step(&inputs(pose(300, 400, 0), &[]));
        assert_eq!(out.command, Command::Stop);
        assert_eq!(out.status.phase, Phase::NoReference);
    }

    #[test]
    fn commands_stay_within_lbc_limits() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(ManeuverParams::Rendezvous {
            radius_units: 10,
            speed_mm_s: 2047,
        });
        let n = [Neighbour {
            id: 1,
            pose: pose(600, 0, 0),
            age_us: 0,
        }];
        for h in (0..6283).step_by(300) {
            if let Command::MoveSv {
                steering_mrad,
                velocity_mm_s,
            } = c.step(&inputs(pose(0, 960, h), &n)).command
            {
                assert!(steering_mrad.abs() <= 523);
                assert!(velocity_mm_s.abs() <= 2000);
            }
        }
    }
}
