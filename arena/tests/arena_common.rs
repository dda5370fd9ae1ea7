// Shared by the arena_* QEMU tests (included with `#[path]`, not a test of its own).
#![allow(dead_code)]

use arena::experiment::{self, Experiment, Summary};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::AtomicBool;

/// What a run left behind.
#[derive(Debug)]
pub struct Outputs {
    /// The summary.
    pub summary: Summary,
    /// `summary.json`, parsed.
    pub doc: Value,
    /// `phases.csv` rows: (t, phase, error_mm).
    pub errors: Vec<(f64, usize, f64)>,
    /// `events.jsonl`, parsed.
    pub events: Vec<Value>,
    /// Each car's trajectory from `car<ID>.csv` (in `[[cars]]` order): `(t, x_mm, y_mm)`.
    pub tracks: Vec<Vec<(f64, f64, f64)>>,
}

impl Outputs {
    /// Times (s since the first phase started, like `phases.csv`) at which a car reported that
    /// the firmware stopped it: it lost its LBC stream or the user link. On a real-time
    /// simulation this happens when the whole machine stalls for longer than the firmware's
    /// stream timeout (300 ms).
    pub fn stalls(&self) -> Vec<f64> {
        let t0 = self
            .events
            .iter()
            .find(|e| e["event"] == "phase-started")
            .and_then(|e| e["t"].as_f64())
            .unwrap_or(0.0);
        self.events
            .iter()
            .filter(|e| {
                e["event"]
                    .as_str()
                    .is_some_and(|n| n.contains("LbcLost") || n.contains("UserLinkLost"))
            })
            .filter_map(|e| e["t"].as_f64())
            .map(|t| t - t0)
            .collect()
    }
}

/// Runs `toml` with the real firmware, checks every output parses, returns the summary
/// and the summary document.
pub fn run_and_check(toml: &str, tag: &str) -> (Summary, Value) {
    let o = run_full(toml, tag);
    (o.summary, o.doc)
}

/// Runs `toml` with the real firmware, checks every output parses, returns them.
pub fn run_full(toml: &str, tag: &str) -> Outputs {
    let exp = Experiment::parse(toml).expect("experiment parses");
    let elf = exp.engine.default_firmware().expect("firmware ELF");
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
    let events = std::fs::read_to_string(out.join("events.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let csv = std::fs::read_to_string(out.join("phases.csv")).unwrap();
    let mut rows = csv.lines();
    assert_eq!(rows.next(), Some("t,phase,error_mm"));
    let errors = rows
        .map(|r| {
            let c: Vec<&str> = r.split(',').collect();
            assert_eq!(c.len(), 3, "{r}");
            (
                c[0].parse().unwrap(),
                c[1].parse().unwrap(),
                c[2].parse().unwrap(),
            )
        })
        .collect();
    let tracks = exp
        .cars
        .iter()
        .map(|car| {
            let csv = std::fs::read_to_string(out.join(format!("car{}.csv", car.id))).unwrap();
            csv.lines()
                .skip(1)
                .map(|row| {
                    let c: Vec<f64> = row.split(',').map(|v| v.parse().unwrap()).collect();
                    (c[0], c[1], c[2])
                })
                .collect()
        })
        .collect();
    nothing_left_behind();
    let _ = std::fs::remove_dir_all(&out);
    Outputs {
        summary,
        doc,
        errors,
        events,
        tracks,
    }
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
    assert!(events.contains("\"phase-started\""));
    // run.json names every car's firmware and the SHA-256 of its bytes.
    let info: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    let fw = info["firmware"].as_array().expect("firmware list");
    assert_eq!(fw.len(), exp.cars.len(), "{info:#}");
    for (f, car) in fw.iter().zip(&exp.cars) {
        assert_eq!(f["car"].as_u64(), Some(u64::from(car.id)), "{info:#}");
        let elf = f["elf"].as_str().expect("ELF path");
        let sha = f["sha256"].as_str().expect("SHA-256");
        let image = f["image_sha256"].as_str().expect("image SHA-256");
        for h in [sha, image] {
            assert!(
                h.len() == 64 && h.bytes().all(|b| b.is_ascii_hexdigit()),
                "{info:#}"
            );
        }
        assert!(std::path::Path::new(elf).is_file(), "{info:#}");
    }
    let svg = std::fs::read_to_string(out.join("trajectories.svg")).unwrap();
    assert!(svg.starts_with("<svg ") && svg.trim_end().ends_with("</svg>"));
    for car in &exp.cars {
        let entry = format!("\ncar {}\n", car.id);
        assert!(svg.contains(&entry), "no legend entry of car {}", car.id);
    }
    for plot in ["trajectories", "phase_error", "separation", "radio"] {
        let png = std::fs::read(out.join(format!("{plot}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{plot}.png");
        assert!(out.join(format!("{plot}.svg")).is_file(), "{plot}.svg");
    }
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(report.contains("data:image/png;base64,"));
    let mcap = std::fs::read(out.join("run.mcap")).unwrap();
    assert!(mcap.starts_with(b"\x89MCAP0\r\n") && mcap.ends_with(b"\x89MCAP0\r\n"));
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
