//! `almc experiment run FILE [--out DIR]`: plays an experiment file (see
//! `docs/experiments.md`) with QEMU cars in the arena and writes its results.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use arena::experiment::{self, Experiment};
use clap::{Args, Subcommand};

/// `almc experiment ...`
#[derive(Debug, Subcommand)]
pub enum ExperimentCommand {
    /// Run an experiment: progress each second, then CSV, JSONL, JSON and SVG outputs.
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
                println!("{}: {} cars, {} s: ok", e.name, e.cars.len(), e.duration_s);
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
            for c in &s.cars {
                println!(
                    "car{}: {} in {}, {:.0} mm travelled, final error {}, wall violations {}",
                    c.id,
                    if c.arrived { "arrived" } else { "NOT arrived" },
                    c.arrival_s.map_or("-".into(), |t| format!("{t:.1} s")),
                    c.distance_mm,
                    c.final_error_mm
                        .map_or("-".into(), |e| format!("{e:.0} mm")),
                    c.wall_violations.len()
                );
            }
            println!(
                "min separation {}, collisions {}; outputs in {}",
                s.min_separation_mm
                    .map_or("-".into(), |d| format!("{d:.0} mm")),
                s.collisions.len(),
                out.display()
            );
            if s.all_arrived && s.collisions.is_empty() {
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

fn qemu_harness_elf() -> Result<PathBuf, String> {
    arena::world::firmware_elf().map_err(|e| e.to_string())
}
