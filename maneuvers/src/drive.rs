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

use crate::fixed::{
    atan2, fx, mul_q14, mul_shift, sin_cos, to_mrad, unfx, wrap, IVec2, HALF_TURN, Q14,
    QUARTER_TURN,
};
use crate::law::Reverse;
use crate::STEER_LIMIT_MRAD;

/// Steering limit, mrad.
pub const STEER_LIMIT: i16 = STEER_LIMIT_MRAD;
/// Heading error beyond which the car reverses: 2.45 rad (about 140 degrees) as a binary
/// angle.
pub const REVERSE_ABOVE: i32 = (2.45 * 65_536.0 / core::f64::consts::TAU + 0.5) as i32;
/// Desired speeds below this are a stop, mm/s.
pub const STOP_BELOW_MM_S: i32 = 8;
/// The prediction horizon [`predict`] takes at most, ms.
pub const MAX_PREDICT_MS: u16 = 4095;

/// Arc length per mm/s and ms, in 1/16 tracking unit, Q32: 16 / (2.5 * 1000).
const ARC_Q32: i64 = (4_294_967_296.0 * 16.0 / 2_500.0 + 0.5) as i64;
/// Turn per unit of `tan(steering)` (Q20) and of mm/s times ms, as a binary angle, Q38: the
/// arc is `v t / 2500` units, the turn `tan * arc / 32` rad (wheelbase 32 units), so
/// 65536 / (2 pi 2^20 * 2500 * 32) binary angles.
const TURN_Q38: i64 =
    (274_877_906_944.0 * 65_536.0 / (core::f64::consts::TAU * 1_048_576.0 * 80_000.0) + 0.5) as i64;
/// Rad per mrad in Q20, Q10.
const MRAD_TO_RAD_Q20_Q10: i64 = (1_048.576 * 1_024.0 + 0.5) as i64;
/// Taylor coefficients of `tan(x) / x` in `x^2`, Q20: 1, 1/3, 2/15, 17/315, 62/2835,
/// 1382/155925.
const TAN: [i64; 6] = [
    1 << 20,
    (1_048_576.0 / 3.0 + 0.5) as i64,
    (1_048_576.0 * 2.0 / 15.0 + 0.5) as i64,
    (1_048_576.0 * 17.0 / 315.0 + 0.5) as i64,
    (1_048_576.0 * 62.0 / 2_835.0 + 0.5) as i64,
    (1_048_576.0 * 1_382.0 / 155_925.0 + 0.5) as i64,
];
/// Rad in Q14 per binary angle, Q30: 2 pi 16384 / 65536 = pi / 2.
const BAM_TO_RAD_Q14_Q30: i64 = (1_073_741_824.0 * core::f64::consts::FRAC_PI_2 + 0.5) as i64;
/// Lateral speed per unit of heading gain (1/256 per second) and of heading error (binary
/// angle), in 1/16 mm/s, Q32: wheelbase 80 mm * 16 * 2 pi / (256 * 65536).
const LATERAL_Q32: i64 =
    (4_294_967_296.0 * 80.0 * 16.0 * core::f64::consts::TAU / 16_777_216.0 + 0.5) as i64;

/// Tuning of the velocity tracker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct DriveConfig {
    /// Yaw-rate gain on the heading error, 1/s in Q8 (256 = 1/s).
    pub heading_gain_q8: u16,
    /// Speed while turning towards a direction far off the heading, mm/s.
    pub creep_mm_s: i16,
    /// Upper speed limit, mm/s.
    pub max_mm_s: i16,
    /// Upper speed limit in reverse, mm/s.
    pub max_reverse_mm_s: i16,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self {
            heading_gain_q8: 3 * 256,
            creep_mm_s: 60,
            max_mm_s: 600,
            max_reverse_mm_s: 200,
        }
    }
}

