//! The program against the emulated LBC (lockstep, simulated time) and a radio-mac ground
//! station on a direct radio pipe: bring-up, the console, MOVE_XY, recovery, corrupt bytes
//! and the user-link watchdog.

mod sim;

use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{
    Command, CommandKind, Duty, EepromAddress, GpioPattern, GpioRate, LedPattern, LedRate, Param,
    ParamValue, Position, Reply as LbcReply, SteerVelocity, SteeringAngle, UserRegister, Velocity,
};
use radio_mac::{
    Address, CarConfig, CarId, CarMac, CarState, Event, GroundConfig, GroundStation, Key, Role,
};
use sim::*;
use ubc_app::program::console::{LbcOutcome, Notice, Point, Points, Refusal, Reply, Request, Tag};
use ubc_app::program::{Config, LogEvent, Phase, Program, DEFAULT_KEY};

#[test]
fn bring_up_completes_and_state_is_broadcast() {
    let mut s = Sim::new();
    s.bring_up();
    s.run_ms(300);
    assert!(s.lbc.drive_enabled());
    assert!(s.lbc.streaming());
    assert_eq!(s.lbc.stream_format(), s.prog.stream_format());
    assert!(s.prog.lbc_stats().stream_frames >= 5);
    // The start pose (750 mm, 1000 mm) in tracking units, via the 30 Hz stream.
    let st = s.status();
    assert_eq!(st.car_id, CAR);
    assert_eq!((st.x, st.y), (300, 400));
    assert_eq!(st.phase, Phase::Running as u8);
    // The ground station hears the car's state broadcast.
    let car = s.ground.cars().next().expect("car heard");
    assert_eq!(car.addr, Address::Car(CarId::new(CAR).unwrap()));
    // Running and heard: green on, red off.
    let (leds, _) = s.lbc.leds();
    assert_eq!(leds[0].duty(), Duty::ON);
    assert_eq!(leds[1].duty(), Duty::OFF);
}

#[test]
fn every_lbc_command_reaches_the_lbc_and_its_answer_returns() {
    let mut s = Sim::new();
    s.bring_up();
    let green = LedPattern::new(LedRate::Blink5Hz, Duty::new(3).unwrap());
    let red = LedPattern::new(LedRate::Dim50Hz, Duty::ON);
    let gpo = GpioPattern::new(GpioRate::Hz10, Duty::new(5).unwrap());
    let reg = UserRegister::new(0x21).unwrap();
    let gain = ParamValue::new(Param::MotorPGain, 17).unwrap();
    let sv = SteerVelocity {
        steering: SteeringAngle::new(0).unwrap(),
        velocity: Velocity::new(0).unwrap(),
    };
    let cmds = [
        Command::ReadId,
        Command::ReadXy,
        Command::ReadSv,
        Command::ReadAy,
        Command::ReadPry,
        Command::ReadBt,
        Command::ReadRs,
        Command::ReadHd,
        Command::ReadSf,
        Command::ReadPar(Param::MotorPGain),
        Command::UpdPar(gain),
        Command::WritLed { green, red },
        Command::WritGpo {
            gpio0: gpo,
            gpio1: gpo,
        },
        Command::WritEp {
            address: reg,
            value: 1234,
        },
        Command::ReadEp(EepromAddress::new(0x21).unwrap()),
        Command::CalbGs,
        Command::CalbSt,
        Command::CalbDm,
        Command::Cmep,
        Command::Rsep,
        Command::MoveSv(sv),
        Command::MoveXy(Position::new(300, 400).unwrap()),
        Command::Stop,
        Command::UpdSf(s.prog.stream_format()),
        Command::Stds,
        Command::Sten,
        Command::Drds,
        Command::Dren,
        Command::Init,
    ];
    let mut kinds = std::collections::HashSet::new();
    for cmd in cmds {
        let o = s.lbc(cmd);
        match &o {
            LbcOutcome::Answer(r) => assert_eq!(r.kind(), cmd.kind(), "{cmd:?}"),
            LbcOutcome::Rejected(k) => assert_eq!(*k, cmd.kind(), "{cmd:?}"),
            other => panic!("{cmd:?}: {other:?}"),
        }
        kinds.insert(cmd.kind());
        match cmd {
            Command::ReadId => {
                assert!(matches!(o, LbcOutcome::Answer(LbcReply::ReadId(id)) if id.get() == CAR))
            }
            Command::ReadXy => assert!(matches!(
                o,
                LbcOutcome::Answer(LbcReply::ReadXy(p)) if (p.x.get(), p.y.get()) == (300, 400)
            )),
            Command::UpdPar(_) => assert_eq!(s.lbc.param(Param::MotorPGain), 17),
            Command::ReadEp(_) => assert!(matches!(
                o,
                LbcOutcome::Answer(LbcReply::ReadEpData { value: 1234, .. })
            )),
            Command::WritLed { .. } => assert_eq!(s.lbc.leds().0, [green, red]),
            Command::WritGpo { .. } => assert_eq!(s.lbc.gpio().0, [gpo, gpo]),
            Command::Drds => assert!(!s.lbc.drive_enabled()),
            Command::Dren => assert!(s.lbc.drive_enabled()),
            Command::Stds => assert!(!s.lbc.streaming()),
            Command::Sten => assert!(s.lbc.streaming()),
            Command::Init => assert!(!s.lbc.drive_enabled() && !s.prog.drive_enabled()),
            _ => {}
        }
    }
    // All 29 commands of Table 3-2.
    assert_eq!(kinds.len(), 29);
    // After the user's INIT the drive is off: the program refuses motion itself.
    let target = Command::MoveXy(Position::new(320, 480).unwrap());
    let before = s.prog.lbc_stats().sent;
    assert_eq!(
        s.request(&Request::Lbc(target)),
        Reply::Refused(Refusal::DriveDisabled)
    );
    assert_eq!(s.prog.lbc_stats().sent, before);
}

