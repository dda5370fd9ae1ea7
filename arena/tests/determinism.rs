//! A run on the virtual-time engine is a function of its inputs: the same experiment file and
//! seed give byte-identical outputs (every file but `run.json`) across runs and across 1 and 2
//! worker threads, and a different seed gives different outputs.

#[path = "arena_common.rs"]
mod common;

use arena::experiment::{self, Experiment};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// Three cars meet by rendezvous over a lossy radio with noisy tracking: every random source
/// of the world is in play.
const EXPERIMENT: &str = r#"
name = "determinism"
duration_s = 8
seed = 7
[[cars]]
id = 1
x = 150
y = 200
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 200
heading_mrad = 1571
[[cars]]
id = 3
x = 300
y = 500
heading_mrad = 4712
[maneuver]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
[faults]
radio_loss = 0.1
tracking_noise_mm = 3.0
tracking_drop = 0.05
"#;

/// Every output file but `run.json`, by name.
fn outputs(exp: &Experiment, tag: &str) -> BTreeMap<String, Vec<u8>> {
    let elf = exp.engine.default_firmware().expect("firmware ELF");
    let out = std::env::temp_dir().join(format!("arena-det-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let cancel = AtomicBool::new(false);
    experiment::run(exp, &elf, &out, &mut |_| {}, &cancel).expect("experiment runs");
    let files = read_dir(&out);
    assert!(out.join("run.json").is_file());
    let _ = std::fs::remove_dir_all(&out);
    common::nothing_left_behind();
    files
}

fn read_dir(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != "run.json")
        .map(|n| {
            let bytes = std::fs::read(dir.join(&n)).unwrap();
            (n, bytes)
        })
        .collect()
}

fn differing(a: &BTreeMap<String, Vec<u8>>, b: &BTreeMap<String, Vec<u8>>) -> Vec<String> {
    let mut names: Vec<String> = a.keys().chain(b.keys()).cloned().collect();
    names.dedup();
    names.into_iter().filter(|n| a.get(n) != b.get(n)).collect()
}

#[test]
fn same_file_and_seed_give_the_same_bytes_on_any_number_of_threads() {
    let mut exp = Experiment::parse(EXPERIMENT).unwrap();
    exp.threads = 1;
    let one = outputs(&exp, "a");
    for name in [
        "summary.json",
        "events.jsonl",
        "car1.csv",
        "phases.csv",
        "trajectories.svg",
    ] {
        assert!(one.contains_key(name), "{name} missing: {:?}", one.keys());
    }
    let again = outputs(&exp, "b");
    assert!(
        differing(&one, &again).is_empty(),
        "two runs differ in {:?}",
        differing(&one, &again)
    );
    exp.threads = 2;
    let two = outputs(&exp, "c");
    assert!(
        differing(&one, &two).is_empty(),
        "1 and 2 threads differ in {:?}",
        differing(&one, &two)
    );
    exp.seed += 1;
    let other = outputs(&exp, "d");
    let diff = differing(&one, &other);
    assert!(
        diff.iter().any(|n| n.ends_with(".csv")),
        "another seed changed only {diff:?}"
    );
}
