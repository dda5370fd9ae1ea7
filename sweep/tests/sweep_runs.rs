//! Sweeps of real runs (every car's firmware on the soft core's model, `VTB_FIRMWARE` or
//! `cargo xtask fw --board softcore`): the same sweep gives the same `runs.csv`,
//! `aggregate.csv` and plots on 1 and 2 workers and from two shares merged; a sweep stopped
//! after a run resumes without doing that run again.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use sweep::{Event, Options, RunState, Shard, Sweep};

/// Two cars meet by rendezvous for 3 s of world time, with noisy tracking.
const BASE: &str = r#"
name = "sweep-test"
duration_s = 3
seed = 5
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
[faults]
tracking_noise_mm = 2.0
"#;

/// 2 radio losses x 2 seeds.
const SWEEP: &str = r#"
experiment = "base.toml"
seeds = 2
metrics = ["completed", "min_separation_mm", "phases.0.final_error_mm", "radio.ground.retries"]
[[grid]]
path = "faults.radio_loss"
values = [0.0, 0.3]
"#;

fn sweep() -> Sweep {
    Sweep::parse(SWEEP, Path::new("base.toml"), BASE).expect("sweep parses")
}

fn options(workers: usize, shard: Shard) -> Options {
    Options {
        workers,
        shard,
        firmware: arena::world::softcore_elf().expect("softcore firmware ELF"),
    }
}

fn run(s: &Sweep, out: &Path, opts: &Options) -> sweep::Report {
    let cancel = AtomicBool::new(false);
    sweep::run_sweep(s, out, opts, &mut |_| {}, &cancel).expect("sweep runs")
}

/// runs.csv, aggregate.csv and every plot, by name.
fn outputs(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut files = BTreeMap::new();
    for name in ["runs.csv", "aggregate.csv"] {
        files.insert(name.to_owned(), std::fs::read(dir.join(name)).unwrap());
    }
    for e in std::fs::read_dir(dir.join("plots")).unwrap() {
        let e = e.unwrap();
        let name = format!("plots/{}", e.file_name().to_string_lossy());
        files.insert(name, std::fs::read(e.path()).unwrap());
    }
    files
}

fn differing(a: &BTreeMap<String, Vec<u8>>, b: &BTreeMap<String, Vec<u8>>) -> Vec<String> {
    let mut names: Vec<&String> = a.keys().chain(b.keys()).collect();
    names.sort();
    names.dedup();
    names
        .into_iter()
        .filter(|n| a.get(*n) != b.get(*n))
        .cloned()
        .collect()
}

#[test]
fn same_outputs_on_one_and_two_workers_and_from_merged_shares() {
    let s = sweep();
    let tmp = tempfile::tempdir().unwrap();
    let one = tmp.path().join("one");
    let r = run(&s, &one, &options(1, Shard::ALL));
    assert_eq!((r.scope, r.ran, r.skipped), (4, 4, 0));
    assert_eq!(r.complete(), 4, "{:?}", r.outputs.rows);
    let a = outputs(&one);
    let csv = String::from_utf8_lossy(&a["runs.csv"]).into_owned();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), 5, "{csv}");
    assert!(rows[0].starts_with("point,seed,status,faults.radio_loss,duration_s,"));
    for (row, start) in rows[1..].iter().zip(["0,5,", "0,6,", "1,5,", "1,6,"]) {
        assert!(row.starts_with(start), "{row}");
        assert!(row.contains(",complete,"), "{row}");
    }
    assert_eq!(a.keys().filter(|k| k.starts_with("plots/")).count(), 8);

    let two = tmp.path().join("two");
    run(&s, &two, &options(2, Shard::ALL));
    let b = outputs(&two);
    assert!(
        differing(&a, &b).is_empty(),
        "1 and 2 workers differ in {:?}",
        differing(&a, &b)
    );

    let shares: Vec<PathBuf> = (0..2)
        .map(|i| tmp.path().join(format!("share{i}")))
        .collect();
    for (i, dir) in shares.iter().enumerate() {
        let r = run(&s, dir, &options(1, Shard::new(i, 2).unwrap()));
        assert_eq!((r.scope, r.complete()), (2, 2));
    }
    let merged = tmp.path().join("merged");
    let m = sweep::merge(&shares, &merged).expect("merge");
    assert_eq!((m.copied, m.missing.len()), (4, 0));
    let c = outputs(&merged);
    assert!(
        differing(&a, &c).is_empty(),
        "merged shares differ in {:?}",
        differing(&a, &c)
    );
    for run in s.plan.runs() {
        let dir = merged.join("runs").join(run.dir_name());
        assert_eq!(
            RunState::read(&dir),
            RunState::Complete,
            "{}",
            dir.display()
        );
        assert_eq!(
            std::fs::read(dir.join("summary.json")).unwrap(),
            std::fs::read(one.join("runs").join(run.dir_name()).join("summary.json")).unwrap()
        );
    }
}

#[test]
fn a_stopped_sweep_resumes_without_redoing_finished_runs() {
    let s = sweep();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let cancel = AtomicBool::new(false);
    let first = sweep::run_sweep(
        &s,
        &out,
        &options(1, Shard::ALL),
        &mut |ev| {
            if let Event::Finished { .. } = ev {
                cancel.store(true, Ordering::Relaxed);
            }
        },
        &cancel,
    )
    .expect("sweep runs");
    assert!(first.stopped);
    let done: Vec<String> = first
        .outputs
        .rows
        .iter()
        .filter(|r| r.state.is_finished())
        .map(|r| r.run.dir_name())
        .collect();
    assert!(!done.is_empty() && done.len() < 4, "{done:?}");
    assert!(first
        .outputs
        .rows
        .iter()
        .all(|r| r.state.is_finished()
            || matches!(r.state, RunState::Interrupted | RunState::Missing)));
    // run.json holds the run's wall-clock start and duration: a run done again rewrites it.
    let stamps: Vec<Vec<u8>> = done
        .iter()
        .map(|d| std::fs::read(out.join("runs").join(d).join("run.json")).unwrap())
        .collect();

    let second = run(&s, &out, &options(2, Shard::ALL));
    assert!(!second.stopped);
    assert_eq!(second.skipped, done.len());
    assert_eq!(second.ran, 4 - done.len());
    assert_eq!(second.complete(), 4);
    for (d, stamp) in done.iter().zip(&stamps) {
        let now = std::fs::read(out.join("runs").join(d).join("run.json")).unwrap();
        assert_eq!(&now, stamp, "{d} was run again");
    }
    // A third run does nothing.
    let third = run(&s, &out, &options(2, Shard::ALL));
    assert_eq!((third.skipped, third.ran), (4, 0));
    // A changed base experiment makes the runs stale.
    let changed = Sweep::parse(
        SWEEP,
        Path::new("base.toml"),
        &BASE.replace("= 3\n", "= 2\n"),
    )
    .unwrap();
    let cancel = AtomicBool::new(true);
    let fourth = sweep::run_sweep(
        &changed,
        &out,
        &options(1, Shard::ALL),
        &mut |_| {},
        &cancel,
    )
    .expect("sweep runs");
    assert_eq!(fourth.skipped, 0);
}