#[test]
fn move_xy_brings_the_car_to_the_target() {
    let mut s = Sim::new();
    s.bring_up();
    let o = s.lbc(Command::MoveXy(Position::new(320, 480).unwrap()));
    assert!(matches!(
        o,
        LbcOutcome::Answer(LbcReply::Echo(Command::MoveXy(_)))
    ));
    let near = |s: &Sim| {
        let st = s.prog.status(s.now);
        (i32::from(st.x) - 320).abs() <= 10 && (i32::from(st.y) - 480).abs() <= 10
    };
    assert!(
        s.run_until(20_000, near),
        "status: {:?}",
        s.prog.status(s.now)
    );
    let st = s.status();
    assert!((i32::from(st.x) - 320).abs() <= 10, "{st:?}");
    assert!((i32::from(st.y) - 480).abs() <= 10, "{st:?}");
}

#[test]
fn go_to_points_maneuver_runs_and_reports_done() {
    let mut s = Sim::new();
    s.bring_up();
    let mut pts = Points::new();
    pts.push(Point { x: 300, y: 470 }).unwrap();
    pts.push(Point { x: 340, y: 520 }).unwrap();
    assert_eq!(
        s.request(&Request::ManeuverStart(pts)),
        Reply::ManeuverStarted(2)
    );
    assert!(s.prog.maneuver().active());
    assert!(
        s.run_until(30_000, |s| s.notices.contains(&Notice::ManeuverDone)),
        "status {:?}",
        s.prog.status(s.now)
    );
    let st = s.prog.status(s.now);
    assert!((i32::from(st.x) - 340).abs() <= 14 && (i32::from(st.y) - 520).abs() <= 14);
    // Stopping an idle maneuver is harmless.
    assert_eq!(s.request(&Request::ManeuverStop), Reply::ManeuverStopped);
}

#[test]
fn lbc_reset_mid_run_is_recovered() {
    let mut s = Sim::new();
    s.bring_up();
    s.run_ms(200);
    s.lbc.reset();
    assert!(!s.lbc.streaming());
    assert!(s.run_until(2_000, |s| s.prog.counters().bringups >= 2));
    s.run_ms(300);
    assert_eq!(s.prog.phase(), Phase::Running);
    assert!(s.lbc.drive_enabled() && s.lbc.streaming());
    assert_eq!(s.prog.counters().streams_lost, 1);
    assert_eq!(s.logged(|e| *e == LogEvent::LbcLost), 1);
    assert!(s.notices.contains(&Notice::LbcLost));
    assert!(s.notices.contains(&Notice::LbcRecovered));
    // The red LED shows the past failure for a while.
    assert_eq!(s.lbc.leds().0[1].rate(), LedRate::Blink2Hz);
    // And the car still drives.
    let o = s.lbc(Command::MoveXy(Position::new(310, 450).unwrap()));
    assert!(matches!(o, LbcOutcome::Answer(_)));
}

#[test]
fn silent_lbc_is_retried_with_backoff_until_it_answers() {
    let mut s = Sim::new();
    s.lbc_connected = false;
    s.run_ms(4_000);
    assert_ne!(s.prog.phase(), Phase::Running);
    let failures = s.prog.counters().bringup_failures;
    // Back-off: far fewer attempts than 4 s / one INIT timeout.
    assert!((3..=10).contains(&failures), "{failures}");
    // The radio started with the fallback ID meanwhile; connect the LBC.
    s.lbc_connected = true;
    let t = s.now;
    // The longest back-off (2 s) plus a bring-up with its ten EEPROM steps (about 1 s).
    assert!(s.run_until(4_000, |s| s.prog.phase() == Phase::Running));
    assert!(s.now - t > 1_000_000);
    s.run_ms(100);
    assert_eq!(s.lbc.leds().0[1].rate(), LedRate::Blink2Hz);
    assert!(s.lbc.drive_enabled());
}

