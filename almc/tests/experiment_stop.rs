//! Stopping a run: Ctrl-C ends any run within 5 s, with its outputs up to then on disk and
//! every child it started gone; a runner killed with SIGKILL takes its QEMU children with it,
//! and the next run removes the run directory (sockets) it left behind.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const FOUR_CARS: &str = r#"
name = "stop-test"
duration_s = 60
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
x = 150
y = 600
heading_mrad = 4712
[[cars]]
id = 4
x = 450
y = 600
heading_mrad = 4712
[maneuver]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 150
"#;

fn dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("almc-stop-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Starts `almc experiment run` on the four-car file; returns the child and a channel of its
/// stdout lines.
fn start(d: &Path, engine: &str) -> (Child, mpsc::Receiver<String>) {
    let file = d.join("exp.toml");
    std::fs::write(&file, FOUR_CARS).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(["experiment", "run"])
        .arg(&file)
        .arg("--out")
        .arg(d.join("out"))
        .args(["--engine", engine])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("almc runs");
    let (tx, rx) = mpsc::channel();
    let out = child.stdout.take().unwrap();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (child, rx)
}

/// Waits for a line containing `needle`.
fn wait_line(rx: &mpsc::Receiver<String>, needle: &str, limit: Duration) {
    let end = Instant::now() + limit;
    while Instant::now() < end {
        match rx.recv_timeout(Duration::from_millis(200)) {
            Ok(l) if l.contains(needle) => return,
            Ok(_) | Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => break,
        }
    }
    panic!("no line with {needle:?} within {limit:?}");
}

fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(ok.success());
}

/// Waits for the child to exit; the time it took.
fn exits_within(child: &mut Child, limit: Duration) -> (Duration, Option<i32>) {
    let t = Instant::now();
    loop {
        if let Some(st) = child.try_wait().unwrap() {
            return (t.elapsed(), st.code());
        }
        if t.elapsed() > limit {
            let _ = child.kill();
            panic!("still running {limit:?} after the signal");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn qemu_children_of(pid: u32) -> String {
    let out = Command::new("pgrep")
        .args(["-P", &pid.to_string(), "qemu-system"])
        .output()
        .expect("pgrep");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn ctrl_c_ends_a_virtual_time_run_with_its_outputs() {
    let d = dir("iss");
    let (mut child, rx) = start(&d, "iss");
    wait_line(&rx, "t=", Duration::from_secs(120));
    signal(&child, "-INT");
    let (took, code) = exits_within(&mut child, Duration::from_secs(5));
    eprintln!("ended {took:?} after Ctrl-C with {code:?}");
    let out = d.join("out");
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(run["state"], "cancelled", "{run}");
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("\"cancelled\": true"));
    let csv = std::fs::read_to_string(out.join("car1.csv")).unwrap();
    assert!(csv.lines().count() > 5, "{csv}");
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn qemu_run_ctrl_c_and_sigkill_leave_no_child_and_no_stale_socket() {
    if qemu_harness::skip_qemu_tests(
        "qemu_run_ctrl_c_and_sigkill_leave_no_child_and_no_stale_socket",
    ) {
        return;
    }
    // Ctrl-C during bring-up: out within 5 s, its QEMUs gone.
    let d = dir("qemu-int");
    let (mut child, rx) = start(&d, "qemu");
    wait_line(&rx, "booting", Duration::from_secs(30));
    std::thread::sleep(Duration::from_millis(1500));
    let pid = child.id();
    signal(&child, "-INT");
    exits_within(&mut child, Duration::from_secs(5));
    assert_eq!(qemu_children_of(pid), "", "QEMU left after Ctrl-C");
    let _ = std::fs::remove_dir_all(&d);

    // SIGKILL: the QEMUs die with it; its run directory is left, and the next world removes it.
    let d = dir("qemu-kill");
    let (mut child, rx) = start(&d, "qemu");
    wait_line(&rx, "bring-up", Duration::from_secs(60));
    let pid = child.id();
    let run_dir = std::env::temp_dir().join(format!("almc-arena-{pid}-0"));
    assert!(run_dir.is_dir(), "{}", run_dir.display());
    signal(&child, "-KILL");
    exits_within(&mut child, Duration::from_secs(5));
    let end = Instant::now() + Duration::from_secs(5);
    while !qemu_children_of(1).is_empty() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(100));
    }
    let orphans = Command::new("pgrep")
        .args(["-f", &format!("almc-arena-{pid}-")])
        .output()
        .unwrap();
    assert!(
        orphans.stdout.is_empty(),
        "QEMU survived its runner: {}",
        String::from_utf8_lossy(&orphans.stdout)
    );
    assert!(
        run_dir.is_dir(),
        "a killed run cannot clean up after itself"
    );
    // A world that starts cleans up: run a short virtual-time experiment.
    let (mut child, rx) = start(&d, "iss");
    wait_line(&rx, "bring-up", Duration::from_secs(120));
    assert!(
        !run_dir.exists(),
        "stale run directory {} still there",
        run_dir.display()
    );
    signal(&child, "-INT");
    exits_within(&mut child, Duration::from_secs(5));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_killed_run_leaves_its_data_up_to_then_marked_incomplete() {
    let d = dir("iss-kill");
    let (mut child, rx) = start(&d, "iss");
    // Two progress lines: the maneuvers have run for two seconds of world time, so at least
    // one flush of the outputs has happened.
    wait_line(&rx, "t=  2.0s", Duration::from_secs(120));
    signal(&child, "-KILL");
    exits_within(&mut child, Duration::from_secs(5));
    let out = d.join("out");
    let run: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(run["state"], "incomplete", "{run}");
    assert!(!out.join("summary.json").exists());
    for car in 1..=4 {
        let csv = std::fs::read_to_string(out.join(format!("car{car}.csv"))).unwrap();
        let rows = csv.lines().count() - 1;
        assert!(rows >= 10, "car{car}.csv has {rows} rows");
        for row in csv.lines().skip(1) {
            assert_eq!(row.split(',').count(), 5, "a torn row: {row:?}");
        }
    }
    let events = std::fs::read_to_string(out.join("events.jsonl")).unwrap();
    assert!(events.lines().count() >= 5);
    for line in events.lines() {
        serde_json::from_str::<serde_json::Value>(line).expect("every flushed event is whole");
    }
    assert!(events.contains("\"phase-started\""));
    let _ = std::fs::remove_dir_all(&d);
}
