//! The firmware's periodic tasks (seed Table 2-2) and what they compute.

use super::*;

impl Lbc {
    pub(super) fn p(&self, p: Param) -> i16 {
        self.param(p)
    }

    pub(super) fn task_velocity_control(&mut self) {
        if !self.fw.drive_enabled {
            self.fw.pid = VelocityPid::default();
            self.fw.duty_permille = 0.0;
            return;
        }
        if let Some(Calibration::Drive { duty, start_count }) = self.fw.calibration {
            let moved = (self.vehicle.encoder_count() - start_count).abs();
            if moved >= 3 {
                let db = duty.round().clamp(0.0, 1000.0) as i16;
                self.fw.params[usize::from(Param::MotorDeadBand.number() - 1)] = db;
                self.fw.calibration = None;
                self.fw.duty_permille = 0.0;
                self.reply(Reply::Echo(Command::CalbDm));
            } else if duty > 300.0 {
                self.fw.calibration = None;
                self.fw.duty_permille = 0.0;
                self.error(CommandKind::CalbDm);
            } else {
                self.fw.duty_permille = duty;
                self.fw.calibration = Some(Calibration::Drive {
                    duty: duty + 0.5,
                    start_count,
                });
            }
            return;
        }
        let gains = MotorGains {
            kp: f64::from(self.p(Param::MotorPGain)),
            ki: f64::from(self.p(Param::MotorIGain)),
            kd: f64::from(self.p(Param::MotorDGain)),
            dead_band: f64::from(self.p(Param::MotorDeadBand)),
        };
        let est = self.fw.estimator.estimate_mm_s();
        self.fw.duty_permille = self.fw.pid.step(self.fw.target_v, est, gains);
    }

    pub(super) fn task_velocity_estimation(&mut self) {
        let mpc = mm_per_count(
            self.p(Param::MotorEncoderRatio),
            self.p(Param::MotorGearRatio),
        );
        let count = self.vehicle.encoder_count();
        self.fw.estimator.update(count, mpc);
    }

    pub(super) fn task_tracking(&mut self) {
        let now = self.now_us;
        if let Some(e) = self.fresh_external() {
            self.fw.tracked = Some(e);
            self.fw.pose_source = PoseSource::External;
        } else if self.cfg.tracking.fallback_to_model {
            if self.fw.pose_source != PoseSource::Model || now >= self.fw.next_model_fix_us {
                self.fw.tracked = Some(model_fix(&self.vehicle, now));
                self.fw.next_model_fix_us = now + MODEL_TRACKING_PERIOD_US;
            }
            self.fw.pose_source = PoseSource::Model;
        } else {
            self.fw.tracked = None;
            self.fw.pose_source = PoseSource::None;
        }
    }

    /// Angular rate, rad/s, of a gyro reading (counts above the reference), using the zero-rate
    /// level (in 1/16 counts) and sensitivity (uV per deg/s) in calibration registers.
    pub(super) fn gyro_rate_rad_s(&self, raw_counts: f64, offset_reg: u8, gain_reg: u8) -> f64 {
        let offset = f64::from(self.calibration_register(offset_reg).unwrap_or(0) as i16) / 16.0;
        let gain_uv = f64::from(self.calibration_register(gain_reg).unwrap_or(1).max(1));
        let volts = (raw_counts - offset) * self.cfg.vehicle.sensors.adc_vref / 1024.0;
        (volts / (gain_uv * 1e-6)).to_radians()
    }

    pub(super) fn task_adc(&mut self) {
        let s = self.vehicle.sample_adc(&mut self.noise);
        self.fw.adc = s;
        let raw_yaw = f64::from(s.gyro_yaw) - f64::from(s.reference);
        let omega = self.gyro_rate_rad_s(raw_yaw, reg::GYO, reg::GYG);
        // Seed 2.1.5: theta_k = T/2 * (w_k + w_{k-1}), T = 2 ms.
        if let Some(prev) = self.fw.prev_omega {
            self.fw.yaw_rad = wrap_2pi(self.fw.yaw_rad + 0.5 * 2e-3 * (omega + prev));
        }
        self.fw.prev_omega = Some(omega);

        if let Some(Calibration::Gyro { n, mut sums }) = self.fw.calibration {
            if self.fw.estimator.estimate_mm_s().abs() > STANDSTILL_MM_S {
                self.fw.calibration = None;
                self.error(CommandKind::CalbGs);
                return;
            }
            let r = f64::from(s.reference);
            sums[0] += (f64::from(s.gyro_pitch) - r) * 16.0;
            sums[1] += (f64::from(s.gyro_roll) - r) * 16.0;
            sums[2] += (f64::from(s.gyro_yaw) - r) * 16.0;
            let n = n + 1;
            if n < GYRO_CAL_SAMPLES {
                self.fw.calibration = Some(Calibration::Gyro { n, sums });
                return;
            }
            let mean = |x: f64| (x / f64::from(n)).round().clamp(-8192.0, 8191.0) as i16;
            let (p, r, y) = (mean(sums[0]), mean(sums[1]), mean(sums[2]));
            self.fw.calib[calib_index(reg::GPO)] = p as u16;
            self.fw.calib[calib_index(reg::GRO)] = r as u16;
            self.fw.calib[calib_index(reg::GYO)] = y as u16;
            self.fw.prev_omega = None;
            self.fw.calibration = None;
            self.reply(Reply::CalbGs(GyroOffsets {
                pitch: I14::from_bits(p as u16 as u32),
                roll: I14::from_bits(r as u16 as u32),
                yaw: Some(I14::from_bits(y as u16 as u32)),
            }));
        }
    }

