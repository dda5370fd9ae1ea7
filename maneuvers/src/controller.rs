//! The per-period entry point: runs the law a group command names, applies avoidance,
//! produces the LBC command.

use heapless::Vec;

use crate::drive::{predict, Drive, DriveConfig, Sv, STEER_LIMIT};
use crate::fixed::{fx, fx_from_f32, mul_shift, sin_cos, IVec2};
use crate::law::{GoalArea, Guidance, LawInput, LawOptions, Neighbours, Plan, Waypoint};
use crate::laws::AnyLaw;
use crate::safety::{field, gate, Conflict, Ego, Obstacle, SafetyConfig};
use crate::{Command, Inputs, ManeuverParams, Neighbour, Output, Phase, Status};

/// Neighbours considered per period; more are ignored (16 cars share the radio schedule).
pub const MAX_NEIGHBOURS: usize = 16;
/// How long a reverse manoeuvre chosen by the avoidance is kept, control periods (0.5 s).
const ESCAPE_PERIODS: u8 = 15;
/// Weight of the heading improvement against the distance gained when a refused command is
/// replaced, tracking units per unit of cosine.
const ALIGN_WEIGHT_UNITS: i32 = 60;
/// A car that wants to move but makes no progress for this long is stuck, us.
const STUCK_US: u64 = 3_000_000;
/// Drop of the law's error that counts as progress, tracking units (20 mm).
const STUCK_PROGRESS_UNITS: u16 = 8;
/// LBC limit on `MOVE_SV` velocity, mm/s.
const MAX_SV_MM_S: i16 = 2000;

/// Controller configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
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

/// What the deadlock breaker watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Progress {
    /// Smallest law error since `since_us`, tracking units.
    best: u16,
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
            best: u16::MAX,
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
    /// Where goals may lie (from the safety configuration).
    area: GoalArea,
    /// The running law (`None`: idle).
    law: Option<AnyLaw>,
    /// Its options in force.
    options: LawOptions,
    /// The latest waypoint, and how many were given since the law started.
    waypoint: Option<Waypoint>,
    waypoints: u16,
    drive: Drive,
    /// A committed reverse manoeuvre: periods left and its command.
    escape: Option<(u8, Sv)>,
    /// Progress watch of the deadlock breaker.
    progress: Progress,
}

impl Controller {
    /// An idle controller.
    pub fn new(cfg: ControllerConfig) -> Self {
        let (x_min, y_min) = cfg.safety.clamp_goal(0, 0);
        let (x_max, y_max) = cfg.safety.clamp_goal(u16::MAX, u16::MAX);
        Self {
            cfg,
            area: GoalArea {
                x_min,
                x_max,
                y_min,
                y_max,
            },
            law: None,
            options: LawOptions::DEFAULT,
            waypoint: None,
            waypoints: 0,
            drive: Drive::default(),
            escape: None,
            progress: Progress::default(),
        }
    }

    /// Switches to the maneuver described by `params` (from the radio or the application);
    /// [`ManeuverParams::IDLE`] stops. (`ManeuverParams` only holds registered laws.)
    pub fn start(&mut self, params: ManeuverParams) {
        self.law = None;
        self.options = params.options().unwrap_or_default();
        self.waypoint = None;
        self.waypoints = 0;
        self.drive = Drive::default();
        self.escape = None;
        self.progress = Progress::default();
        self.law = AnyLaw::new(params.law(), params.values());
    }

    /// Stops the maneuver.
    pub fn stop(&mut self) {
        self.start(ManeuverParams::IDLE);
    }

    /// The running law, if any.
    pub fn law(&self) -> Option<&AnyLaw> {
        self.law.as_ref()
    }

    /// The options in force.
    pub fn options(&self) -> LawOptions {
        self.options
    }

    /// Where goals may lie: inside the walls by the margins of [`SafetyConfig::clamp_goal`].
    pub fn area(&self) -> GoalArea {
        self.area
    }

    /// Gives the running law a waypoint (moved inside the walls like every goal); `false`
    /// while idle.
    pub fn set_waypoint(&mut self, x: u16, y: u16) -> bool {
        if self.law.is_none() {
            return false;
        }
        let (x, y) = self.area.clamp(x, y);
        self.waypoint = Some(Waypoint {
            x,
            y,
            index: self.waypoints,
        });
        self.waypoints = self.waypoints.wrapping_add(1);
        true
    }

