//! Every command of seed Table 3-2 through lbc-link's UBC client, in simulated time.

mod common;

use common::{decode_all, frame, Bench};
use lbc_emu::eeprom::reg;
use lbc_emu::{LbcConfig, VehicleConfig};
use lbc_link::client::Failure;
use lbc_link::{
    Command, CommandKind, Duty, EepromAddress, GpioPattern, GpioRate, LbcMessage, LedPattern,
    LedRate, Param, ParamValue, Position, Reply, SteerVelocity, SteeringAngle, StreamFormat,
    UserRegister, VehicleId, Velocity,
};

fn sv(steer: i16, v: i16) -> SteerVelocity {
    SteerVelocity {
        steering: SteeringAngle::new(steer).unwrap(),
        velocity: Velocity::new(v).unwrap(),
    }
}

fn pv(p: Param, v: i16) -> ParamValue {
    ParamValue::new(p, v).unwrap()
}

#[test]
fn identity_init_and_drive_gating() {
    let mut b = Bench::new(LbcConfig::default());
    assert_eq!(
        b.request(Command::ReadId),
        Ok(Reply::ReadId(VehicleId::new(7).unwrap()))
    );
    b.echo(Command::Init);
    assert!(!b.lbc.drive_enabled());
    // Motion commands while the drive is disabled get their specific errors.
    let target = Command::MoveXy(Position::new(300, 500).unwrap());
    assert_eq!(b.request(target), Err(Failure::Rejected));
    assert_eq!(
        b.request(Command::MoveSv(sv(0, 100))),
        Err(Failure::Rejected)
    );
    b.echo(Command::Dren);
    assert!(b.lbc.drive_enabled());
    b.echo(Command::MoveSv(sv(100, 200)));
    // Beyond the velocity limit of 2000 mm/s.
    assert_eq!(
        b.request(Command::MoveSv(sv(0, 3000))),
        Err(Failure::Rejected)
    );
    b.run_for(1_500_000);
    match b.request(Command::ReadSv) {
        Ok(Reply::ReadSv(m)) => {
            assert!((m.steering.get() - 100).abs() <= 5, "{m:?}");
            assert!((m.velocity.get() - 200).abs() <= 10, "{m:?}");
        }
        other => panic!("{other:?}"),
    }
    b.echo(Command::Stop);
    b.run_for(500_000);
    assert!(b.lbc.vehicle().speed_mm_s().abs() < 3.0);
    b.echo(Command::Drds);
    assert!(!b.lbc.drive_enabled());
    assert_eq!(
        b.request(Command::MoveSv(sv(0, 100))),
        Err(Failure::Rejected)
    );
}

#[test]
fn readings() {
    let mut b = Bench::new(LbcConfig::default());
    b.run_for(100_000);
    // Start pose: (750 mm, 1000 mm) = (300, 400) units, facing +Y (1571 mrad).
    match b.request(Command::ReadXy) {
        Ok(Reply::ReadXy(p)) => assert_eq!((p.x.get(), p.y.get()), (300, 400)),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadHd) {
        Ok(Reply::ReadHd(h)) => assert_eq!(h.get(), 1571),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadAy) {
        Ok(Reply::ReadAy(h)) => assert!((h.get() as i32 - 1571).abs() <= 3, "{h:?}"),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadPry) {
        Ok(Reply::ReadPry(g)) => {
            // Zero-rate level 1.5 V against the 1.225 V reference: 94 counts.
            for v in [g.pitch, g.roll, g.yaw] {
                assert!((v.get() - 94).abs() <= 3, "{g:?}");
            }
        }
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadBt) {
        Ok(Reply::ReadBt(w)) => assert!(!w.battery_low && !w.over_temperature),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadRs) {
        // 905 mm to the far wall: 26 + 165440 / 905 = 209 counts.
        Ok(Reply::ReadRs(r)) => assert!((r.get() as i32 - 209).abs() <= 4, "{r:?}"),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadSf) {
        Ok(Reply::ReadSf(f)) => assert_eq!(f.bits(), 0x1F),
        other => panic!("{other:?}"),
    }
}