    pub(super) fn task_path(&mut self) {
        if let Some(Calibration::Steering {
            second,
            until_us,
            first_mrad,
        }) = self.fw.calibration
        {
            self.fw.target_v = 0.0;
            if self.now_us < until_us {
                return;
            }
            let measured = steer_from_lp(self.fw.adc.steer_lp);
            if !second {
                self.fw.servo_pulse_us = control::SERVO_CENTER_US + STEER_CAL_STEP_US;
                self.fw.calibration = Some(Calibration::Steering {
                    second: true,
                    until_us: self.now_us + STEER_CAL_SETTLE_US,
                    first_mrad: measured,
                });
                return;
            }
            self.fw.calibration = None;
            let span = measured - first_mrad;
            if span.abs() < 50.0 {
                self.error(CommandKind::CalbSt);
                return;
            }
            // Pulses were 1500 -/+ step: gain in us per rad, offset = pulse at 0 rad - 1500.
            let gain = 2.0 * STEER_CAL_STEP_US / (span / 1000.0);
            let p0 = control::SERVO_CENTER_US - STEER_CAL_STEP_US - gain * first_mrad / 1000.0;
            let offset = (p0 - control::SERVO_CENTER_US).round().clamp(-500.0, 500.0) as i16;
            let gain = gain.round().clamp(-8192.0, 8191.0) as i16;
            if gain == 0 {
                self.error(CommandKind::CalbSt);
                return;
            }
            self.fw.params[usize::from(Param::ServoOffset.number() - 1)] = offset;
            self.fw.params[usize::from(Param::ServoGain.number() - 1)] = gain;
            self.fw.target_steer_mrad = 0.0;
            self.fw.servo_pulse_us = servo_pulse_us(0.0, offset, gain);
            self.reply(Reply::CalbSt(SteeringCalibration {
                offset: I14::from_bits(offset as u16 as u32),
                gain: I14::from_bits(gain as u16 as u32),
            }));
            return;
        }
        if matches!(self.fw.calibration, Some(Calibration::Drive { .. })) {
            return;
        }
        self.fw.target_bearing = None;
        match self.fw.motion {
            Motion::Idle => {
                self.fw.target_v = 0.0;
            }
            Motion::Velocity { steer_mrad, v_mm_s } => {
                self.fw.target_v = v_mm_s;
                self.fw.target_steer_mrad = steer_mrad;
            }
            Motion::GoTo {
                target,
                mut phase,
                arrived,
            } => {
                let Some(fix) = self.fw.tracked else {
                    self.fw.target_v = 0.0;
                    return;
                };
                let tgt = (
                    f64::from(target.x.get()) * 2.5,
                    f64::from(target.y.get()) * 2.5,
                );
                let pos = (fix.x_units * 2.5, fix.y_units * 2.5);
                if arrived {
                    self.fw.target_v = 0.0;
                    self.fw.target_bearing = Some(wrap_2pi((tgt.1 - pos.1).atan2(tgt.0 - pos.0)));
                } else {
                    let step = path_step(pos, fix.heading_rad, tgt, &mut phase, &self.cfg.path);
                    self.fw.target_v = step.velocity_mm_s;
                    self.fw.target_steer_mrad = step.steer_mrad;
                    self.fw.target_bearing = Some(step.bearing_rad);
                    self.fw.motion = Motion::GoTo {
                        target,
                        phase,
                        arrived: step.arrived,
                    };
                }
            }
        }
        let pulse = servo_pulse_us(
            self.fw.target_steer_mrad,
            self.p(Param::ServoOffset),
            self.p(Param::ServoGain),
        );
        let dead_band = f64::from(self.p(Param::ServoDeadBand));
        if (pulse - self.fw.servo_pulse_us).abs() >= dead_band {
            self.fw.servo_pulse_us = pulse;
        }
    }