#[test]
fn corrupt_bytes_on_both_links_are_counted_and_survived() {
    let mut s = Sim::new();
    s.bring_up();
    s.noise_every = 300;
    s.run_ms(3_000);
    // Garbage between messages on the LBC line as well.
    s.lbc_port
        .rx
        .extend([0x00, 0x13, 0x7F, 0xFF, 0xFF, 0x80, 0x45]);
    // And a broken radio frame (bad COBS/CRC) closed by a delimiter.
    s.radio_port
        .rx
        .extend([0x05, 0x11, 0x22, 0x33, 0x44, 0x55, 0x00]);
    // Console requests still get through (the ground station retries what noise destroys).
    let o = s.lbc(Command::ReadId);
    assert!(matches!(o, LbcOutcome::Answer(LbcReply::ReadId(_))));
    s.noise_every = 0;
    s.run_ms(500);
    assert_eq!(s.prog.phase(), Phase::Running);
    let l = s.prog.lbc_stats();
    let noise = l.deframer.garbage_bytes
        + l.deframer.checksum_errors
        + l.deframer.truncated
        + l.deframer.stray_terminators
        + l.decode_errors
        + l.unexpected;
    assert!(noise > 0, "{l:?}");
    let lost = |r: &radio_mac::Stats| {
        r.rx_cobs + r.rx_checksum + r.rx_too_short + r.rx_malformed + r.rx_version + r.rx_oversize
    };
    let car = s.prog.radio_stats().unwrap();
    let ground = *s.ground.stats();
    assert!(lost(&ground) > 0, "{ground:?}");
    assert!(lost(&car) > 0, "{car:?}");
    // Counters reach the ground too.
    match s.request(&Request::Stats(1)) {
        Reply::Stats { page: 1, values } => assert!(values.iter().skip(1).any(|v| *v > 0)),
        other => panic!("{other:?}"),
    }
}

#[test]
fn loss_of_the_user_link_stops_the_car() {
    let mut s = Sim::new();
    s.bring_up();
    let sv = SteerVelocity {
        steering: SteeringAngle::new(100).unwrap(),
        velocity: Velocity::new(300).unwrap(),
    };
    assert!(matches!(s.lbc(Command::MoveSv(sv)), LbcOutcome::Answer(_)));
    s.run_ms(500);
    assert!(s.lbc.velocity_estimate_mm_s() > 150.0);
    // The ground station goes silent.
    s.ground_on = false;
    s.run_ms(2_500);
    assert!(s.lbc.velocity_estimate_mm_s() > 150.0, "stopped too early");
    s.run_ms(1_500);
    assert_eq!(s.logged(|e| *e == LogEvent::UserLinkLost), 1);
    assert_eq!(s.lbc.targets().0, 0.0);
    s.run_ms(1_000);
    assert!(s.lbc.velocity_estimate_mm_s().abs() < 20.0);
    // Red LED: user link lost.
    assert_eq!(s.lbc.leds().0[1].rate(), LedRate::Blink1Hz);
    // The ground station returns.
    s.ground_on = true;
    let st = s.status();
    assert_ne!(st.flags & ubc_app::program::console::flags::USER_LINK, 0);
    assert_eq!(s.logged(|e| *e == LogEvent::UserLinkRestored), 1);
}

#[test]
fn malformed_and_unauthorised_requests_are_refused() {
    let mut s = Sim::new();
    s.bring_up();
    assert_eq!(
        s.request_raw(Tag::Status as u8, &[9]),
        Reply::Refused(Refusal::UnsupportedVersion)
    );
    assert_eq!(
        s.request_raw(0x33, &[1]),
        Reply::Refused(Refusal::UnknownRequest)
    );
    // A MOVE_XY with a bad checksum inside.
    assert_eq!(
        s.request_raw(
            Tag::Lbc as u8,
            &[1, 0xC1, 0x02, 0x40, 0x03, 0x60, 0x61, 0xFF]
        ),
        Reply::Refused(Refusal::Malformed)
    );
    assert_eq!(
        s.request(&Request::StreamFormat(1 << 5)),
        Reply::Refused(Refusal::BadArgument)
    );
    assert_eq!(
        s.request(&Request::Stats(9)),
        Reply::Refused(Refusal::BadArgument)
    );
    // A ground station with the wrong key is not heard at all.
    let mut bad = GroundStation::new(GroundConfig::new(Key::new([0x55; 16]), 1));
    let mut buf = [0u8; 32];
    let n = Request::Lbc(Command::Drds).encode(&mut buf).unwrap();
    bad.command(s.now, Address::Car(CarId::new(CAR).unwrap()), 1, &buf[..n])
        .unwrap();
    let mut out = [0u8; 128];
    let n = bad.transmit(&mut out);
    s.radio_port.rx.extend(&out[..n]);
    s.run_ms(50);
    assert!(s.lbc.drive_enabled());
    assert!(s.prog.radio_stats().unwrap().auth_bad_mac >= 1);
}

