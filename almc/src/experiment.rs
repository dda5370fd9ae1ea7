//! `almc experiment run FILE [--out DIR]`: plays an experiment file (see
//! `docs/experiments.md`) with QEMU cars in the arena, shows its progress and summary, and
//! writes its results; `almc experiment check FILE` only checks the file.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use arena::experiment::{self, Experiment};
use clap::{Args, Subcommand};

/// `almc experiment ...`
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Run an experiment: progress each second, then a summary and CSV, JSONL, JSON and SVG
    /// outputs. Exit code 0: every phase completed without collision; 2: the run ended
    /// otherwise; 1: error.
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
    /// Firmware ELF (default: `UBC_FW_ELF`, else built with `cargo xtask fw`).
    #[arg(long, value_name = "ELF")]
    firmware: Option<PathBuf>,
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
    let exp = match Experiment::load(&args.file) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let firmware = match &args.firmware {
        Some(p) => p.clone(),
        None => match qemu_harness_elf() {
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
        "experiment {}: {} cars, up to {} s; booting",
        exp.name,
        exp.cars.len(),
        exp.duration_s
    );
    let result = experiment::run(&exp, &firmware, &out, &mut |p| println!("{p}"), &cancel);
    match result {
        Ok(s) => {
            print_summary(&s, &out);
            if s.completed && s.all_arrived && s.collisions.is_empty() {
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
    println!("summary of {} ({:.1} s):", s.name, s.duration_s);
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
            "  car{}: {:.0} mm travelled{}, wall violations {}, radio states heard {}, LBC stream frames {} (errors {}, resets {})",
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
}

fn qemu_harness_elf() -> Result<PathBuf, String> {
    arena::world::firmware_elf().map_err(|e| e.to_string())
}
