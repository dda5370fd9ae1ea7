//! From a desired world-frame velocity to a `MOVE_SV` steering angle and speed.
//!
//! The car is a kinematic bicycle about the rear axle (wheelbase 80 mm, +/-30 degrees of
//! steering), so it cannot move sideways: the heading is turned towards the desired direction
//! with a yaw rate proportional to the heading error, and the speed is the projection of the
//! desired velocity on the heading, never below a creep speed so that the car can turn. What
//! happens to a desired direction more than [`REVERSE_ABOVE`] behind the car is the law's
//! [`Reverse`] option: driven in reverse (`Allowed`), turned round by backing up on full lock
//! first (`Turn`), or turned round forward on full lock (`Never`); each with hysteresis so the
//! mode does not chatter.

use core::f32::consts::{FRAC_PI_2, PI};

use crate::fmath::{atan, cos, sin_cos, tan};
use crate::geom::{clampf, wrap, Vec2};
use crate::law::Reverse;
use crate::{MM_PER_UNIT, WHEELBASE_MM};

/// Steering limit, rad.
pub const STEER_LIMIT: f32 = 0.523;
/// Heading error beyond which the car reverses, rad (about 140 degrees).
pub const REVERSE_ABOVE: f32 = 2.45;
/// Desired speeds below this are a stop, mm/s.
pub const STOP_BELOW_MM_S: f32 = 8.0;

/// Tuning of the velocity tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct DriveConfig {
    /// Yaw-rate gain on the heading error, 1/s.
    pub heading_gain: f32,
    /// Speed while turning towards a direction far off the heading, mm/s.
    pub creep_mm_s: f32,
    /// Upper speed limit, mm/s.
    pub max_mm_s: f32,
    /// Upper speed limit in reverse, mm/s.
    pub max_reverse_mm_s: f32,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            heading_gain: 3.0,
            creep_mm_s: 60.0,
            max_mm_s: 600.0,
            max_reverse_mm_s: 200.0,
        }
    }
}

/// Steering (rad, + left) and velocity (mm/s, signed).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sv {
    /// Steering angle, rad.
    pub steering: f32,
    /// Velocity, mm/s.
    pub velocity: f32,
}

/// Velocity tracker with its forward/reverse mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Drive {
    reverse: bool,
    /// Side of a turn round on full lock (+1 left, -1 right; 0: not turning round).
    turn: i8,
}

/// Steering that turns the direction of travel by `yaw_rate` rad/s at `velocity` mm/s.
pub fn steering_for(yaw_rate: f32, velocity: f32) -> f32 {
    if velocity.abs() < 1.0 {
        return 0.0;
    }
    clampf(
        atan(WHEELBASE_MM * yaw_rate / velocity),
        -STEER_LIMIT,
        STEER_LIMIT,
    )
}

impl Drive {
    /// Whether the tracker is in reverse mode.
    pub fn reversing(&self) -> bool {
        self.reverse
    }

    /// Steering and speed that follow `desired` (mm/s, world frame) from `heading` (rad), using
    /// reverse as `mode` allows.
    pub fn track(&mut self, cfg: &DriveConfig, mode: Reverse, heading: f32, desired: Vec2) -> Sv {
        let speed = desired.norm();
        if speed < STOP_BELOW_MM_S {
            return Sv::default();
        }
        let psi = desired.angle();
        let e_fwd = wrap(psi - heading);
        match mode {
            Reverse::Allowed => self.turn = 0,
            Reverse::Turn => return self.turn_round(cfg, speed, e_fwd, true),
            Reverse::Never => return self.turn_round(cfg, speed, e_fwd, false),
        }
        if self.reverse {
            // Back to forward once the nose points within 40 degrees of the way.
            self.reverse = e_fwd.abs() >= PI - REVERSE_ABOVE;
        } else {
            self.reverse = e_fwd.abs() > REVERSE_ABOVE;
        }
        let (e, sign, max) = if self.reversing() {
            (wrap(psi - heading - PI), -1.0, cfg.max_reverse_mm_s)
        } else {
            (e_fwd, 1.0, cfg.max_mm_s)
        };
        forward_or_back(cfg, speed, e, sign, max)
    }

    /// `Turn` and `Never`: forward tracking, and a way far behind turned round on full lock
    /// (backing up first with `back`) to the side it started on, until the nose is within 90
    /// degrees of the way.
    fn turn_round(&mut self, cfg: &DriveConfig, speed: f32, e: f32, back: bool) -> Sv {
        let far = if self.turn != 0 {
            e.abs() > FRAC_PI_2
        } else {
            e.abs() > REVERSE_ABOVE
        };
        if !far {
            self.turn = 0;
            self.reverse = false;
            return forward_or_back(cfg, speed, e, 1.0, cfg.max_mm_s);
        }
        if self.turn == 0 {
            self.turn = if e >= 0.0 { 1 } else { -1 };
        }
        let side = f32::from(self.turn);
        self.reverse = back;
        if back {
            // Backing up with the wheels turned away from the way swings the nose towards it.
            Sv {
                steering: -side * STEER_LIMIT,
                velocity: -clampf(speed, cfg.creep_mm_s, cfg.max_reverse_mm_s),
            }
        } else {
            Sv {
                steering: side * STEER_LIMIT,
                velocity: cfg.creep_mm_s.min(speed),
            }
        }
    }
}

/// Steering and speed along heading error `e` (rad) in direction `sign` (1 forward, -1
/// reverse) up to `max` mm/s.
fn forward_or_back(cfg: &DriveConfig, speed: f32, e: f32, sign: f32, max: f32) -> Sv {
    let along = speed * cos(e);
    let v = sign * clampf(along.max(cfg.creep_mm_s.min(speed)), 0.0, max);
    Sv {
        steering: steering_for(cfg.heading_gain * e, v),
        velocity: v,
    }
}

