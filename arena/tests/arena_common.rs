// Shared by the arena_* QEMU tests (included with `#[path]`, not a test of its own).
#![allow(dead_code)]

use arena::experiment::{self, Experiment, Summary};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;

/// Runs `toml` with the real firmware, checks every output parses, returns the summary
/// document and the out dir.
pub fn run_and_check(toml: &str, tag: &str) -> (Summary, Value) {
    let exp = Experiment::parse(toml).expect("experiment parses");
    let elf = qemu_harness::firmware_elf().expect("firmware ELF");
    let out: PathBuf =
        std::env::temp_dir().join(format!("arena-test-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cancel = AtomicBool::new(false);
    let mut lines = 0;
    let summary = experiment::run(
        &exp,
        &elf,
        &out,
        &mut |p| {
            lines += 1;
            eprintln!("{p}");
        },
        &cancel,
    )
    .expect("experiment runs");
    assert!(lines >= 1, "no progress line");
    let doc = check_outputs(&out, &exp);
    nothing_left_behind();
    let _ = std::fs::remove_dir_all(&out);
    (summary, doc)
}

fn check_outputs(out: &Path, exp: &Experiment) -> Value {
    for car in &exp.cars {
        let csv = std::fs::read_to_string(out.join(format!("car{}.csv", car.id))).unwrap();
        let mut rows = csv.lines();
        assert_eq!(rows.next(), Some("t,x_mm,y_mm,heading,v"));
        let mut n = 0;
        for row in rows {
            let cols: Vec<f64> = row.split(',').map(|c| c.parse().unwrap()).collect();
            assert_eq!(cols.len(), 5, "{row}");
            n += 1;
        }
        assert!(n > 10, "car {}: only {n} samples", car.id);
    }
    let events = std::fs::read_to_string(out.join("events.jsonl")).unwrap();
    for line in events.lines() {
        let v: Value = serde_json::from_str(line).unwrap();
        assert!(v["t"].is_number() && v["event"].is_string(), "{line}");
    }
    assert!(events.contains("\"maneuver-started\""));
    let svg = std::fs::read_to_string(out.join("trajectories.svg")).unwrap();
    assert!(svg.starts_with("<svg ") && svg.trim_end().ends_with("</svg>"));
    assert_eq!(svg.matches("<polyline").count(), exp.cars.len());
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    summary
}

/// No QEMU child of this process survives, and no world socket directory is left.
pub fn nothing_left_behind() {
    let me = std::process::id();
    let children = Command::new("pgrep")
        .args(["-P", &me.to_string(), "qemu-system"])
        .output()
        .expect("pgrep");
    assert!(
        children.stdout.is_empty(),
        "QEMU left behind: {}",
        String::from_utf8_lossy(&children.stdout)
    );
    let prefix = format!("almc-arena-{me}-");
    let left: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "socket dirs left: {left:?}");
}
