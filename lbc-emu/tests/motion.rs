//! The vehicle as the LBC's tasks drive it: MOVE_XY, MOVE_SV, STOP, tracking input, resets.

mod common;

use common::{distance_units, Bench};
use lbc_emu::{LbcConfig, Pose, PoseSource};
use lbc_link::client::Failure;
use lbc_link::{Command, Position, Reply, SteerVelocity, SteeringAngle, StreamFormat, Velocity};

fn sv(steer: i16, v: i16) -> SteerVelocity {
    SteerVelocity {
        steering: SteeringAngle::new(steer).unwrap(),
        velocity: Velocity::new(v).unwrap(),
    }
}

fn at(x_mm: f64, y_mm: f64, heading_rad: f64) -> LbcConfig {
    let mut cfg = LbcConfig::default();
    cfg.start_pose = Pose {
        x_mm,
        y_mm,
        heading_rad,
    };
    cfg
}

/// Runs until the LBC reports arrival and the car stands still; returns the time taken, s.
fn drive_to(b: &mut Bench, x: u16, y: u16, limit_s: f64) -> f64 {
    let t0 = b.now;
    b.echo(Command::MoveXy(Position::new(x, y).unwrap()));
    while b.lbc.arrived() != Some(true) || b.lbc.vehicle().speed_mm_s().abs() > 1.0 {
        assert!(
            (b.now - t0) as f64 / 1e6 < limit_s,
            "not there after {limit_s} s: pose {:?}",
            b.lbc.vehicle().pose()
        );
        b.run_for(10_000);
    }
    (b.now - t0) as f64 / 1e6
}