#[test]
fn stream_format_request_adds_variables() {
    let mut s = Sim::new();
    s.bring_up();
    let extra = 1 << 9; // range sensor
    let Reply::StreamFormat(bits) = s.request(&Request::StreamFormat(extra)) else {
        panic!()
    };
    assert_eq!(bits, ubc_app::program::REQUIRED_STREAM | extra);
    assert_eq!(s.lbc.stream_format().bits(), bits);
    s.run_ms(300);
    assert_eq!(s.prog.phase(), Phase::Running);
    assert_eq!(s.prog.counters().streams_lost, 0);
    assert_eq!(s.prog.counters().stream_errors, 0);
    let _ = CommandKind::UpdSf;
}

#[test]
fn battery_and_temperature_warnings_show_on_the_red_led_and_are_reported() {
    let mut s = Sim::new();
    s.bring_up();
    s.lbc.vehicle_mut().set_chip_temp_c(80.0);
    assert!(s.run_until(2_500, |s| s.notices.contains(&Notice::Warnings(1))));
    s.run_ms(100);
    assert_eq!(s.lbc.leds().0[1].rate(), LedRate::Blink5Hz);
    let st = s.status();
    assert_ne!(
        st.flags & ubc_app::program::console::flags::OVER_TEMPERATURE,
        0
    );
    s.lbc.vehicle_mut().set_chip_temp_c(40.0);
    s.lbc.vehicle_mut().set_soc(0.0);
    assert!(s.run_until(2_500, |s| s.notices.contains(&Notice::Warnings(2))));
    s.run_ms(100);
    assert_eq!(s.lbc.leds().0[1].duty(), Duty::ON);
}

#[test]
fn radio_key_provisioned_in_eeprom_is_used() {
    let key = *b"0123456789abcdef";
    let mut image = lbc_emu::EepromImage::factory(CAR);
    for (i, w) in Key::new(key).to_eeprom_words().into_iter().enumerate() {
        assert!(image.set(0x38 + i as u8, w));
    }
    let lbc = Lbc::new(
        LbcConfig::default(),
        image,
        Box::new(lbc_emu::MemoryStore::default()),
    );
    let mut s = Sim::with_lbc(Config::default(), lbc, key);
    s.bring_up();
    assert_eq!(s.status().car_id, CAR);
    // The default key no longer works on this car.
    let mut other = GroundStation::new(GroundConfig::new(Key::new(DEFAULT_KEY), 1));
    let mut buf = [0u8; 32];
    let n = Request::Lbc(Command::Drds).encode(&mut buf).unwrap();
    other
        .command(s.now, Address::Car(CarId::new(CAR).unwrap()), 1, &buf[..n])
        .unwrap();
    let mut out = [0u8; 128];
    let n = other.transmit(&mut out);
    s.radio_port.rx.extend(&out[..n]);
    s.run_ms(50);
    assert!(s.lbc.drive_enabled());
    assert!(s.prog.radio_stats().unwrap().auth_bad_mac >= 1);
}

/// Where the emulated car really is, tracking units.
fn true_pos(s: &Sim) -> (f64, f64) {
    let p = s.lbc.vehicle().pose();
    (p.x_mm / 2.5, p.y_mm / 2.5)
}

#[test]
fn group_goto_drives_there_and_reports_it() {
    let mut s = Sim::new();
    s.bring_up();
    // A waypoint needs a running group maneuver.
    assert_eq!(
        s.request(&Request::GroupWaypoint { x: 10, y: 10 }),
        Reply::Refused(Refusal::NoGroup)
    );
    let stats_before = s.lbc.stats().commands;
    let params = maneuvers::GoTo::params(400, 560, 200).unwrap();
    assert_eq!(s.request(&Request::GroupStart(params)), Reply::GroupStarted);
    assert!(s.prog.group().active());
    let t0 = s.now;
    let arrived = |s: &Sim| s.prog.status(s.now).group_converged;
    assert!(s.run_until(15_000, arrived), "{:?}", s.prog.status(s.now));
    let secs = (s.now - t0) as f64 * 1e-6;
    let (x, y) = true_pos(&s);
    assert!((x - 400.0).hypot(y - 560.0) < 15.0, "at ({x}, {y})");
    // Commands at a bounded rate (the stream runs at 30 Hz; the LED and ping traffic is small).
    let sent = s.lbc.stats().commands - stats_before;
    assert!(
        (sent as f64) < 12.0 * secs + 5.0,
        "{sent} commands in {secs} s"
    );
    let st = s.status();
    assert_eq!(st.group_kind, 4);
    assert_eq!(st.group_phase, 3, "hold: {st:?}");
    assert!(st.group_converged && st.group_error_units <= 8, "{st:?}");
    assert_ne!(st.flags & ubc_app::program::console::flags::MANEUVER, 0);
    s.run_ms(500);
    assert!(s.lbc.velocity_estimate_mm_s().abs() < 10.0);
    // The state broadcast carries the role and phase.
    let car = s.ground.cars().next().expect("car heard");
    let (state, _) = car.state.expect("state heard");
    assert_eq!(state.mode.role, Role::Follower);
    assert_eq!(state.mode.phase, 3);
    assert_eq!(
        s.logged(|e| matches!(e, LogEvent::GroupStarted { kind: 4 })),
        1
    );
    // ManeuverStop ends it.
    assert_eq!(s.request(&Request::ManeuverStop), Reply::ManeuverStopped);
    assert!(!s.prog.group().active());
    assert_eq!(s.status().group_kind, 0);
}