/// Steering and velocity of a `MOVE_SV` command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sv {
    /// Steering angle, mrad (+ left), within +/-[`STEER_LIMIT`].
    pub steering_mrad: i16,
    /// Velocity, mm/s (signed).
    pub velocity_mm_s: i16,
}

/// Velocity tracker with its forward/reverse mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Drive {
    reverse: bool,
    /// Side of a turn round on full lock (+1 left, -1 right; 0: not turning round).
    turn: i8,
}

/// Steering (mrad, within the limit) that turns the direction of travel at `gain_q8` (1/s,
/// Q8) times the heading error `e` (binary angle) at `velocity` mm/s: atan(wheelbase * yaw
/// rate / velocity).
pub fn steering_for(gain_q8: u16, e: i32, velocity: i32) -> i16 {
    if velocity == 0 {
        return 0;
    }
    let lateral = mul_shift(i64::from(gain_q8) * i64::from(e), LATERAL_Q32, 32);
    let a = atan2(lateral * velocity.signum(), fx(velocity.abs()));
    let lim = i32::from(STEER_LIMIT);
    // Within the limit: the cast is exact.
    to_mrad(a).max(-lim).min(lim) as i16
}

/// A speed in 1/16 mm/s as whole mm/s within `i16`.
// Out of line: its clamps inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn mm_s(v: i32) -> i16 {
    unfx(v).max(-i32::from(i16::MAX)).min(i32::from(i16::MAX)) as i16
}

impl Drive {
    /// Whether the tracker is in reverse mode.
    pub fn reversing(&self) -> bool {
        self.reverse
    }

    /// Steering and speed that follow `desired` (1/16 mm/s, world frame) from `heading`
    /// (binary angle), using reverse as `mode` allows.
    pub fn track(&mut self, cfg: &DriveConfig, mode: Reverse, heading: i32, desired: IVec2) -> Sv {
        if desired.len2() < (fx(STOP_BELOW_MM_S) as u64).pow(2) {
            return Sv::default();
        }
        let speed = desired.norm();
        let psi = desired.angle();
        let e_fwd = wrap(psi - heading);
        match mode {
            Reverse::Allowed => self.turn = 0,
            Reverse::Turn => return self.turn_round(cfg, speed, e_fwd, true),
            Reverse::Never => return self.turn_round(cfg, speed, e_fwd, false),
        }
        if self.reverse {
            // Back to forward once the nose points within 40 degrees of the way.
            self.reverse = e_fwd.abs() >= HALF_TURN - REVERSE_ABOVE;
        } else {
            self.reverse = e_fwd.abs() > REVERSE_ABOVE;
        }
        let (e, sign, max) = if self.reversing() {
            (wrap(psi - heading - HALF_TURN), -1, cfg.max_reverse_mm_s)
        } else {
            (e_fwd, 1, cfg.max_mm_s)
        };
        forward_or_back(cfg, speed, e, sign, max)
    }

    /// `Turn` and `Never`: forward tracking, and a way far behind turned round on full lock
    /// (backing up first with `back`) to the side it started on, until the nose is within 90
    /// degrees of the way.
    fn turn_round(&mut self, cfg: &DriveConfig, speed: i32, e: i32, back: bool) -> Sv {
        let far = if self.turn != 0 {
            e.abs() > QUARTER_TURN
        } else {
            e.abs() > REVERSE_ABOVE
        };
        if !far {
            self.turn = 0;
            self.reverse = false;
            return forward_or_back(cfg, speed, e, 1, cfg.max_mm_s);
        }
        if self.turn == 0 {
            self.turn = if e >= 0 { 1 } else { -1 };
        }
        let side = i16::from(self.turn);
        self.reverse = back;
        let creep = fx(i32::from(cfg.creep_mm_s));
        if back {
            // Backing up with the wheels turned away from the way swings the nose towards it.
            let v = speed.max(creep).min(fx(i32::from(cfg.max_reverse_mm_s)));
            Sv {
                steering_mrad: -side * STEER_LIMIT,
                velocity_mm_s: -mm_s(v),
            }
        } else {
            Sv {
                steering_mrad: side * STEER_LIMIT,
                velocity_mm_s: mm_s(creep.min(speed)),
            }
        }
    }
}

