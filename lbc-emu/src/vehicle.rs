//! The physical car the emulated LBC drives: the plant, not the controller.
//!
//! A kinematic bicycle model (rear drive, pose at the midpoint of the rear axle) moved by a DC
//! drive motor with a first-order speed response and static friction, a position servo with a
//! slew rate, an optical encoder on the motor shaft, three analog gyros, a steering linear
//! potentiometer, an infrared range sensor, a NiMH battery pack and the microcontroller's die
//! temperature. Everything the LBC learns about the car goes through [`Vehicle::sample_adc`] and
//! [`Vehicle::encoder_count`], quantised as the real hardware would quantise it.
//!
//! Internal units are SI-like floats (mm, s, rad, V); the protocol's integer units are produced
//! by the LBC code, not here.

use core::f64::consts::PI;
use rand::Rng;

/// Tracking units per millimetre (1 unit = 2.5 mm).
pub const UNITS_PER_MM: f64 = 1.0 / 2.5;

/// Physical truth of one car. Defaults describe the car the factory EEPROM was calibrated for.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct VehicleConfig {
    /// Distance between the axles, mm.
    pub wheelbase_mm: f64,
    /// Drive wheel diameter, mm.
    pub wheel_diameter_mm: f64,
    /// Motor revolutions per wheel revolution.
    pub gear_ratio: f64,
    /// Encoder counts per motor revolution (0.45 degree resolution: 800).
    pub encoder_cpr: f64,
    /// Steady-state speed at full PWM and [`VehicleConfig::nominal_battery_v`], mm/s.
    pub max_speed_mm_s: f64,
    /// Battery voltage at which `max_speed_mm_s` holds, V.
    pub nominal_battery_v: f64,
    /// Speed response time constant of the drive train, s.
    pub motor_tau_s: f64,
    /// PWM fraction that static friction swallows (0..1).
    pub stiction_duty: f64,
    /// Mechanical steering limit, rad (30 degrees).
    pub steer_limit_rad: f64,
    /// Servo slew rate, rad/s.
    pub servo_slew_rad_s: f64,
    /// Servo pulse width for straight ahead, minus 1500 us (a mis-trimmed servo is non-zero).
    pub servo_trim_us: f64,
    /// Servo pulse width change per radian of steering, us/rad (sign: + = left).
    pub servo_us_per_rad: f64,
    /// Distance from the rear axle to the range sensor at the nose, mm.
    pub range_sensor_offset_mm: f64,
    /// Arena size along X (width) and Y (length), mm; the range sensor sees its walls.
    pub arena_mm: (f64, f64),
    /// Sensors.
    pub sensors: SensorConfig,
    /// Battery and die temperature.
    pub power: PowerConfig,
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            wheelbase_mm: 80.0,
            wheel_diameter_mm: 30.0,
            gear_ratio: 20.0,
            encoder_cpr: 800.0,
            max_speed_mm_s: 1500.0,
            nominal_battery_v: 5.0,
            motor_tau_s: 0.08,
            stiction_duty: 0.05,
            steer_limit_rad: 0.523,
            servo_slew_rad_s: 7.5,
            servo_trim_us: 0.0,
            servo_us_per_rad: 1000.0,
            range_sensor_offset_mm: 95.0,
            arena_mm: (1500.0, 2000.0),
            sensors: SensorConfig::default(),
            power: PowerConfig::default(),
        }
    }
}

/// Analog sensor truth (10-bit ADC, 3.0 V full scale).
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct SensorConfig {
    /// ADC full-scale voltage, V.
    pub adc_vref: f64,
    /// Voltage of the reference channel ADC3, V.
    pub reference_v: f64,
    /// Gyro zero-rate level of all three gyros, V.
    pub gyro_zrl_v: f64,
    /// Gyro sensitivity, V per degree/s.
    pub gyro_v_per_dps: f64,
    /// Yaw gyro bias: true zero-rate level minus the factory-calibrated one, degree/s.
    pub gyro_yaw_bias_dps: f64,
    /// Gyro white noise (per sample, one sigma), degree/s.
    pub gyro_noise_dps: f64,
    /// Steering potentiometer reading at straight ahead, ADC counts.
    pub steer_lp_center: f64,
    /// Steering potentiometer slope, ADC counts per rad.
    pub steer_lp_counts_per_rad: f64,
    /// Range sensor curve `adc = offset + k / d_mm`: the offset, counts.
    pub range_offset_counts: f64,
    /// Range sensor curve constant k, counts * mm.
    pub range_k: f64,
    /// Range sensor valid span, mm (outside it the reading saturates).
    pub range_span_mm: (f64, f64),
    /// Range sensor noise (one sigma), ADC counts.
    pub range_noise_counts: f64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            adc_vref: 3.0,
            reference_v: 1.225,
            gyro_zrl_v: 1.5,
            gyro_v_per_dps: 0.002,
            gyro_yaw_bias_dps: 0.0,
            gyro_noise_dps: 0.5,
            steer_lp_center: 512.0,
            steer_lp_counts_per_rad: 600.0,
            range_offset_counts: 26.0,
            range_k: 165_440.0,
            range_span_mm: (200.0, 1500.0),
            range_noise_counts: 1.0,
        }
    }
}