#[test]
fn group_maneuver_avoids_a_neighbour_heard_on_the_radio() {
    let mut s = Sim::new();
    let mut other = CarMac::new(CarConfig::new(CarId::new(3).unwrap()));
    // Car 3 stands 100 units ahead, on the way to the goal.
    other.set_state(CarState {
        x: 300,
        y: 500,
        heading_mrad: 1571,
        velocity_mm_s: 0,
        mode: radio_mac::Mode::default(),
    });
    s.other = Some(other);
    s.bring_up();
    s.run_ms(500);
    let params = maneuvers::GoTo::params(300, 640, 200).unwrap();
    assert_eq!(s.request(&Request::GroupStart(params)), Reply::GroupStarted);
    let mut closest = f64::MAX;
    let mut avoided = false;
    for _ in 0..12_000 {
        s.step();
        let (x, y) = true_pos(&s);
        closest = closest.min((x - 300.0).hypot(y - 500.0));
        avoided |= s.prog.group().status().phase == maneuvers::Phase::Avoid;
    }
    assert!(avoided, "the avoidance never acted");
    // Rear axles; the bodies (centred 16 units ahead) keep further apart than 40 units.
    assert!(closest > 40.0, "came within {closest} units of car 3");
    // And it still gets there.
    let (x, y) = true_pos(&s);
    assert!((x - 300.0).hypot(y - 640.0) < 24.0, "at ({x}, {y})");
}

#[test]
fn group_maneuver_stops_when_the_user_link_or_the_lbc_is_lost() {
    let mut s = Sim::new();
    s.bring_up();
    let far = maneuvers::GoTo::params(300, 750, 250).unwrap();
    assert_eq!(s.request(&Request::GroupStart(far)), Reply::GroupStarted);
    s.run_ms(800);
    assert!(s.lbc.velocity_estimate_mm_s() > 100.0);
    s.ground_on = false;
    s.run_ms(4_500);
    assert!(!s.prog.group().active());
    assert_eq!(s.logged(|e| *e == LogEvent::GroupStopped), 1);
    assert!(s.lbc.velocity_estimate_mm_s().abs() < 20.0);

    s.ground_on = true;
    assert_eq!(s.request(&Request::GroupStart(far)), Reply::GroupStarted);
    s.run_ms(500);
    s.lbc.reset();
    assert!(s.run_until(1_000, |s| !s.prog.group().active()));
    assert_eq!(s.logged(|e| *e == LogEvent::GroupStopped), 2);
    // After the recovery the car stays put until told again.
    assert!(s.run_until(3_000, |s| s.prog.phase() == Phase::Running));
    s.run_ms(1_000);
    assert!(s.lbc.velocity_estimate_mm_s().abs() < 20.0);
    // A manual LBC motion command ends a group maneuver too.
    assert_eq!(s.request(&Request::GroupStart(far)), Reply::GroupStarted);
    s.run_ms(300);
    assert!(matches!(s.lbc(Command::Stop), LbcOutcome::Answer(_)));
    assert!(!s.prog.group().active());
    // So does disabling the drive.
    assert_eq!(s.request(&Request::GroupStart(far)), Reply::GroupStarted);
    assert!(matches!(s.lbc(Command::Drds), LbcOutcome::Answer(_)));
    assert!(!s.prog.group().active());
    assert_eq!(
        s.request(&Request::GroupStart(far)),
        Reply::Refused(Refusal::DriveDisabled)
    );
}

#[test]
fn group_start_of_an_unknown_law_or_an_old_layout_is_refused() {
    let mut s = Sim::new();
    s.bring_up();
    // Version 2, law 200 (not in the registration list), no options, no parameters.
    assert_eq!(
        s.request_raw(Tag::GroupStart as u8, &[2, 200, 0, 0, 0]),
        Reply::Refused(Refusal::UnknownLaw)
    );
    // The version-1 layout (3-bit selector, 6 packed bytes): go-to (300, 600) at 200 mm/s.
    assert_eq!(
        s.request_raw(
            Tag::GroupStart as u8,
            &[1, 0x64, 0x09, 0x4B, 0x64, 0x00, 0x00]
        ),
        Reply::Refused(Refusal::UnsupportedVersion)
    );
    // A known law with a parameter out of range (go-to x = 1024).
    assert_eq!(
        s.request_raw(
            Tag::GroupStart as u8,
            &[2, 4, 0, 0, 0, 0x00, 0x04, 0, 0, 0, 0]
        ),
        Reply::Refused(Refusal::BadArgument)
    );
    assert!(!s.prog.group().active());
}

