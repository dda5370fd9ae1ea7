//! How many QEMU cars run in real time on this machine: for each N, boots N cars (idle, no
//! maneuver), waits for their bring-up, then measures over a window the STREAM frame rate
//! sent by each emulated LBC and received by each firmware (console stats), the radio state
//! rate heard by the ground station and the tracking fix rate. Ignored by default:
//!
//! `ARENA_BENCH_N=1,2,4,8 cargo test -p arena --release --test arena_bench -- --ignored --nocapture`

use arena::world::{CarSpec, World, WorldConfig};
use lbc_emu::Pose;
use std::time::{Duration, Instant};
use ubc_app::program::console::{flags, Reply, Request};

const WINDOW: Duration = Duration::from_secs(10);

/// CPU seconds (user + system) used by process `pid` so far.
fn cpu_s(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command name (which ends with the last ')'): utime is the 12th, stime the 13th.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|v| v.parse().unwrap_or(0.0))
        .collect();
    (f.get(11).copied().unwrap_or(0.0) + f.get(12).copied().unwrap_or(0.0)) / 100.0
}

/// The firmware's STREAM frame count, when it was asked (mid-way through the round trip),
/// and the round trip.
fn firmware_streams(world: &World, id: u8) -> Option<(u64, Instant, Duration)> {
    let sent = Instant::now();
    match world.request(id, &Request::Stats(1), Duration::from_secs(5)) {
        Ok(Reply::Stats { values, .. }) => {
            let rtt = sent.elapsed();
            values.first().map(|&v| (u64::from(v), sent + rtt / 2, rtt))
        }
        _ => None,
    }
}

fn cars(n: usize) -> Vec<CarSpec> {
    (0..n)
        .map(|i| CarSpec {
            id: u8::try_from(i + 1).unwrap_or(1),
            start: Pose {
                x_mm: 150.0 + 300.0 * (i % 4) as f64,
                y_mm: 200.0 + 400.0 * (i / 4) as f64,
                heading_rad: 1.571,
            },
        })
        .collect()
}

fn bench(n: usize) -> String {
    let elf = qemu_harness::firmware_elf().expect("firmware ELF");
    let cfg = WorldConfig::new(elf, cars(n));
    let t_boot = Instant::now();
    let world = match World::start(&cfg) {
        Ok(w) => w,
        Err(e) => return format!("| {n:>2} | world failed: {e} |"),
    };
    let deadline = Instant::now() + Duration::from_secs(90);
    let mut up = 0;
    for &id in world.ids() {
        loop {
            if let Ok(Reply::Status(s)) =
                world.request(id, &Request::Status, Duration::from_secs(5))
            {
                if s.phase == 2 && s.flags & flags::POSE_VALID != 0 {
                    up += 1;
                    break;
                }
            }
            if Instant::now() > deadline {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
    let bringup = t_boot.elapsed().as_secs_f64();
    let fw0: Vec<Option<(u64, Instant, Duration)>> = world
        .ids()
        .iter()
        .map(|&id| firmware_streams(&world, id))
        .collect();
    let pids: Vec<u32> = world.qemu_pids().iter().map(|p| p.1).collect();
    let qemu_cpu0: f64 = pids.iter().map(|&p| cpu_s(p)).sum();
    let own_cpu0 = cpu_s(std::process::id());
    let a = world.truth();
    let t0 = Instant::now();
    std::thread::sleep(WINDOW);
    let b = world.truth();
    let dt_lbc = t0.elapsed().as_secs_f64();
    let qemu_cpu = 100.0 * (pids.iter().map(|&p| cpu_s(p)).sum::<f64>() - qemu_cpu0) / dt_lbc;
    let own_cpu = 100.0 * (cpu_s(std::process::id()) - own_cpu0) / dt_lbc;
    let fw1: Vec<Option<(u64, Instant, Duration)>> = world
        .ids()
        .iter()
        .map(|&id| firmware_streams(&world, id))
        .collect();
    let rate = |f: &dyn Fn(usize) -> u64, dt: f64| {
        let r: Vec<f64> = (0..n).map(|k| f(k) as f64 / dt).collect();
        let min = r.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = r.iter().sum::<f64>() / n as f64;
        (min, mean)
    };
    let lbc = rate(&|k| b[k].lbc.stream_frames - a[k].lbc.stream_frames, dt_lbc);
    let fixes = rate(&|k| b[k].fixes_delivered - a[k].fixes_delivered, dt_lbc);
    let states = rate(&|k| b[k].states_heard - a[k].states_heard, dt_lbc);
    let fw_rates: Vec<f64> = (0..n)
        .map(|k| match (fw0[k], fw1[k]) {
            (Some((x, tx, _)), Some((y, ty, _))) => {
                y.saturating_sub(x) as f64 / ty.duration_since(tx).as_secs_f64()
            }
            _ => 0.0,
        })
        .collect();
    let fw = (
        fw_rates.iter().copied().fold(f64::INFINITY, f64::min),
        fw_rates.iter().sum::<f64>() / n as f64,
    );
    let rtt_max = fw0
        .iter()
        .chain(&fw1)
        .filter_map(|r| r.map(|(_, _, rtt)| rtt.as_secs_f64() * 1000.0))
        .fold(0.0, f64::max);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?").to_owned();
    drop(world);
    format!(
        "| {n:>2} | {up:>2}/{n:<2} | {bringup:>5.1} | {:>5.1} / {:>5.1} | {:>5.1} / {:>5.1} | {:>5.1} / {:>5.1} | {:>5.1} / {:>5.1} | {rtt_max:>5.0} | {qemu_cpu:>5.0} | {own_cpu:>4.0} | {load} |",
        lbc.0, lbc.1, fw.0, fw.1, fixes.0, fixes.1, states.0, states.1
    )
}

#[test]
#[ignore = "benchmark: minutes of QEMU; run explicitly"]
fn realtime_capacity() {
    if qemu_harness::skip_qemu_tests("realtime_capacity") {
        return;
    }
    let ns: Vec<usize> = std::env::var("ARENA_BENCH_N")
        .unwrap_or_else(|_| "1,2,4,8,12,16".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect();
    println!("| N | up | boot+bring-up s | LBC stream Hz min / mean | firmware stream Hz min / mean | tracking fixes Hz min / mean | radio states Hz min / mean | console RTT max ms | QEMU CPU % (all) | engine+hub CPU % | load1 |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for n in ns {
        let line = bench(n);
        println!("{line}");
    }
}