#[test]
fn streaming_at_30_hz_in_the_current_format() {
    let mut b = Bench::new(LbcConfig::default());
    let format = StreamFormat::new(0x0000_8007).unwrap(); // ID, X/Y, S/V, chip status
    b.echo(Command::UpdSf(format));
    assert_eq!(b.request(Command::ReadSf), Ok(Reply::ReadSf(format)));
    b.echo(Command::Sten);
    let t0 = b.now;
    b.run_for(1_000_000);
    b.echo(Command::Stds);
    let t1 = b.now;
    b.run_for(300_000);
    let streams = b.streams();
    let during: Vec<_> = streams
        .iter()
        .filter(|(t, _)| *t > t0 && *t <= t1)
        .collect();
    assert!((30..=31).contains(&during.len()), "{} frames", during.len());
    assert!(
        streams.iter().all(|(t, _)| *t <= t1 + 5_000),
        "STREAM after STDS"
    );
    let s = during[5].1;
    assert_eq!(s.id.map(|v| v.get()), Some(7));
    assert_eq!(s.position.map(|p| (p.x.get(), p.y.get())), Some((300, 400)));
    assert!(s.chip_status.is_some() && s.adjusted_yaw.is_none());
    // An empty format cannot be streamed.
    b.echo(Command::UpdSf(StreamFormat::EMPTY));
    assert_eq!(b.request(Command::Sten), Err(Failure::Rejected));
}

#[test]
fn parameters_eeprom_commit_and_restore() {
    let mut b = Bench::new(LbcConfig::default());
    let p = Param::MotorPGain;
    assert_eq!(
        b.request(Command::ReadPar(p)),
        Ok(Reply::ReadPar(pv(p, 512)))
    );
    b.echo(Command::UpdPar(pv(p, 600)));
    assert_eq!(
        b.request(Command::ReadPar(p)),
        Ok(Reply::ReadPar(pv(p, 600)))
    );
    // Semantic ranges beyond the wire width.
    let bad = [
        pv(Param::MotorEncoderRatio, 0),
        pv(Param::MotorGearRatio, 0),
        pv(Param::MotorDeadBand, 1001),
        pv(Param::ServoOffset, 600),
        pv(Param::ServoGain, 0),
        pv(Param::ServoDeadBand, 501),
    ];
    for v in bad {
        assert_eq!(
            b.request(Command::UpdPar(v)),
            Err(Failure::Rejected),
            "{v:?}"
        );
    }
    assert_eq!(b.lbc.eeprom().get(reg::MPG), Some(512));
    b.echo(Command::Cmep);
    assert_eq!(b.lbc.eeprom().get(reg::MPG), Some(600));
    b.echo(Command::UpdPar(pv(p, 700)));
    b.echo(Command::Rsep);
    assert_eq!(
        b.request(Command::ReadPar(p)),
        Ok(Reply::ReadPar(pv(p, 600)))
    );
    // INIT restores from the EEPROM too.
    b.echo(Command::UpdPar(pv(Param::ServoOffset, -20)));
    b.echo(Command::Init);
    assert_eq!(b.lbc.param(Param::ServoOffset), 0);
    // Signed parameters survive the round trip.
    b.echo(Command::UpdPar(pv(Param::ServoGain, -900)));
    assert_eq!(
        b.request(Command::ReadPar(Param::ServoGain)),
        Ok(Reply::ReadPar(pv(Param::ServoGain, -900)))
    );
    b.echo(Command::Cmep);
    assert_eq!(b.lbc.eeprom().get(reg::SG), Some((-900i16) as u16));

    // User registers.
    let addr = UserRegister::new(0x21).unwrap();
    b.echo(Command::WritEp {
        address: addr,
        value: 0xBEEF,
    });
    assert_eq!(
        b.request(Command::ReadEp(addr.into())),
        Ok(Reply::ReadEpData {
            address: addr.into(),
            value: 0xBEEF
        })
    );
    assert_eq!(b.lbc.eeprom().get(0x21), Some(0xBEEF));
    // READ_EP outside the user registers is refused.
    assert_eq!(
        b.request(Command::ReadEp(EepromAddress::new(0x05).unwrap())),
        Err(Failure::Rejected)
    );
}

