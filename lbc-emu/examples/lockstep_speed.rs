//! How fast the emulated LBC runs in lockstep: simulated seconds per wall-clock second with
//! the drive running and STREAM on in the largest format.

use std::time::Instant;

use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, SteerVelocity, SteeringAngle, StreamFormat, Velocity};

fn main() {
    let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 1);
    let mut buf = [0u8; 16];
    let sv = SteerVelocity {
        steering: SteeringAngle::new(200).expect("in range"),
        velocity: Velocity::new(300).expect("in range"),
    };
    let mut t = 0;
    for cmd in [
        Command::Dren,
        Command::UpdSf(StreamFormat::ALL),
        Command::Sten,
        Command::MoveSv(sv),
    ] {
        let n = cmd.emit(&mut buf).expect("fits");
        lbc.push_rx(t, &buf[..n]);
        t += 5_000;
        lbc.step_until(t);
    }
    let sim_s = 60;
    let start = Instant::now();
    let mut out = Vec::new();
    for ms in 0..sim_s * 1000 {
        let now = t + ms * 1000;
        lbc.step_until(now);
        lbc.drain_tx(now, &mut out);
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "| lockstep, 1 ms steps, STREAM all variables | {sim_s} s simulated in {wall:.3} s | {:.0}x real time | {} bytes sent |",
        sim_s as f64 / wall,
        out.len()
    );
}