#[test]
fn move_xy_reaches_a_target_half_a_metre_ahead() {
    let mut b = Bench::new(at(750.0, 500.0, core::f64::consts::FRAC_PI_2));
    b.enable();
    // 200 units = 500 mm straight ahead.
    let secs = drive_to(&mut b, 300, 400, 4.0);
    eprintln!("reached (300, 400) in {secs:.2} s");
    let d = distance_units(&b.lbc, 300.0, 400.0);
    assert!(d <= 8.0, "stopped {d} units from the target after {secs} s");
    // It stays stopped.
    b.run_for(1_000_000);
    assert!(distance_units(&b.lbc, 300.0, 400.0) <= 8.0);
    match b.request(Command::ReadXy) {
        Ok(Reply::ReadXy(p)) => {
            assert!(
                (i32::from(p.x.get()) - 300).abs() <= 8 && (i32::from(p.y.get()) - 400).abs() <= 8
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn move_xy_reaches_targets_beside_and_behind() {
    for (x, y, limit) in [
        (500u16, 300u16, 6.0),
        (300, 120, 8.0),
        (330, 150, 8.0),
        (100, 250, 8.0),
    ] {
        let mut b = Bench::new(at(750.0, 500.0, core::f64::consts::FRAC_PI_2));
        b.enable();
        let secs = drive_to(&mut b, x, y, limit);
        eprintln!("reached ({x}, {y}) in {secs:.2} s");
        let d = distance_units(&b.lbc, f64::from(x), f64::from(y));
        assert!(d <= 8.0, "target ({x}, {y}): stopped {d} units away");
    }
}

#[test]
fn move_sv_holds_velocity_within_5_percent() {
    let mut b = Bench::new(at(750.0, 100.0, core::f64::consts::FRAC_PI_2));
    b.enable();
    b.echo(Command::MoveSv(sv(0, 300)));
    let t0 = b.now;
    while (b.lbc.vehicle().speed_mm_s() - 300.0).abs() > 15.0 {
        b.run_for(1_000);
        assert!(b.now - t0 < 500_000, "not within 5 % after 0.5 s");
    }
    eprintln!(
        "MOVE_SV 300 mm/s: within 5 % after {} ms",
        (b.now - t0) / 1000
    );
    b.run_for(1_000_000);
    let mut worst: f64 = 0.0;
    for _ in 0..100 {
        b.run_for(10_000);
        worst = worst.max((b.lbc.vehicle().speed_mm_s() - 300.0).abs());
    }
    eprintln!("MOVE_SV 300 mm/s: worst steady-state deviation {worst:.2} mm/s");
    assert!(worst <= 15.0, "speed strayed {worst} mm/s from 300");
    // Reverse, and a curve.
    b.echo(Command::MoveSv(sv(-200, -250)));
    b.run_for(1_000_000);
    let v = b.lbc.vehicle().speed_mm_s();
    assert!((v + 250.0).abs() <= 12.5, "{v}");
    assert!((b.lbc.vehicle().steer_rad() * 1000.0 + 200.0).abs() <= 3.0);
}

#[test]
fn stop_stops() {
    let mut b = Bench::new(at(750.0, 100.0, core::f64::consts::FRAC_PI_2));
    b.enable();
    b.echo(Command::MoveSv(sv(0, 400)));
    b.run_for(1_000_000);
    assert!(b.lbc.vehicle().speed_mm_s() > 350.0);
    b.echo(Command::Stop);
    b.run_for(500_000);
    let p0 = b.lbc.vehicle().pose();
    assert!(b.lbc.vehicle().speed_mm_s().abs() < 3.0);
    b.run_for(1_000_000);
    let p1 = b.lbc.vehicle().pose();
    assert!(
        (p1.y_mm - p0.y_mm).abs() < 2.0,
        "crept {} mm",
        p1.y_mm - p0.y_mm
    );
}

#[test]
fn drds_and_init_stop_the_car() {
    for cmd in [Command::Drds, Command::Init] {
        let mut b = Bench::new(at(750.0, 100.0, core::f64::consts::FRAC_PI_2));
        b.enable();
        b.echo(Command::MoveSv(sv(0, 400)));
        b.run_for(1_000_000);
        b.echo(cmd);
        b.run_for(1_000_000);
        assert!(b.lbc.vehicle().speed_mm_s().abs() < 1.0, "{cmd:?}");
        assert!(!b.lbc.drive_enabled());
        // DREN does not resume the old motion command.
        b.echo(Command::Dren);
        b.run_for(500_000);
        assert!(b.lbc.vehicle().speed_mm_s().abs() < 1.0, "{cmd:?}");
    }
}

#[test]
fn gyro_yaw_follows_the_turn() {
    let mut b = Bench::new(at(750.0, 1000.0, 0.0));
    b.enable();
    b.echo(Command::MoveSv(sv(300, 300)));
    b.run_for(3_000_000);
    let truth = b.lbc.vehicle().pose().heading_rad;
    let err = lbc_emu::vehicle::wrap_pi(b.lbc.yaw_rad() - truth);
    assert!(err.abs() < 0.05, "gyro yaw off by {err} rad");
    match b.request(Command::ReadAy) {
        Ok(Reply::ReadAy(h)) => {
            let e = lbc_emu::vehicle::wrap_pi(f64::from(h.get()) / 1000.0 - truth);
            assert!(e.abs() < 0.05);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn external_tracking_overrides_the_model_until_stale() {
    let mut b = Bench::new(LbcConfig::default());
    b.run_for(10_000);
    b.lbc.set_tracked_pose(b.now, 123, 456, 789);
    b.run_for(5_000);
    assert_eq!(b.lbc.pose_source(), PoseSource::External);
    match b.request(Command::ReadXy) {
        Ok(Reply::ReadXy(p)) => assert_eq!((p.x.get(), p.y.get()), (123, 456)),
        other => panic!("{other:?}"),
    }
    match b.request(Command::ReadHd) {
        Ok(Reply::ReadHd(h)) => assert_eq!(h.get(), 789),
        other => panic!("{other:?}"),
    }
    b.run_for(300_000);
    assert_eq!(b.lbc.pose_source(), PoseSource::Model);
    match b.request(Command::ReadXy) {
        Ok(Reply::ReadXy(p)) => assert_eq!((p.x.get(), p.y.get()), (300, 400)),
        other => panic!("{other:?}"),
    }

    // Without the model fallback, a stale pose means no pose.
    let mut cfg = LbcConfig::default();
    cfg.tracking.stale_after_us = 100_000;
    cfg.tracking.fallback_to_model = false;
    let mut b = Bench::new(cfg);
    b.run_for(10_000);
    assert_eq!(b.request(Command::ReadXy), Err(Failure::Rejected));
    assert_eq!(b.request(Command::ReadHd), Err(Failure::Rejected));
    b.lbc.set_tracked_pose(b.now, 10, 20, 30);
    b.run_for(5_000);
    assert!(b.request(Command::ReadXy).is_ok());
    b.run_for(200_000);
    assert_eq!(b.request(Command::ReadXy), Err(Failure::Rejected));
}

#[test]
fn a_spontaneous_reset_stops_everything() {
    let mut b = Bench::new(at(750.0, 100.0, core::f64::consts::FRAC_PI_2));
    b.enable();
    b.echo(Command::UpdSf(StreamFormat::new(0x7).unwrap()));
    b.echo(Command::Sten);
    b.echo(Command::MoveSv(sv(0, 300)));
    b.run_for(500_000);
    b.lbc.reset();
    assert!(b.lbc.booting());
    let t_reset = b.now;
    b.run_for(1_000_000);
    assert!(!b.lbc.drive_enabled() && !b.lbc.streaming());
    assert!(b.lbc.vehicle().speed_mm_s().abs() < 1.0);
    assert!(b.streams().iter().all(|(t, _)| *t <= t_reset + 2_000));
    // The stream format went back to the default and the LBC answers again.
    assert_eq!(
        b.request(Command::ReadSf),
        Ok(Reply::ReadSf(StreamFormat::new(0x1F).unwrap()))
    );
}
