//! The LBC firmware's control laws: velocity estimation, the velocity PID, servo mapping and
//! the MOVE_XY path generator. Pure functions and small state structs, unit-tested here; the
//! task code in [`crate::lbc`] wires them to the scheduler.
//!
//! Scaling of the seed's control parameters (Table 3-3), all documented in
//! docs/lbc-emulator.md:
//! - Motor Encoder Ratio: encoder counts per motor revolution (800 for a 0.45 degree encoder).
//! - Motor Gear Ratio: motor revolutions per wheel revolution, in hundredths (2000 = 20:1).
//! - Motor P/I/D gains: `u = (Kp*e + Ki*I + Kd*de) / 256` in per-mille PWM, with `e` the
//!   velocity error in mm/s, `I` its integral in mm, `de` its change per 1 ms tick in mm/s.
//! - Motor Dead Band: per-mille PWM added to every non-zero output to overcome static friction.
//! - Servo Offset / Gain: `pulse_us = 1500 + offset + gain * steer_rad` (gain in us per rad).
//! - Servo Dead Band: pulse changes smaller than this many us are not applied.
//! - Servo P/I/D gains: stored and reported; the emulated servo is a position servo that closes
//!   its own loop, so they have no effect.

use core::f64::consts::PI;

use crate::vehicle::{wrap_2pi, wrap_pi};

/// Drive wheel diameter the firmware assumes, mm.
pub const WHEEL_DIAMETER_MM: f64 = 30.0;
/// Velocity estimation window, 1 ms samples.
pub const VELOCITY_WINDOW: usize = 10;
/// Divisor of the motor PID gains.
pub const MOTOR_GAIN_SCALE: f64 = 256.0;
/// Full-scale PWM, per mille.
pub const PWM_FULL: f64 = 1000.0;
/// Below this estimated speed (mm/s) a car asked to stand still has its drive switched off.
pub const STANDSTILL_MM_S: f64 = 3.0;
/// Steering limit, mrad (30 degrees).
pub const STEER_LIMIT_MRAD: i16 = 523;
/// Largest |velocity| MOVE_SV accepts, mm/s.
pub const VELOCITY_LIMIT_MM_S: i16 = 2000;
/// Steering potentiometer reading at straight ahead, ADC counts.
pub const STEER_LP_CENTER: f64 = 512.0;
/// Steering potentiometer slope, ADC counts per rad.
pub const STEER_LP_COUNTS_PER_RAD: f64 = 600.0;
/// Servo pulse width at zero offset and zero angle, us.
pub const SERVO_CENTER_US: f64 = 1500.0;

/// Millimetres per encoder count for the given parameters.
pub fn mm_per_count(encoder_ratio: i16, gear_ratio_hundredths: i16) -> f64 {
    let cpr = f64::from(encoder_ratio.max(1));
    let gear = f64::from(gear_ratio_hundredths.max(1)) / 100.0;
    PI * WHEEL_DIAMETER_MM / (cpr * gear)
}

/// Encoder-based velocity: counts over the last [`VELOCITY_WINDOW`] ms.
#[derive(Debug, Clone, Default)]
pub struct VelocityEstimator {
    history: [i64; VELOCITY_WINDOW + 1],
    next: usize,
    filled: usize,
    estimate_mm_s: f64,
}

impl VelocityEstimator {
    /// Takes one 1 kHz encoder sample; returns the estimate in mm/s.
    pub fn update(&mut self, count: i64, mm_per_count: f64) -> f64 {
        self.history[self.next] = count;
        self.next = (self.next + 1) % self.history.len();
        self.filled = (self.filled + 1).min(self.history.len());
        if self.filled < 2 {
            self.estimate_mm_s = 0.0;
            return 0.0;
        }
        let newest = self.history[(self.next + self.history.len() - 1) % self.history.len()];
        let span = self.filled - 1;
        let oldest = self.history[(self.next + self.history.len() - 1 - span) % self.history.len()];
        self.estimate_mm_s = (newest - oldest) as f64 * mm_per_count / (span as f64 * 1e-3);
        self.estimate_mm_s
    }

    /// The latest estimate, mm/s.
    pub fn estimate_mm_s(&self) -> f64 {
        self.estimate_mm_s
    }
}

/// Motor PID gains and dead band, as stored in the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorGains {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Differential gain.
    pub kd: f64,
    /// Dead band, per mille PWM.
    pub dead_band: f64,
}

/// Velocity PID state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct VelocityPid {
    /// Last error, mm/s.
    pub error: f64,
    /// Last error change per tick, mm/s.
    pub d_error: f64,
    /// Error integral, mm.
    pub integral: f64,
}