#[test]
fn led_and_gpio_patterns() {
    let mut b = Bench::new(LbcConfig::default());
    let green = LedPattern::new(LedRate::Blink2Hz, Duty::new(5).unwrap());
    let red = LedPattern::new(LedRate::Dim100Hz, Duty::ON);
    b.echo(Command::WritLed { green, red });
    let (pat, _) = b.lbc.leds();
    assert_eq!(pat, [green, red]);
    let t0 = b.now;
    let mut highs = 0;
    let mut samples = 0;
    while b.now < t0 + 1_000_000 {
        b.run_for(10_000);
        let (_, out) = b.lbc.leds();
        assert!(out[1], "duty 10 is constant high");
        samples += 1;
        highs += usize::from(out[0]);
    }
    assert!((45..=55).contains(&highs), "{highs} of {samples}");
    let g0 = GpioPattern::new(GpioRate::Hz10, Duty::new(2).unwrap());
    let g1 = GpioPattern::from_bits(0x0C).unwrap(); // duty code 12 means constant low
    b.echo(Command::WritGpo {
        gpio0: g0,
        gpio1: g1,
    });
    b.run_for(50_000);
    let (pat, out) = b.lbc.gpio();
    assert_eq!(pat, [g0, g1]);
    assert!(!out[1]);
}