    pub(super) fn task_comm_parser(&mut self) {
        self.parse_rx(self.now_us);
    }

    /// Parses the received bytes that arrived by `until_us`.
    pub(super) fn parse_rx(&mut self, until_us: u64) {
        while let Some(&(t, b)) = self.rx.front() {
            if t > until_us {
                break;
            }
            self.rx.pop_front();
            match self.parser.push(b) {
                None => {}
                Some(Incoming::Command(cmd)) => {
                    self.stats.commands += 1;
                    self.log(LogEvent::Command(cmd));
                    self.execute(cmd);
                }
                Some(Incoming::Respond(msg)) => {
                    self.log(LogEvent::Rejected(msg.clone()));
                    self.send(msg);
                }
                Some(Incoming::Ignore(why)) => self.log(LogEvent::Ignored(why)),
            }
        }
    }

    pub(super) fn task_eeprom(&mut self) {
        while let Some(job) = self.fw.eeprom_jobs.pop_front() {
            match job {
                EepromJob::Write(cmd) => {
                    let Command::WritEp { address, value } = cmd else {
                        continue;
                    };
                    let mut next = self.image;
                    next.set(address.get(), value);
                    match self.store.commit(&next) {
                        Ok(()) => {
                            self.image = next;
                            self.reply(Reply::Echo(cmd));
                        }
                        Err(_) => self.error(CommandKind::WritEp),
                    }
                }
                EepromJob::Read(address) => match self.image.get(address.get()) {
                    Some(value) => self.reply(Reply::ReadEpData { address, value }),
                    None => self.error(CommandKind::ReadEp),
                },
                EepromJob::Commit => {
                    let mut next = self.image;
                    for p in Param::ALL {
                        next.set(p.eeprom_address().get(), self.param(p) as u16);
                    }
                    for (i, v) in self.fw.calib.iter().enumerate() {
                        next.set(reg::GPO + i as u8, *v);
                    }
                    match self.store.commit(&next) {
                        Ok(()) => {
                            self.image = next;
                            self.reply(Reply::Echo(Command::Cmep));
                        }
                        Err(_) => self.error(CommandKind::Cmep),
                    }
                }
                EepromJob::Restore => match params_from_image(&self.image) {
                    Some((params, calib)) => {
                        self.fw.params = params;
                        self.fw.calib = calib;
                        self.reply(Reply::Echo(Command::Rsep));
                    }
                    None => self.error(CommandKind::Rsep),
                },
            }
        }
    }

    pub(super) fn task_comm_merger(&mut self) {
        while let Some(msg) = self.outbox.pop_front() {
            if self.faults.suppress() {
                if !matches!(msg, LbcMessage::Stream(_)) {
                    self.log(LogEvent::Suppressed(msg));
                }
                continue;
            }
            let mut buf = [0u8; MAX_FRAME_LEN];
            let Ok(n) = msg.emit(&mut buf) else {
                continue;
            };
            let mut bytes = Vec::with_capacity(n);
            for &b in &buf[..n] {
                if let Some(b) = self.faults.byte(b) {
                    bytes.push(b);
                }
            }
            let ready = self.now_us + self.faults.delay_us();
            // A message the UART queue cannot take is dropped whole and counted there.
            let queued = self.uart.push_message(ready, &bytes);
            if queued && !matches!(msg, LbcMessage::Stream(_)) {
                self.log(LogEvent::Sent(msg));
            }
        }
    }

    pub(super) fn task_streaming(&mut self) {
        if !self.fw.stream_on {
            return;
        }
        let sample = self.stream_sample();
        let mut buf = [0u8; MAX_FRAME_LEN];
        if let Ok(n) = sample.emit(self.fw.stream_format, &mut buf) {
            let mut data = heapless::Vec::new();
            if data.extend_from_slice(&buf[1..n - 2]).is_ok() {
                self.send(LbcMessage::Stream(StreamData(data)));
            }
        }
    }

    pub(super) fn task_monitor(&mut self) {
        self.fw.warnings = Warnings {
            battery_low: self.vehicle.battery_v() < BATTERY_WARN_V,
            over_temperature: self.vehicle.chip_temp_c() > TEMP_WARN_C,
        };
    }