impl VelocityPid {
    /// One 1 ms step; returns PWM in per mille (-1000..=1000).
    pub fn step(&mut self, target_mm_s: f64, estimate_mm_s: f64, g: MotorGains) -> f64 {
        if target_mm_s == 0.0 && estimate_mm_s.abs() < STANDSTILL_MM_S {
            *self = Self::default();
            return 0.0;
        }
        let e = target_mm_s - estimate_mm_s;
        self.d_error = e - self.error;
        self.error = e;
        self.integral += e * 1e-3;
        // Anti-windup: the integral term alone never exceeds full scale.
        if g.ki > 0.0 {
            let lim = PWM_FULL * MOTOR_GAIN_SCALE / g.ki;
            self.integral = self.integral.clamp(-lim, lim);
        }
        let u = (g.kp * e + g.ki * self.integral + g.kd * self.d_error) / MOTOR_GAIN_SCALE;
        apply_dead_band(u, g.dead_band)
    }
}

/// Maps a controller output to PWM, adding the dead band to any non-zero output.
pub fn apply_dead_band(u: f64, dead_band: f64) -> f64 {
    let db = dead_band.clamp(0.0, PWM_FULL);
    let u = u.clamp(-PWM_FULL, PWM_FULL);
    if u.abs() < 0.5 {
        0.0
    } else {
        u.signum() * (db + u.abs() * (PWM_FULL - db) / PWM_FULL)
    }
}

/// Servo pulse for a steering angle through the Servo Offset and Gain parameters.
pub fn servo_pulse_us(steer_mrad: f64, offset_us: i16, gain_us_per_rad: i16) -> f64 {
    let s = steer_mrad.clamp(-f64::from(STEER_LIMIT_MRAD), f64::from(STEER_LIMIT_MRAD));
    SERVO_CENTER_US + f64::from(offset_us) + f64::from(gain_us_per_rad) * s / 1000.0
}

/// Steering angle (mrad) read from the steering potentiometer.
pub fn steer_from_lp(lp_counts: u16) -> f64 {
    (f64::from(lp_counts) - STEER_LP_CENTER) / STEER_LP_COUNTS_PER_RAD * 1000.0
}

/// Tuning of the MOVE_XY path generator (not seed parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct PathConfig {
    /// Cruise speed, mm/s.
    pub cruise_mm_s: f64,
    /// Lowest speed while approaching, mm/s.
    pub min_mm_s: f64,
    /// Approach speed per mm of remaining distance, 1/s.
    pub approach_gain: f64,
    /// Arrival tolerance, tracking units (2.5 mm each).
    pub tolerance_units: f64,
    /// Wheelbase the firmware assumes, mm.
    pub wheelbase_mm: f64,
}

impl Default for PathConfig {
    fn default() -> Self {
        Self {
            cruise_mm_s: 300.0,
            min_mm_s: 60.0,
            approach_gain: 2.0,
            tolerance_units: 8.0,
            wheelbase_mm: 80.0,
        }
    }
}

/// How the path generator is currently moving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PathPhase {
    /// Pure pursuit forward (or a full-lock turn towards a target behind).
    #[default]
    Forward,
    /// Pure pursuit in reverse (target close behind).
    Reverse,
    /// Straight back until a forward arc can reach the target.
    BackOff,
    /// Straight ahead until a reverse arc can reach the target.
    PullOut,
}

/// Output of one path generator step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathStep {
    /// Target velocity, mm/s.
    pub velocity_mm_s: f64,
    /// Target steering, mrad.
    pub steer_mrad: f64,
    /// Bearing from the car to the target, rad in `0..2*PI`.
    pub bearing_rad: f64,
    /// The car is within tolerance: stop.
    pub arrived: bool,
}