/// Battery pack (4 x AAA NiMH) and die temperature.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct PowerConfig {
    /// Pack capacity, mAh.
    pub capacity_mah: f64,
    /// State of charge at start, 0..=1.
    pub initial_soc: f64,
    /// Current drawn by the electronics (both boards), mA.
    pub base_current_ma: f64,
    /// Extra current at full drive PWM, mA.
    pub motor_current_ma: f64,
    /// Pack internal resistance, ohm.
    pub internal_resistance_ohm: f64,
    /// Ambient temperature, degrees C.
    pub ambient_c: f64,
    /// Die temperature rise above ambient with the drive idle, K.
    pub self_heating_k: f64,
    /// Extra die temperature rise at full drive PWM, K.
    pub load_heating_k: f64,
    /// Thermal time constant, s.
    pub thermal_tau_s: f64,
}

impl Default for PowerConfig {
    fn default() -> Self {
        Self {
            capacity_mah: 800.0,
            initial_soc: 1.0,
            base_current_ma: 250.0,
            motor_current_ma: 1500.0,
            internal_resistance_ohm: 0.25,
            ambient_c: 25.0,
            self_heating_k: 10.0,
            load_heating_k: 10.0,
            thermal_tau_s: 30.0,
        }
    }
}

/// What the LBC drives: motor PWM and servo pulse.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Actuators {
    /// Drive PWM, -1..=1 (sign = direction); 0 when the drive is disabled.
    pub duty: f64,
    /// Servo pulse width, us; `None` when the servo is disabled (it holds its position).
    pub servo_pulse_us: Option<f64>,
}

/// One ADC sweep (10-bit counts) plus the die temperature.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AdcSample {
    /// ADC0: yaw gyro.
    pub gyro_yaw: u16,
    /// ADC1: steering linear potentiometer.
    pub steer_lp: u16,
    /// ADC2: range sensor.
    pub range: u16,
    /// ADC3: 1.225 V reference.
    pub reference: u16,
    /// ADC4: roll gyro.
    pub gyro_roll: u16,
    /// ADC5: pitch gyro.
    pub gyro_pitch: u16,
    /// Die temperature, whole degrees C.
    pub chip_temp_c: i16,
}

/// Pose in the arena frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// X (across the 1.5 m width), mm.
    pub x_mm: f64,
    /// Y (along the 2 m length), mm.
    pub y_mm: f64,
    /// Heading, rad, counter-clockwise from +X, in `0..2*PI`.
    pub heading_rad: f64,
}

/// The car's physical state.
#[derive(Debug, Clone)]
pub struct Vehicle {
    cfg: VehicleConfig,
    pose: Pose,
    speed_mm_s: f64,
    steer_rad: f64,
    yaw_rate_rad_s: f64,
    encoder: f64,
    soc: f64,
    temp_c: f64,
    last_duty: f64,
    obstacle_mm: Option<f64>,
}

