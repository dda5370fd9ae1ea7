//! `cargo xtask demo`: four cars form a wedge behind a leader, break up to the corners of the
//! arena and meet again by rendezvous.
//!
//! The demo builds the firmware for the soft core and the `almc` tool, then plays
//! `experiments/demo-formation-rendezvous.toml` with `almc experiment run`, the same runner a
//! researcher uses: every car is the real firmware on the soft core's cycle-accurate model, in
//! virtual time, with an emulated lower board, an overhead tracker and a shared radio channel.
//! Progress is printed each second of world time; the run ends with the summary and the path
//! of the trajectory plot. The outputs are kept under `target/demo/`; the same file and seed
//! give the same outputs on any machine.

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::{fw, stage, workspace_root};

/// The experiment the demo plays, relative to the workspace root.
const EXPERIMENT: &str = "experiments/demo-formation-rendezvous.toml";

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"))
}

pub fn run() -> Result<()> {
    let started = Instant::now();

    stage("build the firmware and the almc tool");
    let elf = fw::build("softcore", true)?;
    crate::test::cargo(&["build", "--quiet", "-p", "almc"])?;
    let almc = target_dir().join("debug/almc");
    let experiment = workspace_root().join(EXPERIMENT);
    let out = target_dir().join("demo").join("demo-formation-rendezvous");
    let built = started.elapsed();

    stage("four cars: wedge formation, break-up, rendezvous");
    println!(
        "  $ almc experiment run {EXPERIMENT} --firmware {} --out {}",
        elf.display(),
        out.display()
    );
    let status = Command::new(&almc)
        .args(["experiment", "run"])
        .arg(&experiment)
        .arg("--firmware")
        .arg(&elf)
        .arg("--out")
        .arg(&out)
        .args(["--engine", "iss", "--threads", "2"])
        .current_dir(workspace_root())
        .status()
        .context("running almc experiment run")?;
    println!();
    match status.code() {
        Some(0) => println!(
            "demo: every phase completed without collision ({:.0} s, of which {:.0} s building)",
            started.elapsed().as_secs_f64(),
            built.as_secs_f64()
        ),
        Some(2) => println!(
            "demo: the run ended, but not every phase completed or cars came too close (see the summary above)"
        ),
        Some(3) => println!("demo: a car's firmware stopped (see the summary above)"),
        _ => bail!("almc experiment run failed ({status})"),
    }
    println!(
        "  plot: {}\n  summary: {}",
        out.join("trajectories.svg").display(),
        out.join("summary.json").display()
    );
    if status.code() != Some(0) {
        bail!("the demo's experiment did not complete");
    }
    Ok(())
}