/// One 50 Hz step of MOVE_XY path generation. Pose and target in mm, heading in rad.
pub fn path_step(
    pos_mm: (f64, f64),
    heading_rad: f64,
    target_mm: (f64, f64),
    phase: &mut PathPhase,
    cfg: &PathConfig,
) -> PathStep {
    let (dx, dy) = (target_mm.0 - pos_mm.0, target_mm.1 - pos_mm.1);
    let d = dx.hypot(dy);
    let bearing = wrap_2pi(dy.atan2(dx));
    if d <= cfg.tolerance_units * 2.5 {
        return PathStep {
            velocity_mm_s: 0.0,
            steer_mrad: 0.0,
            bearing_rad: bearing,
            arrived: true,
        };
    }
    let limit = f64::from(STEER_LIMIT_MRAD) / 1000.0;
    let kappa_max = limit.tan() / cfg.wheelbase_mm;
    let r_min = 1.0 / kappa_max;
    let alpha = wrap_pi(bearing - heading_rad);
    let behind = alpha.abs() > PI / 2.0;
    let k_fwd = 2.0 * alpha.sin() / d;
    let alpha_r = wrap_pi(alpha - PI);
    let k_rev = 2.0 * alpha_r.sin() / d;

    // Choose a phase (with hysteresis on the reachability tests).
    *phase = match *phase {
        PathPhase::BackOff if k_fwd.abs() > 0.6 * kappa_max && !behind => PathPhase::BackOff,
        PathPhase::PullOut if k_rev.abs() > 0.6 * kappa_max && behind => PathPhase::PullOut,
        _ => {
            if behind && d < 3.0 * r_min {
                if k_rev.abs() > kappa_max {
                    PathPhase::PullOut
                } else {
                    PathPhase::Reverse
                }
            } else if !behind && k_fwd.abs() > kappa_max {
                PathPhase::BackOff
            } else {
                PathPhase::Forward
            }
        }
    };
    let speed = (cfg.approach_gain * d).clamp(cfg.min_mm_s, cfg.cruise_mm_s);
    let (v, kappa) = match *phase {
        PathPhase::Forward => {
            let k = if behind {
                alpha.signum() * kappa_max
            } else {
                k_fwd
            };
            (speed, k)
        }
        // Reversing, steering left curves the path to the right of the travel direction.
        PathPhase::Reverse => (-speed, -k_rev),
        PathPhase::BackOff => (-2.0 * cfg.min_mm_s, 0.0),
        PathPhase::PullOut => (2.0 * cfg.min_mm_s, 0.0),
    };
    let kappa = kappa.clamp(-kappa_max, kappa_max);
    let slow = 1.0 - 0.5 * kappa.abs() / kappa_max;
    let steer = (kappa * cfg.wheelbase_mm).atan() * 1000.0;
    PathStep {
        velocity_mm_s: v * slow,
        steer_mrad: steer,
        bearing_rad: bearing,
        arrived: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoder_scaling() {
        let mpc = mm_per_count(800, 2000);
        assert!((mpc - PI * 30.0 / 16_000.0).abs() < 1e-12);
        let mut est = VelocityEstimator::default();
        // 100 counts per ms.
        for k in 0..20 {
            est.update(k * 100, mpc);
        }
        assert!((est.estimate_mm_s() - 100.0 * mpc * 1000.0).abs() < 1e-9);
    }

    #[test]
    fn pid_scaling_and_dead_band() {
        let g = MotorGains {
            kp: 512.0,
            ki: 0.0,
            kd: 0.0,
            dead_band: 50.0,
        };
        let mut pid = VelocityPid::default();
        // 100 mm/s error * 512 / 256 = 200 per mille, plus dead band.
        let u = pid.step(100.0, 0.0, g);
        assert!((u - (50.0 + 200.0 * 0.95)).abs() < 1e-9, "{u}");
        assert_eq!(apply_dead_band(0.1, 50.0), 0.0);
        assert_eq!(apply_dead_band(-5000.0, 50.0), -1000.0);
        // Standing still with a zero target switches the drive off and clears the state.
        assert_eq!(pid.step(0.0, 1.0, g), 0.0);
        assert_eq!(pid, VelocityPid::default());
    }

    #[test]
    fn servo_mapping_limits_steering() {
        assert_eq!(servo_pulse_us(0.0, 10, 1000), 1510.0);
        assert_eq!(servo_pulse_us(1000.0, 0, 1000), 2023.0);
        assert_eq!(servo_pulse_us(-1000.0, 0, -1000), 2023.0);
        assert!((steer_from_lp(812) - 500.0).abs() < 1e-9);
    }

    #[test]
    fn path_step_turns_towards_the_target_and_arrives() {
        let cfg = PathConfig::default();
        let mut ph = PathPhase::default();
        // Target ahead and to the left.
        let s = path_step((0.0, 0.0), 0.0, (500.0, 200.0), &mut ph, &cfg);
        assert_eq!(ph, PathPhase::Forward);
        assert!(s.steer_mrad > 0.0 && s.velocity_mm_s > 0.0);
        // Within tolerance.
        let s = path_step((0.0, 0.0), 0.0, (15.0, 0.0), &mut ph, &cfg);
        assert!(s.arrived);
        assert_eq!(s.velocity_mm_s, 0.0);
        // Close behind: reverse.
        let mut ph = PathPhase::default();
        let s = path_step((0.0, 0.0), 0.0, (-200.0, 10.0), &mut ph, &cfg);
        assert_eq!(ph, PathPhase::Reverse);
        assert!(s.velocity_mm_s < 0.0);
        // Beside the car, inside the turning circle: back off first.
        let mut ph = PathPhase::default();
        let s = path_step((0.0, 0.0), 0.0, (30.0, 100.0), &mut ph, &cfg);
        assert_eq!(ph, PathPhase::BackOff);
        assert!(s.velocity_mm_s < 0.0);
        assert_eq!(s.steer_mrad, 0.0);
        // Far behind: full lock forward turn.
        let mut ph = PathPhase::default();
        let s = path_step((0.0, 0.0), 0.0, (-1000.0, 10.0), &mut ph, &cfg);
        assert_eq!(ph, PathPhase::Forward);
        assert!((s.steer_mrad - 523.0).abs() < 1e-6);
    }
}