    pub(super) fn task_led(&mut self) {
        let t = self.now_us - self.fw.pattern_epoch_us;
        for i in 0..2 {
            let p = self.fw.leds[i];
            self.fw.led_out[i] = pattern_level(t, u64::from(p.rate().hz()), p.duty().tenths());
        }
    }

    pub(super) fn task_gpio(&mut self) {
        let t = self.now_us - self.fw.pattern_epoch_us;
        for i in 0..2 {
            let p = self.fw.gpio[i];
            self.fw.gpio_out[i] = pattern_level(t, u64::from(p.rate().hz()), p.duty().tenths());
        }
    }

    pub(super) fn position(&self) -> Option<Position> {
        let t = self.fw.tracked?;
        Some(Position {
            x: clamp_x(t.x_units),
            y: clamp_y(t.y_units),
        })
    }

    pub(super) fn measured_steer_velocity(&self) -> SteerVelocity {
        SteerVelocity {
            steering: steering(steer_from_lp(self.fw.adc.steer_lp)),
            velocity: velocity(self.fw.estimator.estimate_mm_s()),
        }
    }

    pub(super) fn gyro_raw(&self) -> GyroRaw {
        let r = i32::from(self.fw.adc.reference);
        let d = |v: u16| i14(f64::from(i32::from(v) - r));
        GyroRaw {
            pitch: d(self.fw.adc.gyro_pitch),
            roll: d(self.fw.adc.gyro_roll),
            yaw: d(self.fw.adc.gyro_yaw),
        }
    }

    pub(super) fn stream_sample(&self) -> StreamSample {
        let fw = &self.fw;
        let pos = self.position();
        let tracked_heading = fw.tracked.map(|t| heading(t.heading_rad));
        let target_position = match fw.motion {
            Motion::GoTo { target, .. } => Some(target),
            _ => pos,
        };
        let target_yaw = fw.target_bearing.map(heading).or(tracked_heading);
        let gyro = self.gyro_raw();
        let zero_pos = Position {
            x: clamp_x(0.0),
            y: clamp_y(0.0),
        };
        let mut user = [None; 6];
        for (slot, v) in user.iter_mut().zip(self.user_vars) {
            *slot = Some(u14(v));
        }
        StreamSample {
            id: Some(u14(u16::from(fw.car_id))),
            position: Some(pos.unwrap_or(zero_pos)),
            steer_velocity: Some(self.measured_steer_velocity()),
            adjusted_yaw: Some(heading(fw.yaw_rad)),
            heading: Some(tracked_heading.unwrap_or(heading(0.0))),
            adc_steering: Some(u14(fw.adc.steer_lp)),
            adc_range: Some(u14(fw.adc.range)),
            adc_gyro_reference: Some(u14(fw.adc.reference)),
            adc_gyro_pitch: Some(gyro.pitch),
            adc_gyro_roll: Some(gyro.roll),
            adc_gyro_yaw: Some(gyro.yaw),
            chip_status: Some(ChipStatus {
                temperature: ChipTemperature::new(fw.adc.chip_temp_c.clamp(0, 127) as u8)
                    .unwrap_or(TEMP0),
                warnings: fw.warnings,
            }),
            target_position: Some(target_position.unwrap_or(zero_pos)),
            target_steer_velocity: Some(SteerVelocity {
                steering: steering(fw.target_steer_mrad),
                velocity: velocity(fw.target_v),
            }),
            target_yaw: Some(target_yaw.unwrap_or(heading(0.0))),
            motor_p_error: Some(i14(fw.pid.error)),
            motor_d_error: Some(i14(fw.pid.d_error)),
            motor_i_error: Some(i28(fw.pid.integral * 1000.0)),
            user,
        }
    }
}

pub(super) fn pattern_level(t_us: u64, hz: u64, tenths: u8) -> bool {
    match tenths {
        0 => false,
        10.. => true,
        d => {
            let period = 1_000_000 / hz.max(1);
            (t_us % period) * 10 < period * u64::from(d)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::pattern_level;

    #[test]
    fn pattern_levels() {
        // 2 Hz, 50 %: high for the first 250 ms of each 500 ms period.
        assert!(pattern_level(0, 2, 5));
        assert!(pattern_level(249_999, 2, 5));
        assert!(!pattern_level(250_000, 2, 5));
        assert!(pattern_level(500_000, 2, 5));
        assert!(!pattern_level(123, 100, 0));
        assert!(pattern_level(9_999, 100, 10));
        // 30 Hz, 10 %: 3.33 ms high in 33.33 ms.
        assert!(pattern_level(3_000, 30, 1));
        assert!(!pattern_level(3_400, 30, 1));
    }
}
