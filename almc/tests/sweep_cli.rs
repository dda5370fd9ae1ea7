//! `almc sweep`: a sweep killed with SIGKILL in the middle resumes without doing its finished
//! runs again; `check` names a bad field; `slurm` writes a script for the sweep. The runs use
//! the soft-core firmware (`VTB_FIRMWARE`, else `cargo xtask fw --board softcore`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

const BASE: &str = r#"
name = "sweep-cli"
duration_s = 3
seed = 1
[[cars]]
id = 1
x = 200
y = 300
heading_mrad = 1571
[[cars]]
id = 2
x = 400
y = 300
heading_mrad = 1571
[maneuver]
kind = "rendezvous"
radius_units = 40
speed_mm_s = 200
"#;

/// 2 speeds x 3 seeds = 6 runs.
const SWEEP: &str = r#"
experiment = "base.toml"
seeds = 3
metrics = ["completed", "min_separation_mm"]
[[grid]]
path = "maneuver.speed_mm_s"
values = [150, 250]
"#;

fn dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("almc-sweep-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(d.join("base.toml"), BASE).unwrap();
    std::fs::write(d.join("sweep.toml"), SWEEP).unwrap();
    d
}

fn almc(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .output()
        .expect("almc runs")
}

/// Runs whose `run.json` says complete, by directory name, with that file's bytes.
fn complete_runs(out: &Path) -> Vec<(String, Vec<u8>)> {
    let mut done: Vec<(String, Vec<u8>)> = std::fs::read_dir(out.join("runs"))
        .map(|rd| {
            rd.filter_map(Result::ok)
                .filter_map(|e| {
                    let info = std::fs::read(e.path().join("run.json")).ok()?;
                    let complete = String::from_utf8_lossy(&info).contains("\"complete\"")
                        && e.path().join("summary.json").is_file();
                    complete.then(|| (e.file_name().to_string_lossy().into_owned(), info))
                })
                .collect()
        })
        .unwrap_or_default();
    done.sort();
    done
}

#[test]
fn a_killed_sweep_resumes_without_redoing_finished_runs() {
    let d = dir("kill");
    let out = d.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_almc"))
        .args([
            "sweep",
            "run",
            "sweep.toml",
            "--workers",
            "1",
            "--out",
            "out",
        ])
        .current_dir(&d)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("almc runs");
    let end = Instant::now() + Duration::from_secs(120);
    while complete_runs(&out).len() < 2 {
        assert!(Instant::now() < end, "no two runs finished in 120 s");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the sweep ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let before = complete_runs(&out);
    assert!(
        before.len() >= 2 && before.len() < 6,
        "{} runs finished",
        before.len()
    );

    let o = almc(&["sweep", "run", "sweep.toml", "--out", "out"], &d);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        o.status.code(),
        Some(0),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        stdout.contains(&format!(
            "6 runs: 6 complete, 0 failed, 0 still to do ({} kept from an earlier run, {} run now)",
            before.len(),
            6 - before.len()
        )),
        "{stdout}"
    );
    let after = complete_runs(&out);
    assert_eq!(after.len(), 6);
    for (name, info) in &before {
        let now = after.iter().find(|(n, _)| n == name).map(|(_, i)| i);
        assert_eq!(now, Some(info), "{name} was run again");
    }
    let csv = std::fs::read_to_string(out.join("runs.csv")).unwrap();
    assert_eq!(csv.lines().count(), 7);
    assert!(out.join("aggregate.csv").is_file());
    assert!(out.join("plots/min_separation_mm.png").is_file());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn check_names_a_bad_field_and_lists_points() {
    let d = dir("check");
    let o = almc(&["sweep", "check", "sweep.toml"], &d);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}");
    assert!(stdout.contains("2 points x 3 seeds = 6 runs"), "{stdout}");
    assert!(
        stdout.contains("point 1: maneuver.speed_mm_s = 250"),
        "{stdout}"
    );

    std::fs::write(
        d.join("bad.toml"),
        SWEEP.replace("maneuver.speed_mm_s", "maneuver.sped_mm_s"),
    )
    .unwrap();
    let o = almc(&["sweep", "run", "bad.toml"], &d);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("bad.toml: parameter `maneuver.sped_mm_s` = 150: the experiment rejects it: invalid experiment: phase 1: unknown field `sped_mm_s`"),
        "{stderr}"
    );
    assert!(
        !d.join("sweep-out").exists(),
        "nothing is written for a bad file"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn slurm_writes_a_job_array_script() {
    let d = dir("slurm");
    let o = almc(
        &[
            "sweep",
            "slurm",
            "sweep.toml",
            "--shards",
            "3",
            "--out",
            "out",
        ],
        &d,
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let script = std::fs::read_to_string(d.join("out/slurm.sh")).unwrap();
    let out = d.join("out");
    assert!(script.starts_with("#!/bin/bash"));
    assert!(script.contains("--array=0-2"), "{script}");
    assert!(
        script.contains("--shard \"$SLURM_ARRAY_TASK_ID/3\""),
        "{script}"
    );
    assert!(
        script.contains(&format!("sweep run {}", d.join("sweep.toml").display())),
        "{script}"
    );
    assert!(
        script.contains(&format!(
            "sweep merge {0}/shards/0 {0}/shards/1 {0}/shards/2 --into {0}",
            out.display()
        )),
        "{script}"
    );
    assert!(script.contains("--dependency=afterany:"), "{script}");
    let status = Command::new("bash")
        .arg("-n")
        .arg(d.join("out/slurm.sh"))
        .status()
        .unwrap();
    assert!(status.success(), "the script is not valid bash");
    let _ = std::fs::remove_dir_all(&d);
}