#[test]
fn group_start_broadcast_reaches_the_car() {
    let mut s = Sim::new();
    s.bring_up();
    // Heard once, so that the user link is up.
    s.status();
    let params = maneuvers::Rendezvous::params(40, 200).unwrap();
    let mut buf = [0u8; 32];
    let n = Request::GroupStart(params).encode(&mut buf).unwrap();
    s.ground
        .command(s.now, Address::Broadcast, Tag::GroupStart as u8, &buf[..n])
        .expect("broadcast");
    assert!(s.run_until(1_000, |s| s.prog.group().active()));
    assert_eq!(s.prog.group().law_id(), params.law());
    // Alone, the car is at its own rendezvous point.
    s.run_ms(200);
    let st = s.status();
    assert_eq!(st.group_kind, 2);
    assert!(st.group_converged, "{st:?}");
}

// ----- security: late LBC, replay after a reboot, forged heartbeats -----------------------

const REAL_KEY: [u8; 16] = *b"provisioned-key!";

/// An LBC whose EEPROM holds `REAL_KEY` in registers 0x38..=0x3F.
fn provisioned_lbc() -> Lbc {
    let mut image = lbc_emu::EepromImage::factory(CAR);
    for (i, w) in Key::new(REAL_KEY).to_eeprom_words().into_iter().enumerate() {
        assert!(image.set(0x38 + i as u8, w));
    }
    Lbc::new(
        LbcConfig::default(),
        image,
        Box::new(lbc_emu::MemoryStore::default()),
    )
}

/// One command from `gs` to car `id`, run until answered or `ms` passed; the reply or `None`.
fn try_command(
    s: &mut Sim,
    gs: &mut GroundStation,
    id: u8,
    req: &Request,
    ms: u64,
) -> Option<Reply> {
    let mut buf = [0u8; 32];
    let n = req.encode(&mut buf).unwrap();
    let h = gs
        .command(
            s.now,
            Address::Car(CarId::new(id).unwrap()),
            req.tag() as u8,
            &buf[..n],
        )
        .unwrap();
    let mut out = [0u8; 256];
    for _ in 0..ms {
        s.step();
        let car_bytes: Vec<u8> = s.radio_port.tx.clone();
        gs.push_rx(s.now, &car_bytes);
        gs.poll(s.now);
        let n = gs.transmit(&mut out);
        s.radio_port.rx.extend(&out[..n]);
        while let Some(ev) = gs.next_event() {
            match ev {
                Event::Reply {
                    handle,
                    tag,
                    payload,
                    ..
                } if handle == h => return Some(Reply::decode(tag, &payload).unwrap()),
                Event::Failed { handle, .. } if handle == h => return None,
                _ => {}
            }
        }
    }
    None
}

#[test]
fn a_late_lbc_leaves_the_car_deaf_to_commands_until_it_answers() {
    // The attacker's ground station has the public default key; the car's own has the key
    // provisioned in its EEPROM, which it cannot read while the LBC is silent.
    let mut s = Sim::with_lbc(Config::default(), provisioned_lbc(), REAL_KEY);
    s.ground_on = false;
    s.lbc_connected = false;
    s.run_ms(5_000);
    assert!(
        s.logged(|e| *e
            == LogEvent::RadioStarted {
                car_id: 126,
                keyed: false
            })
            == 1
    );
    // Bring-up keeps trying, with growing delays.
    let delays: Vec<u32> = s
        .log
        .0
        .iter()
        .filter_map(|(_, e)| match e {
            LogEvent::BringUpFailed { retry_in_ms, .. } => Some(*retry_in_ms),
            _ => None,
        })
        .collect();
    assert!(
        delays.len() >= 3 && delays.windows(2).all(|w| w[0] <= w[1]),
        "{delays:?}"
    );
    assert_eq!(delays.last(), Some(&2_000));
    let mut public = GroundStation::new(GroundConfig::new(Key::new(DEFAULT_KEY), 1));
    let mut real = GroundStation::new(GroundConfig::new(Key::new(REAL_KEY), 1));
    let read_key = Request::Lbc(Command::ReadEp(EepromAddress::new(0x38).unwrap()));
    for gs in [&mut public, &mut real] {
        assert_eq!(try_command(&mut s, gs, 126, &read_key, 2_500), None);
        assert_eq!(try_command(&mut s, gs, 126, &Request::Status, 2_500), None);
    }
    let st = s.prog.radio_stats().unwrap();
    assert!(st.auth_no_key >= 2, "{st:?}");
    assert_eq!(s.prog.counters().console_requests, 0);

    // The LBC answers: the radio restarts as car 7 with the provisioned key.
    s.lbc_connected = true;
    assert!(s.run_until(5_000, |s| s.prog.phase() == Phase::Running));
    assert_eq!(
        s.logged(|e| *e
            == LogEvent::RadioStarted {
                car_id: CAR,
                keyed: true
            }),
        1
    );
    assert_eq!(s.lbc.eeprom().get(ubc_app::program::BOOT_REGISTER), Some(1));
    let mut public = GroundStation::new(GroundConfig::new(Key::new(DEFAULT_KEY), 1));
    assert_eq!(
        try_command(&mut s, &mut public, CAR, &Request::Status, 2_500),
        None
    );
    s.ground_on = true;
    assert!(matches!(s.request(&Request::Status), Reply::Status(st) if st.car_id == CAR));
    // No radio command reads or writes the key or the boot counter.
    let writ = |reg: u8| Command::WritEp {
        address: UserRegister::new(reg).unwrap(),
        value: 0,
    };
    for cmd in [
        Command::ReadEp(EepromAddress::new(0x38).unwrap()),
        Command::ReadEp(EepromAddress::new(0x3F).unwrap()),
        Command::ReadEp(EepromAddress::new(0x37).unwrap()),
        writ(0x3A),
        writ(0x37),
    ] {
        assert_eq!(
            s.request(&Request::Lbc(cmd)),
            Reply::Refused(Refusal::Protected),
            "{cmd:?}"
        );
    }
    assert!(matches!(
        s.lbc(Command::ReadEp(EepromAddress::new(0x36).unwrap())),
        LbcOutcome::Answer(_)
    ));
    assert_eq!(
        s.lbc.eeprom().get(0x3A),
        Some(Key::new(REAL_KEY).to_eeprom_words()[2])
    );
}

