//! Acceptance: the program firmware in QEMU, its LBC UART on an emulated LBC, its radio UART
//! driven by a ground station: every LBC command reaches the LBC through radio + firmware and
//! its result comes back; MOVE_XY brings the car to the target; corrupt bytes on both UARTs
//! are counted and break nothing.

use std::time::{Duration, Instant};

use lbc_link::{
    Command, Duty, EepromAddress, GpioPattern, GpioRate, LedPattern, LedRate, Param, ParamValue,
    Position, SteerVelocity, SteeringAngle, UserRegister, Velocity,
};
use ubc_app::program::console::{flags, LbcOutcome, Reply, Request};

mod program_common;

/// Bound on the whole test.
const DEADLINE: Duration = Duration::from_secs(150);

fn lbc(g: &mut program_common::Ground, cmd: Command) -> LbcOutcome {
    match g.request(&Request::Lbc(cmd), Duration::from_secs(15)) {
        Reply::Lbc(o) => o,
        other => panic!("{cmd:?}: {other:?}"),
    }
}

#[test]
fn console_commands_motion_and_noise() {
    let Some(mut rig) = program_common::boot("console_commands_motion_and_noise") else {
        return;
    };
    let start = Instant::now();
    let g = &mut rig.ground;

    // Bring-up completes on its own.
    let s = g.wait_status(Duration::from_secs(20), |s| {
        s.phase == 2 && s.flags & flags::STREAMING != 0
    });
    assert_eq!(s.car_id, program_common::CAR);
    assert_ne!(s.flags & flags::DRIVE_ENABLED, 0);

    // Every command of Table 3-2 reaches the LBC and its answer comes back.
    let led = LedPattern::new(LedRate::Blink2Hz, Duty::new(5).unwrap());
    let gpo = GpioPattern::new(GpioRate::Hz5, Duty::ON);
    let sv0 = SteerVelocity {
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
        Command::UpdPar(ParamValue::new(Param::MotorPGain, 512).unwrap()),
        Command::WritLed {
            green: led,
            red: led,
        },
        Command::WritGpo {
            gpio0: gpo,
            gpio1: gpo,
        },
        Command::WritEp {
            address: UserRegister::new(0x22).unwrap(),
            value: 4321,
        },
        Command::ReadEp(EepromAddress::new(0x22).unwrap()),
        Command::CalbGs,
        Command::CalbSt,
        Command::CalbDm,
        Command::Cmep,
        Command::Rsep,
        Command::MoveSv(sv0),
        Command::Stop,
        Command::Stds,
        Command::Sten,
        Command::Drds,
        Command::Dren,
        Command::Init,
        Command::UpdSf(lbc_link::StreamFormat::new(ubc_app::program::REQUIRED_STREAM).unwrap()),
        Command::Sten,
        Command::Dren,
    ];
    let lbc_log = rig.lbc.as_ref().expect("lbc running");
    for cmd in cmds {
        let before = lbc_log.commands().iter().filter(|c| **c == cmd).count();
        let o = lbc(g, cmd);
        match &o {
            LbcOutcome::Answer(r) => assert_eq!(r.kind(), cmd.kind(), "{cmd:?}"),
            LbcOutcome::Rejected(k) => assert_eq!(*k, cmd.kind(), "{cmd:?}"),
            other => panic!("{cmd:?}: {other:?}"),
        }
        let after = lbc_log.commands().iter().filter(|c| **c == cmd).count();
        assert!(after > before, "{cmd:?} never reached the LBC");
        if let Command::ReadEp(_) = cmd {
            assert!(
                matches!(
                    o,
                    LbcOutcome::Answer(lbc_link::Reply::ReadEpData { value: 4321, .. })
                ),
                "{o:?}"
            );
        }
        if cmd == Command::ReadId {
            assert!(matches!(o, LbcOutcome::Answer(lbc_link::Reply::ReadId(id)) if id.get() == 7));
        }
    }
    // MOVE_SV and MOVE_XY are refused by the program itself while the drive is disabled.
    assert!(matches!(lbc(g, Command::Drds), LbcOutcome::Answer(_)));
    let target = Command::MoveXy(Position::new(320, 480).unwrap());
    assert_eq!(
        g.request(&Request::Lbc(target), Duration::from_secs(10)),
        Reply::Refused(ubc_app::program::console::Refusal::DriveDisabled)
    );
    assert!(matches!(lbc(g, Command::Dren), LbcOutcome::Answer(_)));

    // MOVE_XY brings the car to the target, as the stream shows.
    assert!(matches!(lbc(g, target), LbcOutcome::Answer(_)));
    let s = g.wait_status(Duration::from_secs(30), |s| {
        (i32::from(s.x) - 320).abs() <= 10 && (i32::from(s.y) - 480).abs() <= 10
    });
    eprintln!("arrived: {s:?} after {:?}", start.elapsed());

    // Noise on both UARTs: counted, survived.
    rig.relay
        .corrupt_every
        .store(200, std::sync::atomic::Ordering::Relaxed);
    for i in 0..20u8 {
        g.inject(&[0x55, i, 0xAA, 0x13, 0x00]);
        g.run_for(Duration::from_millis(50));
    }
    rig.relay
        .corrupt_every
        .store(0, std::sync::atomic::Ordering::Relaxed);
    g.run_for(Duration::from_millis(500));
    let s = g.wait_status(Duration::from_secs(20), |s| s.phase == 2);
    assert!(
        rig.relay
            .corrupted
            .load(std::sync::atomic::Ordering::Relaxed)
            > 0
    );
    let line = match g.request(&Request::Stats(1), Duration::from_secs(10)) {
        Reply::Stats { values, .. } => values,
        other => panic!("{other:?}"),
    };
    let radio = match g.request(&Request::Stats(2), Duration::from_secs(10)) {
        Reply::Stats { values, .. } => values,
        other => panic!("{other:?}"),
    };
    // LBC line: garbage, truncated, missing checksum or checksum errors were seen.
    assert!(line.iter().skip(2).any(|v| *v > 0), "lbc line {line:?}");
    // Radio: checksum, COBS or malformed frames were seen.
    assert!(
        radio.iter().skip(1).take(3).any(|v| *v > 0),
        "radio {radio:?}"
    );
    assert!(s.flags & flags::DRIVE_ENABLED != 0);
    assert!(
        rig.qemu.try_wait().expect("qemu state").is_none(),
        "firmware died"
    );
    assert!(start.elapsed() < DEADLINE, "took {:?}", start.elapsed());
    rig.shutdown();
}