#[test]
fn calibrations_return_plausible_values() {
    let mut cfg = LbcConfig::default();
    let mut v = VehicleConfig::default();
    v.servo_trim_us = 12.0;
    v.servo_us_per_rad = 950.0;
    v.sensors.gyro_yaw_bias_dps = 2.0;
    cfg.vehicle = v;
    let mut b = Bench::new(cfg);
    // Gyro calibration works with the drive off; steering and drive need it on.
    match b.request(Command::CalbGs) {
        Ok(Reply::CalbGs(g)) => {
            // Pitch/roll at 94 counts (x16 = 1504); yaw biased by 2 deg/s = 4 mV = 1.37 counts.
            assert!((g.pitch.get() - 1504).abs() <= 4, "{g:?}");
            assert!((g.roll.get() - 1504).abs() <= 4, "{g:?}");
            let yaw = g.yaw.unwrap().get();
            assert!((yaw - 1526).abs() <= 4, "{g:?}");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(
        b.lbc
            .calibration_register(reg::GYO)
            .map(|v| v as i16 > 1515),
        Some(true)
    );
    assert_eq!(b.request(Command::CalbSt), Err(Failure::Rejected));
    assert_eq!(b.request(Command::CalbDm), Err(Failure::Rejected));
    b.echo(Command::Dren);
    match b.request(Command::CalbSt) {
        Ok(Reply::CalbSt(c)) => {
            assert!((c.offset.get() - 12).abs() <= 3, "{c:?}");
            assert!((c.gain.get() - 950).abs() <= 30, "{c:?}");
            assert_eq!(b.lbc.param(Param::ServoOffset), c.offset.get());
        }
        other => panic!("{other:?}"),
    }
    b.echo(Command::CalbDm);
    let db = b.lbc.param(Param::MotorDeadBand);
    assert!((50..=80).contains(&db), "dead band {db}");
    // Calibrated values persist only through CMEP.
    assert_eq!(b.lbc.eeprom().get(reg::SO), Some(0));
    b.echo(Command::Cmep);
    assert_eq!(
        b.lbc.eeprom().get(reg::SO),
        Some(b.lbc.param(Param::ServoOffset) as u16)
    );
    assert!(b.lbc.eeprom().get(reg::GYO).unwrap() as i16 > 1515);
}

#[test]
fn specific_errors_for_out_of_range_fields() {
    let mut b = Bench::new(LbcConfig::default());
    b.echo(Command::Dren);
    let cases: Vec<(Vec<u8>, [u8; 3])> = vec![
        (frame(0xC1, &[(641, 14), (0, 14)]), [0x81, 0x01, 0xFF]),
        (frame(0xC1, &[(0, 14), (961, 14)]), [0x81, 0x01, 0xFF]),
        (frame(0xC2, &[(600, 14), (0, 14)]), [0x82, 0x02, 0xFF]),
        (frame(0xD0, &[(0x1F, 7), (1, 16)]), [0x90, 0x10, 0xFF]),
        (frame(0xD0, &[(0x40, 7), (1, 16)]), [0x90, 0x10, 0xFF]),
        (frame(0xD1, &[(0x40, 7)]), [0x91, 0x11, 0xFF]),
        (frame(0xD1, &[(0x00, 7)]), [0x91, 0x11, 0xFF]),
        (frame(0xF1, &[(0x20, 28)]), [0xB1, 0x31, 0xFF]),
        (frame(0xF1, &[(0x0020_0000, 28)]), [0xB1, 0x31, 0xFF]),
        (frame(0xF2, &[(0, 7)]), [0xB2, 0x32, 0xFF]),
        (frame(0xF2, &[(13, 7)]), [0xB2, 0x32, 0xFF]),
        (frame(0xF3, &[(13, 7), (5, 14)]), [0xB3, 0x33, 0xFF]),
        // Seed example requests and a bad checksum.
        (vec![0xE8, 0x69, 0xFF], [0xBD, 0x3D, 0xFF]),
    ];
    for (req, expect) in cases {
        assert_eq!(b.raw(&req), expect, "request {req:02x?}");
    }
}

#[test]
fn unknown_and_general_error_messages() {
    let mut b = Bench::new(LbcConfig::default());
    // NOT-IN-USE headers and malformed lengths: UNKCMD echoing the message.
    for req in [
        frame(0xC3, &[]),
        frame(0xE7, &[(5, 7)]),
        frame(0xF5, &[]),
        frame(0xE8, &[(1, 7)]),  // READ_ID with data
        frame(0xC1, &[(1, 14)]), // MOVE_XY too short
        frame(0x81, &[]),        // an error header sent to the LBC
    ] {
        let out = decode_all(&b.raw(&req));
        match out.as_slice() {
            [LbcMessage::UnknownCommand(Some(echo))] => {
                assert_eq!(echo.header, req[0]);
                assert_eq!(echo.data.as_slice(), &req[1..req.len() - 2]);
            }
            other => panic!("{req:02x?} -> {other:?}"),
        }
    }
    let unk = b.raw(&[0xC3, 0x43, 0xFF]);
    // Checksum: (0xBC ^ 0x43) & 0x7F = 0x7F.
    assert_eq!(unk, [0xBC, 0x43, 0x7F, 0xFF]);
    // General errors, STREAM and line noise get no reply.
    for req in [
        vec![0xBC, 0x3C, 0xFF],
        vec![0xBD, 0x3D, 0xFF],
        vec![0x9C, 0x1C, 0xFF],
        vec![0xDF, 0x5F, 0xFF],
        vec![0xFC, 0x01, 0x7D, 0xFF],
        vec![0x12, 0x34, 0xFF],
        vec![0xE8, 0xE8, 0x68, 0xFF], // truncated, then a good READ_ID
    ] {
        let out = decode_all(&b.raw(&req));
        let expect_id = req.len() == 4 && req[0] == 0xE8;
        assert_eq!(out.len(), usize::from(expect_id), "{req:02x?} -> {out:?}");
    }
    assert!(b.lbc.deframer_stats().errors() > 0);
}

#[test]
fn uart_paces_bytes_at_115200_baud() {
    let mut b = Bench::new(LbcConfig::default());
    b.echo(Command::UpdSf(StreamFormat::ALL));
    b.echo(Command::Sten);
    b.run_for(100_000);
    let out = b.raw_exchange(&[], 200_000);
    assert!(out.len() > 300, "{}", out.len());
    for w in out.windows(2) {
        assert!(w[1].0 - w[0].0 >= 86, "bytes {} us apart", w[1].0 - w[0].0);
    }
    // The capture may start inside a frame: skip to the first header.
    let bytes: Vec<u8> = out
        .iter()
        .map(|(_, b)| *b)
        .skip_while(|b| *b != 0xFC)
        .collect();
    let msgs = decode_all(&bytes);
    assert!(
        msgs.iter()
            .filter(|m| matches!(m, LbcMessage::Stream(_)))
            .count()
            >= 5
    );
}

#[test]
fn battery_and_temperature_warnings() {
    let mut b = Bench::new(LbcConfig::default());
    b.lbc.vehicle_mut().set_soc(0.02);
    b.lbc.vehicle_mut().set_ambient_c(70.0);
    b.lbc.vehicle_mut().set_chip_temp_c(80.0);
    b.run_for(1_100_000);
    match b.request(Command::ReadBt) {
        Ok(Reply::ReadBt(w)) => assert!(w.battery_low && w.over_temperature, "{w:?}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn error_headers_are_bit_6_cleared() {
    // A table check against the headers the emulator actually sends.
    let mut b = Bench::new(LbcConfig::default());
    let out = b.raw(&frame(0xF2, &[(99, 7)]));
    assert_eq!(out[0], CommandKind::ReadPar.error_header());
}

#[test]
fn eeprom_failures_and_bad_contents_get_specific_errors() {
    use lbc_emu::{EepromImage, Lbc, MemoryStore};
    // A store that cannot commit: WRIT_EP and CMEP fail, nothing changes.
    let store = MemoryStore {
        fail: true,
        ..MemoryStore::default()
    };
    let lbc = Lbc::new(
        LbcConfig::default(),
        EepromImage::factory(2),
        Box::new(store),
    );
    let mut b = Bench::with_lbc(lbc);
    let addr = UserRegister::new(0x30).unwrap();
    assert_eq!(
        b.request(Command::WritEp {
            address: addr,
            value: 1
        }),
        Err(Failure::Rejected)
    );
    assert_eq!(b.lbc.eeprom().get(0x30), Some(0));
    assert_eq!(b.request(Command::Cmep), Err(Failure::Rejected));

    // Parameter registers holding values no parameter may take: the LBC boots with factory
    // parameters and RSEP refuses to load them.
    let mut image = EepromImage::factory(2);
    image.set(reg::MERR, 0);
    let mut b = Bench::with_lbc(Lbc::new(
        LbcConfig::default(),
        image,
        Box::new(MemoryStore::default()),
    ));
    assert_eq!(b.lbc.param(Param::MotorEncoderRatio), 800);
    assert_eq!(b.request(Command::Rsep), Err(Failure::Rejected));
}

#[test]
fn eeprom_queue_overflow_is_refused() {
    let mut b = Bench::new(LbcConfig::default());
    let mut burst = Vec::new();
    for i in 0..9u32 {
        burst.extend(frame(0xD0, &[(0x20 + i, 7), (i, 16)]));
    }
    let out = decode_all(
        &b.raw_exchange(&burst, 300_000)
            .into_iter()
            .map(|(_, b)| b)
            .collect::<Vec<_>>(),
    );
    let errors = out
        .iter()
        .filter(|m| **m == LbcMessage::Error(CommandKind::WritEp))
        .count();
    let acks = out
        .iter()
        .filter(|m| matches!(m, LbcMessage::Reply(Reply::Echo(Command::WritEp { .. }))))
        .count();
    assert_eq!((acks, errors), (8, 1), "{out:?}");
    assert_eq!(b.lbc.eeprom().get(0x27), Some(7));
}