/// Rear-axle position (tracking units) and heading (rad) after driving `sv` for `t` seconds.
pub fn predict(pos: Vec2, heading: f32, sv: Sv, t: f32) -> (Vec2, f32) {
    let s = sv.velocity * t / MM_PER_UNIT;
    let k = tan(sv.steering) / (WHEELBASE_MM / MM_PER_UNIT);
    let turn = k * s;
    if turn.abs() < 1e-3 {
        return (pos + Vec2::from_angle(heading) * s, heading);
    }
    let h1 = heading + turn;
    let (s0, c0) = sin_cos(heading);
    let (s1, c1) = sin_cos(h1);
    let d = Vec2::new((s1 - s0) / k, (c0 - c1) / k);
    (pos + d, h1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_ahead() {
        let mut d = Drive::default();
        let sv = d.track(
            &DriveConfig::default(),
            Reverse::Allowed,
            0.0,
            Vec2::new(200.0, 0.0),
        );
        assert_eq!(
            sv,
            Sv {
                steering: 0.0,
                velocity: 200.0
            }
        );
    }

    #[test]
    fn turns_left_towards_left_target_at_creep() {
        let mut d = Drive::default();
        let sv = d.track(
            &DriveConfig::default(),
            Reverse::Allowed,
            0.0,
            Vec2::new(0.0, 200.0),
        );
        assert!((sv.steering - STEER_LIMIT).abs() < 1e-6);
        assert!((sv.velocity - 60.0).abs() < 1e-3);
    }

    #[test]
    fn reverses_for_targets_behind_with_hysteresis() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Desired direction slightly right of straight behind.
        let sv = d.track(&cfg, Reverse::Allowed, 0.0, Vec2::new(-200.0, -20.0));
        assert!(d.reversing());
        assert!(sv.velocity < -150.0);
        // Backing up turns the tail towards -Y: steer left (the nose swings to +Y... rear to -Y).
        let (p, h) = predict(Vec2::ZERO, 0.0, sv, 0.5);
        assert!(p.x < 0.0 && p.y < 0.0 && h > 0.0, "{p:?} {h}");
        // 90 degrees off: stays in reverse.
        d.track(&cfg, Reverse::Allowed, 0.0, Vec2::new(0.0, 200.0));
        assert!(d.reversing());
        d.track(&cfg, Reverse::Allowed, 0.0, Vec2::new(200.0, 10.0));
        assert!(!d.reversing());
    }

    #[test]
    fn never_turns_round_forward_on_one_side() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Way straight behind, a little to the left: forward on full left lock at creep.
        let sv = d.track(&cfg, Reverse::Never, 0.0, Vec2::new(-200.0, 1.0));
        assert_eq!(sv.velocity, 60.0);
        assert!((sv.steering - STEER_LIMIT).abs() < 1e-6);
        // The way swings to the other side of straight behind: it keeps turning left.
        let sv = d.track(&cfg, Reverse::Never, 0.0, Vec2::new(-200.0, -1.0));
        assert!((sv.steering - STEER_LIMIT).abs() < 1e-6, "{sv:?}");
        assert!(!d.reversing());
        // Nose within 90 degrees: ordinary tracking.
        let sv = d.track(&cfg, Reverse::Never, 0.0, Vec2::new(200.0, 10.0));
        assert!(sv.velocity > 150.0 && sv.steering.abs() < 0.3, "{sv:?}");
    }

    #[test]
    fn turn_backs_up_swinging_the_nose_towards_the_way() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Way behind and to the left: back up steering right.
        let sv = d.track(&cfg, Reverse::Turn, 0.0, Vec2::new(-200.0, 20.0));
        assert!(
            d.reversing() && sv.velocity < 0.0 && sv.steering < 0.0,
            "{sv:?}"
        );
        let (_, h) = predict(Vec2::ZERO, 0.0, sv, 0.5);
        assert!(h > 0.0, "the nose turns left: {h}");
        // Still more than 90 degrees off: keeps backing.
        let sv = d.track(&cfg, Reverse::Turn, 1.2, Vec2::new(-200.0, 20.0));
        assert!(sv.velocity < 0.0, "{sv:?}");
        // Within 90 degrees: forward.
        let sv = d.track(&cfg, Reverse::Turn, 1.8, Vec2::new(-200.0, 20.0));
        assert!(sv.velocity > 0.0 && !d.reversing(), "{sv:?}");
    }

    #[test]
    fn stop_for_tiny_speeds() {
        let mut d = Drive::default();
        assert_eq!(
            d.track(
                &DriveConfig::default(),
                Reverse::Allowed,
                1.0,
                Vec2::new(1.0, 1.0)
            ),
            Sv::default()
        );
    }

    #[test]
    fn predict_arc_quarter_circle() {
        // Full left lock: radius = 80 mm / tan(0.523) = 138.7 mm = 55.5 units.
        let r = 32.0 / tan(STEER_LIMIT);
        let sv = Sv {
            steering: STEER_LIMIT,
            velocity: 100.0,
        };
        let t = FRAC_PI_2 * r * MM_PER_UNIT / 100.0;
        let (p, h) = predict(Vec2::ZERO, 0.0, sv, t);
        assert!((h - FRAC_PI_2).abs() < 1e-3);
        assert!((p.x - r).abs() < 0.05 && (p.y - r).abs() < 0.05, "{p:?}");
        let (p, _) = predict(
            Vec2::ZERO,
            PI,
            Sv {
                steering: 0.0,
                velocity: 250.0,
            },
            1.0,
        );
        assert!((p.x + 100.0).abs() < 1e-3);
    }
}