#[test]
fn a_command_recorded_before_a_reboot_is_not_executed_after_it() {
    let mut s = Sim::new();
    s.bring_up();
    assert_eq!(s.lbc.eeprom().get(ubc_app::program::BOOT_REGISTER), Some(1));
    let pattern = |d: u8| GpioPattern::new(GpioRate::Hz10, Duty::new(d).unwrap());
    let gpo = |d: u8| Command::WritGpo {
        gpio0: pattern(d),
        gpio1: pattern(d),
    };
    // The ground station sets GPIO pattern 7; a listener records the air.
    let start = s.tape.len();
    assert!(matches!(s.lbc(gpo(7)), LbcOutcome::Answer(_)));
    let recorded = s.tape[start..].to_vec();
    assert!(matches!(s.lbc(gpo(3)), LbcOutcome::Answer(_)));
    assert_eq!(s.lbc.gpio().0[0], pattern(3));

    // The upper board reboots (the LBC keeps running, its EEPROM keeps the boot counter).
    s.prog = Program::new(Config::default());
    s.bring_up();
    assert_eq!(s.lbc.eeprom().get(ubc_app::program::BOOT_REGISTER), Some(2));
    // Replayed while the car waits for its session, then again once the ground station
    // answered its Hello: neither time executed.
    s.radio_port.rx.extend(&recorded);
    s.run_ms(300);
    assert!(s.prog.radio_stats().unwrap().sessions_opened >= 1);
    s.radio_port.rx.extend(&recorded);
    s.run_ms(300);
    assert_ne!(
        s.lbc.gpio().0[0],
        pattern(7),
        "the recorded command ran again"
    );
    let st = s.prog.radio_stats().unwrap();
    assert!(st.auth_replay + st.auth_no_session >= 1, "{st:?}");
    // The ground station goes on as before.
    assert!(matches!(s.lbc(gpo(5)), LbcOutcome::Answer(_)));
    assert_eq!(s.lbc.gpio().0[0], pattern(5));
}

/// Raw bytes on air for `frame` (radio-mac refuses to encode a plain ground heartbeat, so that
/// one is built by hand).
fn plain_ground_heartbeat() -> Vec<u8> {
    let body = [
        (radio_mac::wire::VERSION << 5) | 2,
        0x00,
        0x00,
        0x00,
        0x10,
        0x00,
    ];
    let mut raw = body.to_vec();
    raw.extend_from_slice(&radio_mac::wire::CRC16.checksum(&body).to_le_bytes());
    // COBS by hand: zeros at 1, 2, 3 and 5.
    let mut enc = Vec::new();
    let mut block = Vec::new();
    for b in raw {
        if b == 0 {
            enc.push(block.len() as u8 + 1);
            enc.append(&mut block);
        } else {
            block.push(b);
        }
    }
    enc.push(block.len() as u8 + 1);
    enc.append(&mut block);
    enc.push(0);
    enc
}