/// Steering and speed along heading error `e` (binary angle) in direction `sign` (1 forward,
/// -1 reverse) up to `max` mm/s, for a desired `speed` (1/16 mm/s).
fn forward_or_back(cfg: &DriveConfig, speed: i32, e: i32, sign: i16, max: i16) -> Sv {
    let along = mul_q14(speed, sin_cos(e).1);
    let creep = fx(i32::from(cfg.creep_mm_s)).min(speed);
    let v = sign * mm_s(along.max(creep).max(0).min(fx(i32::from(max))));
    Sv {
        steering_mrad: steering_for(cfg.heading_gain_q8, e, i32::from(v)),
        velocity_mm_s: v,
    }
}

/// `tan` of a steering angle (mrad, clamped to the limit), Q20: its Taylor series to `x^11`,
/// relative error below 2e-5 on the steering range.
fn tan_q20(steering_mrad: i16) -> i32 {
    let lim = STEER_LIMIT;
    let x = mul_shift(
        i64::from(steering_mrad.max(-lim).min(lim)),
        MRAD_TO_RAD_Q20_Q10,
        10,
    );
    let z = i64::from(mul_shift(i64::from(x), i64::from(x), 20));
    let p = TAN[..5]
        .iter()
        .rev()
        .fold(TAN[5], |acc, &c| c + i64::from(mul_shift(acc, z, 20)));
    mul_shift(i64::from(x), p, 20)
}

/// `sin(x) / x` in Q14 for the binary angle `a`.
fn sinc(a: i32) -> i32 {
    // x in rad, Q14.
    let x = mul_shift(i64::from(a), BAM_TO_RAD_Q14_Q30, 30);
    if x.abs() <= Q14 {
        // 1 - z/6 + z^2/120 - z^3/5040 with z = x^2, in Horner form; error below 3e-6 plus
        // the roundings (a few parts in 16 384).
        let z = mul_q14(x, x);
        let p = Q14 - z / 42;
        let p = Q14 - mul_q14(z, p) / 20;
        Q14 - mul_q14(z, p) / 6
    } else {
        (sin_cos(a).0 << 14) / x
    }
}

