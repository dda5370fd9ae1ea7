//! The COMM parser's command execution (seed 3.4) and the EEPROM job queue.

use super::*;

impl Lbc {
    pub(super) fn motion_allowed(&self) -> bool {
        self.fw.drive_enabled && self.fw.calibration.is_none()
    }

    pub(super) fn abort_calibration(&mut self) {
        if let Some(c) = self.fw.calibration.take() {
            self.error(c.kind());
        }
    }

    pub(super) fn stationary(&self) -> bool {
        self.fw.estimator.estimate_mm_s().abs() <= STANDSTILL_MM_S && self.fw.target_v == 0.0
    }

    pub(super) fn execute(&mut self, cmd: Command) {
        use Command as C;
        let echo = Reply::Echo(cmd);
        match cmd {
            C::Stop => {
                self.abort_calibration();
                self.fw.motion = Motion::Idle;
                self.fw.target_v = 0.0;
                self.reply(echo);
            }
            C::MoveXy(target) => {
                if self.motion_allowed() {
                    self.fw.motion = Motion::GoTo {
                        target,
                        phase: PathPhase::default(),
                        arrived: false,
                    };
                    self.reply(echo);
                } else {
                    self.error(cmd.kind());
                }
            }
            C::MoveSv(sv) => {
                if self.motion_allowed() && sv.velocity.get().abs() <= VELOCITY_LIMIT_MM_S {
                    self.fw.motion = Motion::Velocity {
                        steer_mrad: f64::from(sv.steering.get()),
                        v_mm_s: f64::from(sv.velocity.get()),
                    };
                    self.reply(echo);
                } else {
                    self.error(cmd.kind());
                }
            }
            C::CalbSt | C::CalbDm | C::CalbGs => {
                let needs_drive = !matches!(cmd, C::CalbGs);
                let ok = self.fw.calibration.is_none()
                    && self.stationary()
                    && (!needs_drive || self.fw.drive_enabled);
                if !ok {
                    self.error(cmd.kind());
                    return;
                }
                self.fw.motion = Motion::Idle;
                self.fw.calibration = Some(match cmd {
                    C::CalbSt => {
                        self.fw.servo_pulse_us = control::SERVO_CENTER_US - STEER_CAL_STEP_US;
                        Calibration::Steering {
                            second: false,
                            until_us: self.now_us + STEER_CAL_SETTLE_US,
                            first_mrad: 0.0,
                        }
                    }
                    C::CalbDm => Calibration::Drive {
                        duty: 0.0,
                        start_count: self.vehicle.encoder_count(),
                    },
                    _ => Calibration::Gyro {
                        n: 0,
                        sums: [0.0; 3],
                    },
                });
            }
            C::WritEp { .. } => self.queue_eeprom(EepromJob::Write(cmd), cmd.kind()),
            C::ReadEp(addr) => {
                if !addr.is_user() || self.fw.eeprom_jobs.len() >= EEPROM_QUEUE {
                    self.error(cmd.kind());
                } else {
                    self.reply(echo);
                    self.fw.eeprom_jobs.push_back(EepromJob::Read(addr));
                }
            }
            C::WritLed { green, red } => {
                self.fw.leds = [green, red];
                self.fw.pattern_epoch_us = self.now_us;
                self.reply(echo);
            }
            C::WritGpo { gpio0, gpio1 } => {
                self.fw.gpio = [gpio0, gpio1];
                self.fw.pattern_epoch_us = self.now_us;
                self.reply(echo);
            }
            C::Init => {
                self.boot_firmware();
                self.reply(echo);
            }
            C::Cmep => self.queue_eeprom(EepromJob::Commit, cmd.kind()),
            C::Rsep => self.queue_eeprom(EepromJob::Restore, cmd.kind()),
            C::Drds => {
                self.abort_calibration();
                self.fw.drive_enabled = false;
                self.fw.motion = Motion::Idle;
                self.fw.target_v = 0.0;
                self.reply(echo);
            }
            C::Dren => {
                self.fw.drive_enabled = true;
                self.reply(echo);
            }
            C::Stds => {
                self.fw.stream_on = false;
                self.reply(echo);
            }
            C::Sten => {
                if self.fw.stream_format == StreamFormat::EMPTY {
                    self.error(cmd.kind());
                } else {
                    self.fw.stream_on = true;
                    self.reply(echo);
                }
            }
            C::ReadId => {
                let id = VehicleId::new(self.fw.car_id & 0x7F).unwrap_or(ID0);
                self.reply(Reply::ReadId(id));
            }
            C::ReadXy => match self.position() {
                Some(p) => self.reply(Reply::ReadXy(p)),
                None => self.error(cmd.kind()),
            },
            C::ReadSv => {
                let sv = self.measured_steer_velocity();
                self.reply(Reply::ReadSv(sv));
            }
            C::ReadAy => {
                let y = heading(self.fw.yaw_rad);
                self.reply(Reply::ReadAy(y));
            }
            C::ReadPry => {
                let g = self.gyro_raw();
                self.reply(Reply::ReadPry(g));
            }
            C::ReadBt => self.reply(Reply::ReadBt(self.fw.warnings)),
            C::ReadRs => self.reply(Reply::ReadRs(u14(self.fw.adc.range))),
            C::ReadHd => match self.fw.tracked {
                Some(t) => self.reply(Reply::ReadHd(heading(t.heading_rad))),
                None => self.error(cmd.kind()),
            },
            C::ReadSf => self.reply(Reply::ReadSf(self.fw.stream_format)),
            C::UpdSf(f) => {
                self.fw.stream_format = f;
                if f == StreamFormat::EMPTY {
                    self.fw.stream_on = false;
                }
                self.reply(echo);
            }
            C::ReadPar(p) => match ParamValue::new(p, self.param(p)) {
                Ok(v) => self.reply(Reply::ReadPar(v)),
                Err(_) => self.error(cmd.kind()),
            },
            C::UpdPar(v) => {
                if param_valid(v.param(), v.value()) {
                    self.fw.params[usize::from(v.param().number() - 1)] = v.value();
                    self.reply(echo);
                } else {
                    self.error(cmd.kind());
                }
            }
        }
    }

    pub(super) fn queue_eeprom(&mut self, job: EepromJob, kind: CommandKind) {
        if self.fw.eeprom_jobs.len() >= EEPROM_QUEUE {
            self.error(kind);
        } else {
            self.fw.eeprom_jobs.push_back(job);
        }
    }
}