impl Vehicle {
    /// A car at rest at `pose` with the battery and die at their configured start values.
    pub fn new(cfg: VehicleConfig, pose: Pose) -> Self {
        let soc = cfg.power.initial_soc.clamp(0.0, 1.0);
        let temp_c = cfg.power.ambient_c + cfg.power.self_heating_k;
        Self {
            cfg,
            pose: normalise(pose),
            speed_mm_s: 0.0,
            steer_rad: 0.0,
            yaw_rate_rad_s: 0.0,
            encoder: 0.0,
            soc,
            temp_c,
            last_duty: 0.0,
            obstacle_mm: None,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &VehicleConfig {
        &self.cfg
    }

    /// Current pose (rear-axle midpoint).
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Moves the car (arena placement); speed and steering are kept.
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = normalise(pose);
    }

    /// Forward speed of the rear wheels, mm/s.
    pub fn speed_mm_s(&self) -> f64 {
        self.speed_mm_s
    }

    /// Actual steering angle, rad (+ = left).
    pub fn steer_rad(&self) -> f64 {
        self.steer_rad
    }

    /// Yaw rate, rad/s (counter-clockwise positive).
    pub fn yaw_rate_rad_s(&self) -> f64 {
        self.yaw_rate_rad_s
    }

    /// State of charge, 0..=1.
    pub fn soc(&self) -> f64 {
        self.soc
    }

    /// Sets the state of charge (tests, long-run scenarios).
    pub fn set_soc(&mut self, soc: f64) {
        self.soc = soc.clamp(0.0, 1.0);
    }

    /// Sets the ambient temperature, degrees C.
    pub fn set_ambient_c(&mut self, ambient_c: f64) {
        self.cfg.power.ambient_c = ambient_c;
    }

    /// Die temperature, degrees C.
    pub fn chip_temp_c(&self) -> f64 {
        self.temp_c
    }

    /// Sets the die temperature directly (tests).
    pub fn set_chip_temp_c(&mut self, t: f64) {
        self.temp_c = t;
    }

    /// An obstacle straight ahead of the range sensor at this distance (mm), closer than the
    /// walls; `None` removes it. The arena uses this for other cars.
    pub fn set_obstacle_mm(&mut self, d: Option<f64>) {
        self.obstacle_mm = d;
    }

    /// Battery terminal voltage under the present load, V.
    pub fn battery_v(&self) -> f64 {
        open_circuit_v(self.soc) - self.current_a() * self.cfg.power.internal_resistance_ohm
    }

    fn current_a(&self) -> f64 {
        (self.cfg.power.base_current_ma + self.cfg.power.motor_current_ma * self.last_duty.abs())
            / 1000.0
    }

    /// Encoder position, counts (signed, wraps like a 64-bit hardware counter never will).
    pub fn encoder_count(&self) -> i64 {
        self.encoder.floor() as i64
    }

    /// Advances the physics by `dt_s` seconds (callers keep steps at or below 1 ms).
    pub fn step(&mut self, dt_s: f64, act: Actuators) {
        if dt_s <= 0.0 {
            return;
        }
        let c = &self.cfg;
        let duty = act.duty.clamp(-1.0, 1.0);
        self.last_duty = duty;

        // Servo: slews towards the angle its pulse asks for, within the mechanical limit.
        if let Some(pulse) = act.servo_pulse_us {
            let want = ((pulse - 1500.0 - c.servo_trim_us) / c.servo_us_per_rad)
                .clamp(-c.steer_limit_rad, c.steer_limit_rad);
            let max_step = c.servo_slew_rad_s * dt_s;
            self.steer_rad += (want - self.steer_rad).clamp(-max_step, max_step);
        }

        // Drive: first-order speed response to the effective PWM, scaled by the battery.
        let eff = if duty.abs() > c.stiction_duty {
            duty.signum() * (duty.abs() - c.stiction_duty) / (1.0 - c.stiction_duty)
        } else {
            0.0
        };
        let v_ss = c.max_speed_mm_s * (self.battery_v() / c.nominal_battery_v).max(0.0) * eff;
        let alpha = (dt_s / c.motor_tau_s).min(1.0);
        let v0 = self.speed_mm_s;
        self.speed_mm_s += (v_ss - self.speed_mm_s) * alpha;
        let v = 0.5 * (v0 + self.speed_mm_s);

        // Kinematic bicycle about the rear axle.
        self.yaw_rate_rad_s = v * self.steer_rad.tan() / c.wheelbase_mm;
        let mid_heading = self.pose.heading_rad + 0.5 * self.yaw_rate_rad_s * dt_s;
        self.pose.x_mm += v * mid_heading.cos() * dt_s;
        self.pose.y_mm += v * mid_heading.sin() * dt_s;
        self.pose.heading_rad = wrap_2pi(self.pose.heading_rad + self.yaw_rate_rad_s * dt_s);

        // Encoder on the motor shaft.
        let wheel_revs = v * dt_s / (PI * c.wheel_diameter_mm);
        self.encoder += wheel_revs * c.gear_ratio * c.encoder_cpr;

        // Battery and die temperature.
        let used_mah = self.current_a() * 1000.0 * dt_s / 3600.0;
        self.soc = (self.soc - used_mah / c.power.capacity_mah).max(0.0);
        let p = &c.power;
        let t_ss = p.ambient_c + p.self_heating_k + p.load_heating_k * duty.abs();
        self.temp_c += (t_ss - self.temp_c) * (dt_s / p.thermal_tau_s).min(1.0);
    }

    /// Distance from the range sensor to the nearest wall or obstacle straight ahead, mm.
    pub fn range_mm(&self) -> f64 {
        let c = &self.cfg;
        let (hx, hy) = (self.pose.heading_rad.cos(), self.pose.heading_rad.sin());
        let sx = self.pose.x_mm + hx * c.range_sensor_offset_mm;
        let sy = self.pose.y_mm + hy * c.range_sensor_offset_mm;
        let wall = |p: f64, d: f64, hi: f64| -> f64 {
            if d > 1e-9 {
                (hi - p) / d
            } else if d < -1e-9 {
                -p / d
            } else {
                f64::INFINITY
            }
        };
        let d = wall(sx, hx, c.arena_mm.0)
            .min(wall(sy, hy, c.arena_mm.1))
            .max(0.0);
        match self.obstacle_mm {
            Some(o) => d.min(o.max(0.0)),
            None => d,
        }
    }

    /// One ADC sweep with noise from `rng`.
    pub fn sample_adc(&self, rng: &mut impl Rng) -> AdcSample {
        let s = &self.cfg.sensors;
        let counts_per_v = 1024.0 / s.adc_vref;
        let to_adc = |v: f64| -> u16 { (v * counts_per_v).round().clamp(0.0, 1023.0) as u16 };
        let gyro = |rate_dps: f64, bias_dps: f64, rng: &mut dyn rand::RngCore| -> u16 {
            let noise = gaussian(rng) * s.gyro_noise_dps;
            to_adc(s.gyro_zrl_v + (rate_dps + bias_dps + noise) * s.gyro_v_per_dps)
        };
        let yaw_dps = self.yaw_rate_rad_s.to_degrees();
        let d = self.range_mm().clamp(s.range_span_mm.0, s.range_span_mm.1);
        let range = s.range_offset_counts + s.range_k / d + gaussian(rng) * s.range_noise_counts;
        AdcSample {
            gyro_yaw: gyro(yaw_dps, s.gyro_yaw_bias_dps, rng),
            steer_lp: (s.steer_lp_center + self.steer_rad * s.steer_lp_counts_per_rad)
                .round()
                .clamp(0.0, 1023.0) as u16,
            range: range.round().clamp(0.0, 1023.0) as u16,
            reference: to_adc(s.reference_v),
            gyro_roll: gyro(0.0, 0.0, rng),
            gyro_pitch: gyro(0.0, 0.0, rng),
            chip_temp_c: self.temp_c.round().clamp(-40.0, 150.0) as i16,
        }
    }
}

/// Open-circuit voltage of the 4-cell NiMH pack against state of charge.
pub fn open_circuit_v(soc: f64) -> f64 {
    const CURVE: [(f64, f64); 6] = [
        (0.0, 4.2),
        (0.05, 4.5),
        (0.1, 4.65),
        (0.2, 4.8),
        (0.8, 5.0),
        (1.0, 5.4),
    ];
    let soc = soc.clamp(0.0, 1.0);
    for w in CURVE.windows(2) {
        let ((s0, v0), (s1, v1)) = (w[0], w[1]);
        if soc <= s1 {
            return v0 + (v1 - v0) * (soc - s0) / (s1 - s0);
        }
    }
    CURVE[CURVE.len() - 1].1
}

/// A standard normal sample (Box-Muller).
pub fn gaussian(rng: &mut (impl Rng + ?Sized)) -> f64 {
    let u1: f64 = rng.random::<f64>().max(f64::MIN_POSITIVE);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
}

/// Wraps an angle into `0..2*PI`.
pub fn wrap_2pi(a: f64) -> f64 {
    let r = a.rem_euclid(2.0 * PI);
    if r >= 2.0 * PI {
        0.0
    } else {
        r
    }
}

/// Wraps an angle into `-PI..PI`.
pub fn wrap_pi(a: f64) -> f64 {
    let r = wrap_2pi(a + PI) - PI;
    if r < -PI {
        r + 2.0 * PI
    } else {
        r
    }
}

fn normalise(p: Pose) -> Pose {
    Pose {
        heading_rad: wrap_2pi(p.heading_rad),
        ..p
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn run(v: &mut Vehicle, secs: f64, act: Actuators) {
        let n = (secs * 1000.0).round() as usize;
        for _ in 0..n {
            v.step(0.001, act);
        }
    }

    #[test]
    fn full_pwm_reaches_max_speed_and_encoder_counts_distance() {
        let mut v = Vehicle::new(VehicleConfig::default(), Pose::default());
        v.set_soc(0.5); // plateau: about 4.9 V under load
        run(
            &mut v,
            1.0,
            Actuators {
                duty: 1.0,
                servo_pulse_us: Some(1500.0),
            },
        );
        let expect = 1500.0 * v.battery_v() / 5.0;
        assert!((v.speed_mm_s() - expect).abs() < 5.0, "{}", v.speed_mm_s());
        // Straight along +X: encoder counts match distance travelled.
        let per_mm = 20.0 * 800.0 / (PI * 30.0);
        let got = v.encoder_count() as f64 / per_mm;
        assert!(
            (got - v.pose().x_mm).abs() < 0.1,
            "{got} vs {}",
            v.pose().x_mm
        );
        assert!(v.pose().y_mm.abs() < 1e-6);
    }

    #[test]
    fn stiction_holds_the_car_at_small_pwm() {
        let mut v = Vehicle::new(VehicleConfig::default(), Pose::default());
        run(
            &mut v,
            0.5,
            Actuators {
                duty: 0.04,
                servo_pulse_us: None,
            },
        );
        assert_eq!(v.speed_mm_s(), 0.0);
        assert_eq!(v.encoder_count(), 0);
    }

    #[test]
    fn full_left_lock_turns_on_the_bicycle_radius() {
        let mut v = Vehicle::new(VehicleConfig::default(), Pose::default());
        // 523 us above centre = 0.523 rad left.
        run(
            &mut v,
            0.5,
            Actuators {
                duty: 0.0,
                servo_pulse_us: Some(2100.0),
            },
        );
        assert!(
            (v.steer_rad() - 0.523).abs() < 1e-9,
            "servo clamps to the mechanical limit"
        );
        run(
            &mut v,
            3.0,
            Actuators {
                duty: 0.3,
                servo_pulse_us: Some(2100.0),
            },
        );
        let w = v.yaw_rate_rad_s();
        let r = v.speed_mm_s() / w;
        assert!((r - 80.0 / 0.523f64.tan()).abs() < 0.5, "radius {r}");
        assert!(w > 0.0, "left turn is counter-clockwise");
    }

    #[test]
    fn gyro_reads_zero_rate_level_at_rest_and_moves_with_yaw() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut v = Vehicle::new(VehicleConfig::default(), Pose::default());
        let s = v.sample_adc(&mut rng);
        assert!((511..=513).contains(&s.gyro_yaw), "{}", s.gyro_yaw);
        assert_eq!(s.reference, 418);
        assert_eq!(s.steer_lp, 512);
        run(
            &mut v,
            2.0,
            Actuators {
                duty: 0.5,
                servo_pulse_us: Some(2000.0),
            },
        );
        let s = v.sample_adc(&mut rng);
        assert!(s.gyro_yaw > 530, "{}", s.gyro_yaw);
        assert!(s.steer_lp > 800);
    }

    #[test]
    fn range_sees_the_wall_ahead() {
        let v = Vehicle::new(
            VehicleConfig::default(),
            Pose {
                x_mm: 750.0,
                y_mm: 1000.0,
                heading_rad: PI / 2.0,
            },
        );
        assert!((v.range_mm() - (1000.0 - 95.0)).abs() < 1e-6);
        let mut v = v;
        v.set_obstacle_mm(Some(300.0));
        assert_eq!(v.range_mm(), 300.0);
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let s = v.sample_adc(&mut rng);
        let expect = 26.0 + 165_440.0 / 300.0;
        assert!((f64::from(s.range) - expect).abs() <= 4.0, "{}", s.range);
    }

    #[test]
    fn battery_drains_and_die_warms_under_load() {
        let mut cfg = VehicleConfig::default();
        cfg.power.capacity_mah = 1.0;
        let mut v = Vehicle::new(cfg, Pose::default());
        let v0 = v.battery_v();
        run(
            &mut v,
            2.0,
            Actuators {
                duty: 1.0,
                servo_pulse_us: None,
            },
        );
        assert!(v.battery_v() < v0);
        assert!(v.soc() < 1.0);
        assert!(v.chip_temp_c() > 35.0);
        assert!((open_circuit_v(0.05) - 4.5).abs() < 1e-9);
    }

    #[test]
    fn angle_wrapping() {
        assert!((wrap_2pi(-0.1) - (2.0 * PI - 0.1)).abs() < 1e-12);
        assert!((wrap_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!(wrap_2pi(2.0 * PI) < 1e-12);
    }
}