/// Rear-axle position (1/16 tracking unit) and heading (binary angle) after driving `sv` for
/// `t_ms` milliseconds (at most [`MAX_PREDICT_MS`]): an arc of the kinematic bicycle, its
/// chord `s sin(turn/2) / (turn/2)` along the heading at half the turn.
pub fn predict(pos: IVec2, heading: i32, sv: Sv, t_ms: u16) -> (IVec2, i32) {
    // Velocity times time, below 2^15 mm/s * 2^12 ms.
    let vt = i64::from(sv.velocity_mm_s) * i64::from(t_ms.min(MAX_PREDICT_MS));
    // Arc length, below 2^20 sixteenths of a unit.
    let s = mul_shift(vt, ARC_Q32, 32);
    // |tan * vt| < 2^47 and TURN_Q38 < 2^16: the product fits.
    let turn = mul_shift(i64::from(tan_q20(sv.steering_mrad)) * vt, TURN_Q38, 38);
    let chord = mul_q14(s, sinc(turn / 2));
    let d = IVec2::from_angle(heading + turn / 2).along(chord);
    (pos + d, wrap(heading + turn))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::{from_mrad, IVec2, QUARTER_TURN, TURN};
    use proptest::prelude::*;
    use std::f64::consts::TAU;

    fn v(x: i32, y: i32) -> IVec2 {
        IVec2::from_units(x, y)
    }

    fn sv(steering_mrad: i16, velocity_mm_s: i16) -> Sv {
        Sv {
            steering_mrad,
            velocity_mm_s,
        }
    }

    #[test]
    fn straight_ahead() {
        let mut d = Drive::default();
        let cmd = d.track(&DriveConfig::default(), Reverse::Allowed, 0, v(200, 0));
        assert_eq!(cmd, sv(0, 200));
    }

    #[test]
    fn turns_left_towards_left_target_at_creep() {
        let mut d = Drive::default();
        let cmd = d.track(&DriveConfig::default(), Reverse::Allowed, 0, v(0, 200));
        assert_eq!(cmd, sv(STEER_LIMIT, 60));
    }

    #[test]
    fn reverses_for_targets_behind_with_hysteresis() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Desired direction slightly right of straight behind.
        let cmd = d.track(&cfg, Reverse::Allowed, 0, v(-200, -20));
        assert!(d.reversing());
        assert!(cmd.velocity_mm_s < -150);
        // Backing up turns the tail towards -Y: the nose swings to +Y.
        let (p, h) = predict(IVec2::ZERO, 0, cmd, 500);
        assert!(p.x < 0 && p.y < 0 && h > 0, "{p:?} {h}");
        // 90 degrees off: stays in reverse.
        d.track(&cfg, Reverse::Allowed, 0, v(0, 200));
        assert!(d.reversing());
        d.track(&cfg, Reverse::Allowed, 0, v(200, 10));
        assert!(!d.reversing());
    }

    #[test]
    fn never_turns_round_forward_on_one_side() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Way straight behind, a little to the left: forward on full left lock at creep.
        let cmd = d.track(&cfg, Reverse::Never, 0, v(-200, 1));
        assert_eq!(cmd, sv(STEER_LIMIT, 60));
        // The way swings to the other side of straight behind: it keeps turning left.
        let cmd = d.track(&cfg, Reverse::Never, 0, v(-200, -1));
        assert_eq!(cmd.steering_mrad, STEER_LIMIT);
        assert!(!d.reversing());
        // Nose within 90 degrees: ordinary tracking.
        let cmd = d.track(&cfg, Reverse::Never, 0, v(200, 10));
        assert!(
            cmd.velocity_mm_s > 150 && cmd.steering_mrad.abs() < 300,
            "{cmd:?}"
        );
    }

    #[test]
    fn turn_backs_up_swinging_the_nose_towards_the_way() {
        let mut d = Drive::default();
        let cfg = DriveConfig::default();
        // Way behind and to the left: back up steering right.
        let cmd = d.track(&cfg, Reverse::Turn, 0, v(-200, 20));
        assert!(
            d.reversing() && cmd.velocity_mm_s < 0 && cmd.steering_mrad < 0,
            "{cmd:?}"
        );
        let (_, h) = predict(IVec2::ZERO, 0, cmd, 500);
        assert!(h > 0, "the nose turns left: {h}");
        // Still more than 90 degrees off: keeps backing.
        let cmd = d.track(&cfg, Reverse::Turn, from_mrad(1200), v(-200, 20));
        assert!(cmd.velocity_mm_s < 0, "{cmd:?}");
        // Within 90 degrees: forward.
        let cmd = d.track(&cfg, Reverse::Turn, from_mrad(1800), v(-200, 20));
        assert!(cmd.velocity_mm_s > 0 && !d.reversing(), "{cmd:?}");
    }

    #[test]
    fn stop_for_tiny_speeds() {
        let mut d = Drive::default();
        let cmd = d.track(&DriveConfig::default(), Reverse::Allowed, 0, v(5, 5));
        assert_eq!(cmd, Sv::default());
    }

    #[test]
    fn steering_is_the_bicycle_arctangent() {
        // Heading error 0.2 rad at gain 3/s: yaw rate 0.6 rad/s; at 100 mm/s the steering is
        // atan(80 * 0.6 / 100) = 0.4466 rad.
        // atan(0.48) = 447.52 mrad.
        assert_eq!(steering_for(768, from_mrad(200), 100), 448);
        assert_eq!(steering_for(768, from_mrad(-200), 100), -448);
        // Backwards the same error needs the opposite steering.
        assert_eq!(steering_for(768, from_mrad(200), -100), -448);
        assert_eq!(steering_for(768, QUARTER_TURN, 100), STEER_LIMIT);
        assert_eq!(steering_for(768, QUARTER_TURN, 0), 0);
    }

    #[test]
    fn predict_arc_quarter_circle() {
        // Full left lock: radius = 80 mm / tan(0.523) = 138.7 mm = 55.5 units. A quarter of
        // the circle at 100 mm/s takes 2.18 s.
        let r = 32.0 / 0.523f64.tan();
        let t_ms = (TAU / 4.0 * r * 2.5 / 100.0 * 1000.0).round() as u16;
        let (p, h) = predict(IVec2::ZERO, 0, sv(STEER_LIMIT, 100), t_ms);
        assert!((h - QUARTER_TURN).abs() <= 10, "{h}");
        let (x, y) = (f64::from(p.x) / 16.0, f64::from(p.y) / 16.0);
        assert!((x - r).abs() < 0.1 && (y - r).abs() < 0.1, "{p:?} {r}");
        let (p, h) = predict(IVec2::ZERO, TURN / 2, sv(0, 250), 1000);
        assert_eq!((p, wrap(h)), (IVec2::from_units(-100, 0), wrap(TURN / 2)));
        assert_eq!(predict(v(3, 4), 77, sv(300, 0), 450), (v(3, 4), 77));
    }

    #[test]
    fn tangent_of_the_steering() {
        for m in -523i16..=523 {
            let exact = (f64::from(m) * 1e-3).tan();
            let e = f64::from(tan_q20(m)) / 1_048_576.0 - exact;
            assert!(e.abs() <= 2e-5 * exact.abs() + 1e-6, "{m}: {e}");
        }
        assert_eq!(tan_q20(600), tan_q20(STEER_LIMIT));
    }

    proptest! {
        /// The arc against the bicycle model in `f64`: within 0.1 unit (1.6 steps of the fixed
        /// point) plus 2.5e-4 of the distance driven (0.16 unit, 0.4 mm, at 600 mm/s for
        /// 1 s), and the heading within
        /// 2e-4 rad, over the whole range of commands and horizons up to one second.
        #[test]
        fn predict_against_f64(
            steering in -523i16..=523,
            velocity in -2000i16..=2000,
            heading_mrad in 0i32..6283,
            t_ms in 0u16..=1000,
        ) {
            let h0 = f64::from(heading_mrad) * 1e-3;
            let (p, h) = predict(v(300, 400), from_mrad(heading_mrad), sv(steering, velocity), t_ms);
            let s = f64::from(velocity) * f64::from(t_ms) * 1e-3 / 2.5;
            let k = (f64::from(steering) * 1e-3).tan() / 32.0;
            let (dx, dy, dh) = if (k * s).abs() < 1e-9 {
                (s * h0.cos(), s * h0.sin(), 0.0)
            } else {
                let h1 = h0 + k * s;
                ((h1.sin() - h0.sin()) / k, (h0.cos() - h1.cos()) / k, k * s)
            };
            let ex = f64::from(p.x) / 16.0 - 300.0 - dx;
            let ey = f64::from(p.y) / 16.0 - 400.0 - dy;
            let bound = 0.1 + 2.5e-4 * s.abs();
            prop_assert!(ex.abs() < bound && ey.abs() < bound, "{} {} ({} {})", ex, ey, dx, dy);
            let eh = (f64::from(h) * TAU / 65536.0 - (h0 + dh)).rem_euclid(TAU);
            let eh = eh.min(TAU - eh);
            prop_assert!(eh < 2e-4, "{}", eh);
        }
    }
}
