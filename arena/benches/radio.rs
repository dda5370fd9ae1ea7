//! Radio benchmark: bytes on air per state message against MAVLink v2, and state delivery
//! ratio for 1..=16 cars at 30 Hz over a simulated minute, with and without the slot
//! schedule. Prints markdown. `cargo bench -p arena --bench radio`
//! (`RADIO_BENCH_SECONDS=10` for a shorter run).

use arena::radio_medium::MediumParams;
use arena::radio_sim::{run_state_experiment, StateExperiment};
use radio_mac::wire::{encode_frame, CarState, Frame, Mode, Role, STATE_FRAME_LEN};
use radio_mac::CarId;
use std::time::Instant;

/// MAVLink v2 framing: STX, len, incompat, compat, seq, sysid, compid, msgid (3), CRC (2).
const MAVLINK2_OVERHEAD: usize = 12;
/// GLOBAL_POSITION_INT payload (time, lat, lon, alt, relative alt, vx, vy, vz, hdg).
const MAVLINK_GLOBAL_POSITION_INT: usize = 28;

fn main() {
    let seconds: u64 = std::env::var("RADIO_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(60);
    let Some(id) = CarId::new(12) else { return };
    let frame = Frame::State {
        src: id,
        seq: 0,
        state: CarState {
            x: 640,
            y: 960,
            heading_mrad: 6283,
            velocity_mm_s: -1500,
            mode: Mode {
                role: Role::Follower,
                phase: 3,
            },
        },
    };
    let on_air = encode_frame(&frame).map(|f| f.len()).unwrap_or(0);
    assert_eq!(on_air, STATE_FRAME_LEN);
    let p = MediumParams::default();
    let mav = MAVLINK2_OVERHEAD + MAVLINK_GLOBAL_POSITION_INT;
    let us = |n: usize| p.air_time_ns(n) as f64 / 1000.0;

    println!("## Radio: bytes on air per state message\n");
    println!("| format | bytes via UART | air time incl. {}-byte radio preamble | max at 30 Hz in one channel |", p.air_overhead_bytes);
    println!("|---|---:|---:|---:|");
    for (name, n) in [
        ("radio-mac State (COBS + CRC-16 + header)", on_air),
        ("MAVLink v2 GLOBAL_POSITION_INT (12 + 28)", mav),
    ] {
        let per_frame = 33_333.0 / us(n);
        println!(
            "| {name} | {n} | {:.0} us | {:.0} cars |",
            us(n),
            per_frame.floor()
        );
    }

    println!(
        "\n## Radio: state delivery ratio, 30 Hz, {seconds} s simulated (after 1 s warm-up)\n"
    );
    println!(
        "Receivers: every other car and the ground station. Channel: {:?}\n",
        p
    );
    println!("| cars | slotted, follow lowest ID: delivered | collisions | slotted, tracking tick: delivered | collisions | CSMA only: delivered | collisions |");
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    let started = Instant::now();
    for n in 1..=16usize {
        let mut cells = Vec::new();
        for (scheduled, tracking) in [(true, false), (true, true), (false, false)] {
            let mut e = StateExperiment::new(n, scheduled, seconds * 1_000_000_000, 42 + n as u64);
            e.tracking_time_base = tracking;
            let r = run_state_experiment(&e);
            cells.push(format!(
                "{:.2}% ({}/{})",
                100.0 * r.delivery_ratio(),
                r.received,
                r.expected
            ));
            cells.push(format!("{}", r.medium.collisions));
        }
        println!("| {n} | {} |", cells.join(" | "));
    }
    eprintln!("simulated in {:.1} s", started.elapsed().as_secs_f64());
}