    /// One control period.
    pub fn step(&mut self, inputs: &Inputs<'_>) -> Output {
        let me = Ego::new(inputs.id, &inputs.own);
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
        let nearest;
        let selected: &[Neighbour] = match self.options.neighbours {
            Neighbours::All => &fresh,
            Neighbours::None => &[],
            Neighbours::Nearest(k) => {
                nearest = nearest_of(&fresh, inputs.own.x, inputs.own.y, k);
                &nearest
            }
        };
        let area = self.area;
        let plan = match &mut self.law {
            None => Plan::hold(Phase::Idle, false, 0),
            Some(law) => law.step(&LawInput {
                now_us: inputs.now_us,
                id: inputs.id,
                own: inputs.own,
                neighbours: selected,
                waypoint: self.waypoint,
                options: self.options,
                area,
            }),
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
                error_units: plan.error_units,
            },
        }
    }

    /// Deadlock breaker: a car whose law asks it to move, whose commands the avoidance has
    /// changed in at least a quarter of the periods, and whose error has not dropped by
    /// [`STUCK_PROGRESS_UNITS`] for [`STUCK_US`] backs out on a curve for a second, turning to
    /// alternate sides on successive attempts (starting by the parity of its ID, so that two
    /// stuck cars do not mirror each other).
    fn watch_progress(
        &mut self,
        me: &Ego,
        fresh: &[Obstacle],
        plan: &Plan,
        desired: IVec2,
        now_us: u64,
    ) {
        let p = &mut self.progress;
        let error = plan.error_units;
        let creep = fx(i32::from(self.cfg.drive.creep_mm_s));
        let idle = desired.len2() < (creep as u64).pow(2) || self.escape.is_some();
        if idle || error < p.best.saturating_sub(STUCK_PROGRESS_UNITS) {
            *p = Progress {
                best: error,
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
            best: error,
            since_us: now_us,
            periods: 0,
            avoided: 0,
            tries: tries.wrapping_add(1),
        };
        let side = if (me.id ^ tries).is_multiple_of(2) {
            STEER_LIMIT
        } else {
            -STEER_LIMIT
        };
        let creep = self.cfg.drive.creep_mm_s;
        let options = [
            sv(side, -creep),
            sv(-side, -creep),
            sv(side, creep),
            sv(-side, creep),
        ];
        if let Some(c) = options
            .into_iter()
            .find(|c| gate(&self.cfg.safety, me, fresh, *c).is_ok())
        {
            self.escape = Some((2 * ESCAPE_PERIODS, c));
        }
    }

    /// The command for `plan`, and whether avoidance changed it.
    fn command(
        &mut self,
        me: &Ego,
        fresh: &[Obstacle],
        plan: &Plan,
        now_us: u64,
    ) -> (Command, bool) {
        let cfg = self.cfg;
        let safety = &cfg.safety;
        // The goal of a point, moved into the goal area.
        let mut goal = None;
        let (desired, holding) = match plan.guidance {
            Guidance::Hold => (IVec2::ZERO, true),
            Guidance::VelocityF(v) => (IVec2::new(fx_from_f32(v.x), fx_from_f32(v.y)), false),
            Guidance::Velocity { vx_mm_s, vy_mm_s } => (
                IVec2::from_units(i32::from(vx_mm_s), i32::from(vy_mm_s)),
                false,
            ),
            Guidance::Point { x, y, speed_mm_s } => {
                let (x, y) = safety.clamp_goal(x, y);
                goal = Some((x, y));
                let err = IVec2::from_units(i32::from(x), i32::from(y)) - me.pos;
                // Slowing down at 1/s: 2.5 mm/s per tracking unit of distance.
                let speed = fx(i32::from(speed_mm_s)).min(err.norm() * 5 / 2);
                (err.unit().along(speed), false)
            }
        };
        let v = field(safety, me, fresh, desired, holding);
        // Pushed: the field changed the velocity by more than a fifth of it (at least 10
        // mm/s).
        let pushed = 5 * (v - desired).norm() > desired.norm().max(fx(50));
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
        let cmd = self
            .drive
            .track(&self.cfg.drive, self.options.reverse, me.heading, v);
        if cmd == Sv::default() {
            return (Command::Stop, pushed);
        }
        let refused = gate(safety, me, fresh, cmd);
        if refused.is_ok() {
            if let (Some((x, y)), true, false) = (goal, self.cfg.use_move_xy, pushed) {
                return (Command::MoveXy { x, y }, false);
            }
            return (to_command(cmd), pushed);
        }
        // Refused: the alternative that is safe and goes furthest in the desired direction.
        let speed = cmd.velocity_mm_s.abs().max(self.cfg.drive.creep_mm_s);
        let reverse = speed.min(self.cfg.drive.max_reverse_mm_s);
        let candidates = [
            sv(STEER_LIMIT, speed),
            sv(-STEER_LIMIT, speed),
            sv(0, -reverse),
            sv(STEER_LIMIT, -reverse),
            sv(-STEER_LIMIT, -reverse),
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
            // At the end of the horizon.
            let nb = o.steps[2];
            (nb, (nb - safety.body(me.pos, me.heading)).norm())
        });
        let psi = v.angle();
        let way = v.unit();
        let align_now = sin_cos(psi - me.heading).1;
        let mut best: Option<(i32, Sv)> = None;
        let mut room: Option<(i32, Sv)> = None;
        for c in candidates {
            if gate(safety, me, fresh, c).is_err() {
                continue;
            }
            let (p, h) = predict(me.pos, me.heading, c, safety.horizon_ms);
            // Distance gained along the way plus the heading improvement, 1/16 unit:
            // cosines in Q14 times 60 units.
            let gained = mul_shift((p - me.pos).dot(way), 1, 14);
            let aligned = ((sin_cos(psi - h).1 - align_now) * ALIGN_WEIGHT_UNITS) >> 10;
            let score = gained + aligned;
            if score > 0 && best.is_none_or(|(s, _)| score > s) {
                best = Some((score, c));
            }
            if let Some((nb, d0)) = other {
                let gain = (nb - safety.body(p, h)).norm() - d0;
                // More than half a unit.
                if gain > fx(1) / 2 && room.is_none_or(|(g, _)| gain > g) {
                    room = Some((gain, c));
                }
            }
        }
        if let Some((_, c)) = best {
            if c.velocity_mm_s < 0 {
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

/// A steering (mrad) and velocity (mm/s) command.
const fn sv(steering_mrad: i16, velocity_mm_s: i16) -> Sv {
    Sv {
        steering_mrad,
        velocity_mm_s,
    }
}

/// The `k` nearest of `fresh` to `(x, y)`, nearest first (ties in the order heard).
fn nearest_of(fresh: &[Neighbour], x: u16, y: u16, k: u8) -> Vec<Neighbour, MAX_NEIGHBOURS> {
    let d2 = |n: &Neighbour| {
        let dx = i32::from(n.pose.x) - i32::from(x);
        let dy = i32::from(n.pose.y) - i32::from(y);
        dx * dx + dy * dy
    };
    let mut out: Vec<Neighbour, MAX_NEIGHBOURS> = Vec::new();
    for n in fresh {
        let at = out.iter().position(|o| d2(o) > d2(n)).unwrap_or(out.len());
        // At most MAX_NEIGHBOURS fresh neighbours: never full. Pushed and swapped down to
        // `at` rather than `insert`ed: `insert` shifts with an overlapping copy, which links
        // `memmove` into the firmware.
        if out.push(*n).is_ok() {
            for j in (at + 1..out.len()).rev() {
                out.swap(j - 1, j);
            }
        }
    }
    out.truncate(usize::from(k));
    out
}

/// Clamped to what the LBC accepts.
// Out of line: its two clamps inlined at each of its five uses made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn to_command(c: Sv) -> Command {
    Command::MoveSv {
        steering_mrad: c.steering_mrad.clamp(-STEER_LIMIT, STEER_LIMIT),
        velocity_mm_s: c.velocity_mm_s.clamp(-MAX_SV_MM_S, MAX_SV_MM_S),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        CameraFollow, CarPose, Circle, Formation, GoTo, Overrides, Rendezvous, Reverse, Shape,
    };

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
        c.start(CameraFollow::params(1, 80, 200).unwrap());
        let out = c.step(&inputs(pose(300, 400, 0), &[]));
        assert_eq!(out.command, Command::Stop);
        assert_eq!(out.status.phase, Phase::Hold);
    }

    #[test]
    fn goto_drives_then_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(GoTo::params(300, 600, 250).unwrap());
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
        c.start(GoTo::params(300, 1000, 250).unwrap());
        let out = c.step(&inputs(pose(300, 400, 1571), &[]));
        assert_eq!(out.command, Command::MoveXy { x: 300, y: 742 });
    }

    #[test]
    fn blocked_car_avoids_or_stops() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(GoTo::params(300, 700, 300).unwrap());
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
        c.start(GoTo::params(300, 700, 300).unwrap());
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
        c.start(Formation::params(Shape::Line, 1, None, 60, 100).unwrap());
        let out = c.step(&inputs(pose(300, 400, 0), &[]));
        assert_eq!(out.command, Command::Stop);
        assert_eq!(out.status.phase, Phase::NoReference);
    }

    #[test]
    fn the_goal_area_is_what_clamp_goal_keeps() {
        let c = Controller::new(ControllerConfig::default());
        let a = c.area();
        let safety = SafetyConfig::default();
        let lo = safety.clamp_goal(0, 0);
        let hi = safety.clamp_goal(1000, 1000);
        assert_eq!(
            (a.x_min, a.x_max, a.y_min, a.y_max),
            (lo.0, hi.0, lo.1, hi.1)
        );
        assert_eq!((a.x_min, a.y_max), (58, 742));
    }

    #[test]
    fn every_law_takes_waypoints() {
        let mut c = Controller::new(ControllerConfig::default());
        assert!(!c.set_waypoint(300, 300), "idle");
        c.start(GoTo::params(300, 600, 250).unwrap());
        // A waypoint behind the car replaces the target: it turns towards it.
        assert!(c.set_waypoint(300, 1000));
        let out = c.step(&inputs(pose(300, 400, 1571), &[]));
        assert_eq!(out.status.error_units, 342, "clamped to y 742");
        c.start(Circle::params(300, 400, 100, 0).unwrap());
        let on_circle = c.step(&inputs(pose(400, 400, 1571), &[]));
        assert!(on_circle.status.converged);
        // The centre moves: the car is 100 units off its circle now.
        assert!(c.set_waypoint(300, 500));
        let off = c.step(&inputs(pose(400, 400, 1571), &[]));
        assert!(
            !off.status.converged && off.status.error_units > 30,
            "{off:?}"
        );
    }

    #[test]
    fn the_neighbours_option_selects_what_the_law_sees() {
        let others = [
            Neighbour {
                id: 3,
                pose: pose(100, 100, 0),
                age_us: 0,
            },
            Neighbour {
                id: 4,
                pose: pose(400, 400, 0),
                age_us: 0,
            },
        ];
        let error_with = |n: Option<Neighbours>| {
            let mut c = Controller::new(ControllerConfig::default());
            c.start(
                Rendezvous::params(10, 200)
                    .unwrap()
                    .with_overrides(Overrides {
                        neighbours: n,
                        ..Overrides::default()
                    }),
            );
            c.step(&inputs(pose(300, 400, 0), &others))
                .status
                .error_units
        };
        // All: mean of (300,400), (100,100), (400,400) = (266.7, 300): 105 units away.
        assert_eq!(error_with(None), 105);
        // The nearest only: mean of (300,400) and (400,400) = 50 units away.
        assert_eq!(error_with(Some(Neighbours::Nearest(1))), 50);
        // None: alone, at its own rendezvous.
        assert_eq!(error_with(Some(Neighbours::None)), 0);
    }

    #[test]
    fn the_reverse_option_reaches_the_steering() {
        let velocity = |r: Reverse| {
            let mut c = Controller::new(ControllerConfig::default());
            c.start(
                GoTo::params(300, 200, 200)
                    .unwrap()
                    .with_overrides(Overrides {
                        reverse: Some(r),
                        ..Overrides::default()
                    }),
            );
            match c.step(&inputs(pose(300, 400, 1571), &[])).command {
                Command::MoveSv {
                    velocity_mm_s,
                    steering_mrad,
                } => (velocity_mm_s, steering_mrad),
                other => panic!("{other:?}"),
            }
        };
        // The target is straight behind.
        assert_eq!(velocity(Reverse::Allowed), (-200, 0));
        let (v, s) = velocity(Reverse::Turn);
        assert!(v < 0 && s.abs() == 523, "{v} {s}");
        let (v, s) = velocity(Reverse::Never);
        assert!(v == 60 && s.abs() == 523, "{v} {s}");
    }

    #[test]
    fn commands_stay_within_lbc_limits() {
        let mut c = Controller::new(ControllerConfig::default());
        c.start(Rendezvous::params(10, 2047).unwrap());
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