#[test]
fn forged_replayed_or_foreign_heartbeats_do_not_keep_the_user_link() {
    let mut s = Sim::new();
    s.bring_up();
    let sv = SteerVelocity {
        steering: SteeringAngle::new(0).unwrap(),
        velocity: Velocity::new(300).unwrap(),
    };
    assert!(matches!(s.lbc(Command::MoveSv(sv)), LbcOutcome::Answer(_)));
    s.run_ms(2_500);
    // What a listener recorded: among it, the ground station's heartbeats.
    let mut d = radio_mac::Deframer::new();
    let beats: Vec<radio_mac::Frame> = s
        .tape
        .iter()
        .filter_map(|b| d.push(*b))
        .filter_map(Result::ok)
        .filter(|f| matches!(f, radio_mac::Frame::GroundBeat { .. }))
        .collect();
    assert!(beats.len() >= 2, "{beats:?}");
    let heard = s.logged(|e| *e == LogEvent::UserLinkLost);
    assert_eq!(heard, 0);
    // The ground station goes silent; the attacker keeps sending heartbeats in its name.
    s.ground_on = false;
    for i in 0..10u32 {
        let beat = 1_000_000 + i;
        s.radio_port.rx.extend(plain_ground_heartbeat());
        for f in &beats {
            s.radio_port
                .rx
                .extend(radio_mac::wire::encode_frame(f).unwrap());
        }
        // Another testbed's ground station (another key), and ours in an old epoch.
        for (key, epoch) in [
            ([0x33u8; 16], s.ground.epoch()),
            (DEFAULT_KEY, s.ground.epoch() ^ 7),
        ] {
            let mut f = radio_mac::Frame::GroundBeat {
                epoch,
                beat,
                mac: [0; 8],
            };
            radio_mac::auth::sign(&Key::new(key), 0, &mut f).unwrap();
            s.radio_port
                .rx
                .extend(radio_mac::wire::encode_frame(&f).unwrap());
        }
        s.run_ms(500);
        if i == 2 {
            // Less than the 3 s timeout since the ground station was last heard.
            assert!(s.lbc.velocity_estimate_mm_s() > 150.0, "stopped too early");
        }
    }
    assert_eq!(s.logged(|e| *e == LogEvent::UserLinkLost), 1);
    assert!(s.lbc.velocity_estimate_mm_s().abs() < 20.0);
    let st = s.prog.radio_stats().unwrap();
    assert!(
        st.auth_replay >= 10 && st.auth_bad_mac >= 10 && st.rx_malformed >= 10,
        "{st:?}"
    );
    // The real ground station is heard again.
    s.ground_on = true;
    s.run_ms(1_500);
    assert_eq!(s.logged(|e| *e == LogEvent::UserLinkRestored), 1);
}

/// A clock that moves on by `step` microseconds at every reading (a poll that takes time).
struct SlowClock {
    t: std::cell::Cell<u64>,
    step: u64,
}

impl ubc_app::program::Clock for SlowClock {
    fn now_us(&self) -> u64 {
        let t = self.t.get();
        self.t.set(t + self.step);
        t
    }
}

/// A radio port holding whole frames, each read on its own with its arrival time; records
/// how many were still unread when the program first wrote.
struct FramePort {
    frames: std::collections::VecDeque<Vec<u8>>,
    arrived: u64,
    tx: Vec<u8>,
    unread_at_first_write: Option<usize>,
}

impl ubc_app::program::BytePort for FramePort {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        self.read_frame(buf).0
    }

    fn read_frame(&mut self, buf: &mut [u8]) -> (usize, Option<u64>) {
        match self.frames.pop_front() {
            Some(f) => {
                buf[..f.len()].copy_from_slice(&f);
                (f.len(), Some(self.arrived))
            }
            None => (0, None),
        }
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        self.unread_at_first_write.get_or_insert(self.frames.len());
        self.tx.extend_from_slice(bytes);
        bytes.len()
    }
}

#[test]
fn a_state_broadcast_due_during_a_long_poll_leaves_on_time() {
    let mut s = Sim::new();
    s.bring_up();
    s.run_ms(300);
    // Up to about a millisecond before the car's next state broadcast is due.
    let due = loop {
        s.step();
        let due = s
            .prog
            .next_state_due(s.now)
            .expect("the car broadcasts its state");
        if (600..1_600).contains(&(due - s.now)) {
            break due;
        }
    };
    // A poll with twelve radio frames waiting (other cars' heartbeats, which leave the slot
    // schedule alone), each taking 150 us to handle.
    let frames = (1..=12u8)
        .map(|id| {
            let mut buf = [0u8; 64];
            let n = radio_mac::wire::Frame::Heartbeat {
                src: Address::Car(CarId::new(id + 20).unwrap()),
                beat: radio_mac::wire::Heartbeat::default(),
            }
            .encode(&mut buf)
            .unwrap();
            buf[..n].to_vec()
        })
        .collect();
    let mut radio = FramePort {
        frames,
        arrived: s.now,
        tx: Vec::new(),
        unread_at_first_write: None,
    };
    let clock = SlowClock {
        t: std::cell::Cell::new(s.now),
        step: 150,
    };
    let sent = s.prog.radio_stats().unwrap().states_sent;
    s.prog.poll(&clock, &mut s.lbc_port, &mut radio, &mut s.log);
    assert_eq!(s.prog.radio_stats().unwrap().states_sent, sent + 1);
    // It went out between the frames, not after all of them.
    let unread = radio.unread_at_first_write.expect("written");
    assert!(unread > 0, "written only after every frame was handled");
    // At most one frame's handling (one clock step) after it fell due.
    assert!(clock.t.get() > due);
    let frames_read = 12 - unread;
    assert!(frames_read <= 8, "{frames_read} frames handled first");
}
