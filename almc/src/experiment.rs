//! `almc experiment run FILE [--out DIR] [--engine iss|qemu] [--vision-unit on|off] [--threads N]
//! [--realtime] [--live [ADDR]]`: plays an experiment file (see `docs/experiments.md`) in the arena, every
//! car on the soft core's model in virtual time (or in QEMU in real time), shows its progress
//! and summary, and writes its results (with `--live`, also serves them to Foxglove while it
//! runs); `almc experiment check FILE` only checks the file.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use arena::experiment::{self, Experiment, RunOptions};
use arena::world::EngineKind;
use clap::{Args, Subcommand};

/// `almc experiment ...`
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Run an experiment: progress each second of world time, then a summary; writes CSV,
    /// JSONL, JSON, MCAP, the plots (SVG, PNG) and report.html. Exit code 0: every phase
    /// completed without collision and no car failed; 2: the run ended otherwise; 3: a car's
    /// firmware stopped; 1: error.
    Run(RunArgs),
    /// Check an experiment file without running it.
    Check {
        /// The experiment (TOML).
        file: PathBuf,
    },
}

/// `almc experiment run`
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The experiment (TOML).
    file: PathBuf,
    /// Output directory (default: `experiment-out/<name>`).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Firmware ELF for every car (default: the engine's build: `VTB_FIRMWARE` or `cargo xtask
    /// fw --board softcore` for iss, `UBC_FW_ELF` or `cargo xtask fw --board qemu_virt` for
    /// qemu).
    #[arg(long, value_name = "ELF")]
    firmware: Option<PathBuf>,
    /// Car engine, overriding the file's `engine`: `iss` (the soft core's model, virtual
    /// time) or `qemu` (real time).
    #[arg(long, value_parser = ["iss", "qemu"])]
    engine: Option<String>,
    /// The cars' vision unit, overriding the file's `vision_unit`: `on` (the SoC's pixel
    /// pipeline makes the runs) or `off` (boards without it: the firmware processes the pixels).
    #[arg(long, value_name = "on|off", value_parser = ["on", "off"])]
    vision_unit: Option<String>,
    /// Threads stepping the cars (iss); the outputs do not depend on it.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    threads: Option<u16>,
    /// Pace world time to the wall clock, so a person can talk to the cars with `almc car
    /// --radio unix:<run dir>/ground.sock` (printed at start).
    #[arg(long)]
    realtime: bool,
    /// Profile car ID's processor by function (iss): `profile-car<ID>.csv` in the outputs.
    #[arg(long = "profile-car", value_name = "ID")]
    profile_car: Vec<u8>,
    /// Serve the run live to Foxglove over its WebSocket protocol on ADDR (a loopback address,
    /// default 127.0.0.1:8765): the same channels as run.mcap. Paces world time to the wall
    /// clock, as --realtime does.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "127.0.0.1:8765", value_parser = loopback)]
    live: Option<SocketAddr>,
}

/// A loopback socket address (the live view is for this machine only).
fn loopback(s: &str) -> Result<SocketAddr, String> {
    let addr: SocketAddr = s
        .parse()
        .map_err(|e| format!("`{s}` is not an address with a port (127.0.0.1:8765): {e}"))?;
    if addr.port() == 0 {
        Err("give the live view a port (127.0.0.1:8765)".into())
    } else if addr.ip().is_loopback() {
        Ok(addr)
    } else {
        Err(format!(
            "{} is not a loopback address: the live view serves this machine only (127.0.0.1 or ::1)",
            addr.ip()
        ))
    }
}

pub fn run(cmd: ExperimentCommand) -> ExitCode {
    match cmd {
        ExperimentCommand::Check { file } => match Experiment::load(&file) {
            Ok(e) => {
                let kinds: Vec<&str> = e.phases.iter().map(|p| p.kind.name()).collect();
                println!(
                    "{}: {} cars, phases {}, up to {} s: ok",
                    e.name,
                    e.cars.len(),
                    kinds.join(" -> "),
                    e.duration_s
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        },
        ExperimentCommand::Run(args) => run_one(&args),
    }
}

fn run_one(args: &RunArgs) -> ExitCode {
    let mut exp = match Experiment::load(&args.file) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    if let Some(engine) = args.engine.as_deref().and_then(EngineKind::parse) {
        exp.engine = engine;
    }
    if let Some(v) = args.vision_unit.as_deref() {
        exp.vision_unit = v == "on";
    }
    if let Some(t) = args.threads {
        exp.threads = usize::from(t);
    }
    exp.realtime |= args.realtime || args.live.is_some();
    for &id in &args.profile_car {
        if !exp.cars.iter().any(|c| c.id == id) {
            eprintln!("error: --profile-car {id}: no such car in {}", exp.name);
            return ExitCode::FAILURE;
        }
        if !exp.profile_cars.contains(&id) {
            exp.profile_cars.push(id);
        }
    }
    let firmware = match &args.firmware {
        Some(p) => p.clone(),
        None => match exp.engine.default_firmware() {
            Ok(p) => p,
            Err(e) => {
                eprintln!("error: no firmware: {e}");
                return ExitCode::FAILURE;
            }
        },
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("experiment-out").join(&exp.name));
    let cancel = Arc::new(AtomicBool::new(false));
    let c = cancel.clone();
    if let Err(e) = ctrlc::set_handler(move || c.store(true, Ordering::Relaxed)) {
        eprintln!("warning: Ctrl-C will not stop the experiment cleanly: {e}");
    }
    println!(
        "experiment {}: {} cars on {}, up to {} s; booting",
        exp.name,
        exp.cars.len(),
        exp.engine.name(),
        exp.duration_s
    );
    if exp.realtime || exp.engine == EngineKind::Qemu {
        // This process starts one world: its run directory is the first of this PID.
        let ground = std::env::temp_dir()
            .join(format!("almc-arena-{}-0", std::process::id()))
            .join("ground.sock");
        println!(
            "real time: talk to a car with `almc car --radio unix:{} --car ID status`",
            ground.display()
        );
    }
    if let Some(addr) = args.live {
        println!(
            "live: open ws://{addr} in Foxglove (Open connection > Foxglove WebSocket); the run goes at wall-clock pace"
        );
    }
    let opts = RunOptions { live: args.live };
    let result = experiment::run_with(
        &exp,
        &firmware,
        &out,
        &opts,
        &mut |p| println!("{p}"),
        &cancel,
    );
    match result {
        Ok(s) => {
            print_summary(&s, &out);
            if !s.failed_cars.is_empty() {
                ExitCode::from(3)
            } else if s.completed && s.all_arrived && s.collisions.is_empty() {
                ExitCode::SUCCESS
            } else {
                ExitCode::from(2)
            }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn secs(v: Option<f64>) -> String {
    v.map_or("-".into(), |t| format!("{t:.1} s"))
}

fn mm(v: Option<f64>) -> String {
    v.map_or("-".into(), |d| format!("{d:.0} mm"))
}

/// The summary on screen (the full one is `summary.json` in `out`).
pub fn print_summary(s: &experiment::Summary, out: &std::path::Path) {
    println!(
        "summary of {} ({:.1} s on {}{}):",
        s.name,
        s.duration_s,
        s.engine,
        if s.aborted { ", ABORTED" } else { "" }
    );
    for f in &s.failed_cars {
        println!("  car{} FAILED at {:.1} s: {}", f.car, f.t_s, f.reason);
    }
    for p in &s.phases {
        if p.kind == "goto" {
            println!(
                "  phase {} goto: {} at {:.1}..{:.1} s; every car arrived {}",
                p.phase,
                if p.completed {
                    "completed"
                } else if p.timed_out {
                    "TIMED OUT"
                } else {
                    "NOT completed"
                },
                p.start_s,
                p.end_s,
                secs(p.converged_s),
            );
            continue;
        }
        println!(
            "  phase {} {}: {} at {:.1}..{:.1} s; started {}, settled {}, converged {} (cars reported {}); error after settling {}, final {} (tolerance {:.0} mm)",
            p.phase,
            p.kind,
            if p.completed {
                "completed"
            } else if p.timed_out {
                "TIMED OUT"
            } else {
                "NOT completed"
            },
            p.start_s,
            p.end_s,
            secs(p.started_s),
            secs(p.settled_s),
            secs(p.converged_s),
            secs(p.reported_converged_s),
            p.error_after_settled.map_or("-".into(), |e| format!(
                "max {:.0} / p95 {:.0} / mean {:.0} mm",
                e.max_mm, e.p95_mm, e.mean_mm
            )),
            mm(p.final_error_mm),
            p.tolerance_mm
        );
    }
    for c in &s.cars {
        let lbc = &c.lbc;
        println!(
            "  car{}: {:.0} mm travelled{}, wall violations {}, radio states heard {}, LBC stream frames {} (errors {}, resets {}){}",
            c.id,
            c.distance_mm,
            match (c.final_error_mm, c.arrived) {
                (Some(e), true) => format!(", arrived in {}, {e:.0} mm from its last point", secs(c.arrival_s)),
                (Some(e), false) => format!(", NOT arrived, {e:.0} mm from its last point"),
                (None, _) => String::new(),
            },
            c.wall_violations.len(),
            c.states_heard,
            lbc["stream_frames"],
            lbc["errors"],
            lbc["resets"],
            c.processor_load
                .map_or(String::new(), |l| format!(", processor load {:.1} %", 100.0 * l)),
        );
    }
    let g = &s.radio["ground"];
    let m = &s.radio["medium"];
    println!(
        "  radio: {} requests, {} replies, {} failed, {} retries; channel {} packets, {} deliveries, {} collisions, {} random losses",
        g["requests"], g["replies"], g["failed"], g["retries"],
        m["packets_sent"], m["deliveries"], m["collisions"], m["random_losses"]
    );
    println!(
        "  min separation {}, collisions {}",
        mm(s.min_separation_mm),
        s.collisions.len()
    );
    println!("  outputs in {}", out.display());
    println!("  plot: {}", out.join("trajectories.svg").display());
    println!(
        "  report: {} (recording: {}, opens in Foxglove)",
        out.join("report.html").display(),
        out.join("run.mcap").display()
    );
}

#[cfg(test)]
mod tests {
    use super::loopback;

    #[test]
    fn the_live_view_listens_on_loopback_addresses_only() {
        assert_eq!(loopback("127.0.0.1:8765").unwrap().port(), 8765);
        assert!(loopback("[::1]:9000").is_ok());
        for bad in [
            "0.0.0.0:8765",
            "192.168.1.2:8765",
            "[::]:8765",
            "localhost",
            "8765",
            "127.0.0.1:0",
        ] {
            assert!(loopback(bad).is_err(), "{bad}");
        }
    }
}
