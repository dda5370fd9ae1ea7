//! `cargo xtask demo`: one car, end to end, with no hardware.
//!
//! The real firmware boots in QEMU; its LBC UART is attached to an emulated lower board
//! (`almc lbc-emu`) and its radio UART to the simulated radio medium (`almc radio hub`). A
//! scripted session then drives the car from the ground station with the same `almc car`
//! commands a researcher types: bring-up, status, LBC commands through the radio, MOVE_XY to
//! two points followed in the car's status, an LED pattern and STOP. Every command line is
//! printed, so the session can be repeated by hand; logs are kept under `target/demo/`.

use std::fs::{self, File};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use qemu_harness::{Qemu, SocketSpec, UartAttach};
use serde_json::Value;

use crate::{fw, install, stage, workspace_root};

/// The demo car's ID (stored in the emulated EEPROM's register 0x00).
const CAR: u8 = 1;
/// How close (tracking units, 2.5 mm) counts as having reached a MOVE_XY target.
const ARRIVED_UNITS: f64 = 10.0;
/// The two MOVE_XY targets (tracking units); the car starts at (300, 400) facing +Y.
const TARGETS: [(u16, u16); 2] = [(300, 600), (200, 450)];

/// A background process that is killed when dropped.
struct Background {
    name: &'static str,
    child: Child,
}

impl Drop for Background {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Background {
    fn spawn(name: &'static str, cmd: &mut Command, log: &Path) -> Result<Self> {
        let out = File::create(log).with_context(|| format!("creating {}", log.display()))?;
        let err = out.try_clone()?;
        let child = cmd
            .stdin(Stdio::null())
            .stdout(out)
            .stderr(err)
            .spawn()
            .with_context(|| format!("starting {name}"))?;
        Ok(Self { name, child })
    }

    fn check_alive(&mut self) -> Result<()> {
        if let Some(status) = self.child.try_wait()? {
            bail!("{} exited early ({status})", self.name);
        }
        Ok(())
    }
}

/// Removes the socket directory however the demo ends.
struct TempDir(PathBuf);

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// The ground station's side: runs `almc car` commands against the hub's ground socket.
struct Console {
    almc: PathBuf,
    ground: PathBuf,
    counter: PathBuf,
}

impl Console {
    fn args(&self) -> Vec<String> {
        vec![
            "car".into(),
            "--radio".into(),
            format!("unix:{}", self.ground.display()),
            "--car".into(),
            CAR.to_string(),
            "--state".into(),
            self.counter.display().to_string(),
        ]
    }

    /// Runs `almc car ... <words>` and prints what it printed.
    fn show(&self, words: &[&str]) -> Result<bool> {
        let mut args = self.args();
        args.extend(words.iter().map(|w| w.to_string()));
        println!("  $ almc {}", shell_words(&args));
        let out = Command::new(&self.almc)
            .args(&args)
            .output()
            .context("running almc car")?;
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            println!("    {line}");
        }
        for line in String::from_utf8_lossy(&out.stderr).lines() {
            println!("    {line}");
        }
        Ok(out.status.success())
    }

    /// Runs `almc car --json ... <words>` quietly and returns the reply document.
    fn json(&self, words: &[&str]) -> Result<Value> {
        let mut args = self.args();
        args.push("--json".into());
        args.extend(words.iter().map(|w| w.to_string()));
        let out = Command::new(&self.almc)
            .args(&args)
            .output()
            .context("running almc car")?;
        let text = String::from_utf8_lossy(&out.stdout);
        serde_json::from_str(text.trim())
            .with_context(|| format!("almc car printed no JSON: {text}"))
    }

    fn status(&self) -> Result<Value> {
        let doc = self.json(&["status"])?;
        if doc["ok"] != Value::Bool(true) {
            bail!("status failed: {doc}");
        }
        Ok(doc["reply"].clone())
    }
}

fn shell_words(args: &[String]) -> String {
    args.iter()
        .map(|a| {
            if a.contains(' ') {
                format!("'{a}'")
            } else {
                a.clone()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn wait_for_path(path: &Path, timeout: Duration) -> Result<()> {
    let start = Instant::now();
    while !path.exists() {
        if start.elapsed() > timeout {
            bail!("{} did not appear within {timeout:?}", path.display());
        }
        thread::sleep(Duration::from_millis(20));
    }
    Ok(())
}

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join("target"))
}

/// Prints the firmware log lines that arrived since `cursor`.
fn print_firmware_log(qemu: &Qemu, cursor: &mut usize) {
    let lines = qemu.log().lines();
    for line in lines.iter().skip(*cursor) {
        println!("    car{CAR} | {line}");
    }
    *cursor = lines.len().max(*cursor);
}

fn num(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or(f64::NAN)
}

pub fn run() -> Result<()> {
    let started = Instant::now();
    install::ensure_qemu()?;

    stage("build the firmware and the almc tool");
    let elf = fw::build("qemu_virt", true)?;
    crate::test::cargo(&["build", "--quiet", "-p", "almc"])?;
    let almc = target_dir().join("debug/almc");

    let logs = target_dir().join("demo");
    fs::create_dir_all(&logs)?;
    let sockets = TempDir(std::env::temp_dir().join(format!("almc-demo-{}", std::process::id())));
    fs::create_dir_all(&sockets.0)?;
    let lbc_sock = sockets.0.join("lbc.sock");
    let radio_sock = sockets.0.join("radio.sock");
    let ground_sock = sockets.0.join("ground.sock");

    stage("start the emulated lower board");
    let eeprom = logs.join("car1.eeprom");
    let _ = fs::remove_file(&eeprom);
    let mut emu = Background::spawn(
        "almc lbc-emu",
        Command::new(&almc)
            .args(["lbc-emu", "--listen"])
            .arg(format!("unix:{}", lbc_sock.display()))
            .arg("--eeprom")
            .arg(&eeprom)
            .args(["--id", &CAR.to_string(), "--log"]),
        &logs.join("lbc-emu.log"),
    )?;
    wait_for_path(&lbc_sock, Duration::from_secs(10))?;
    println!(
        "  almc lbc-emu --listen unix:{} --id {CAR} --log",
        lbc_sock.display()
    );

    stage("boot the firmware in QEMU");
    let qemu = Qemu::builder(&elf)
        .lbc(UartAttach::Connect(SocketSpec::Unix(lbc_sock.clone())))
        .radio(UartAttach::Listen(SocketSpec::Unix(radio_sock.clone())))
        .spawn()
        .context("starting QEMU")?;
    qemu.wait_for_log(|l| l.message.contains("ubc-app"), Duration::from_secs(20))
        .context("waiting for the firmware's banner")?;
    let mut cursor = 0;
    print_firmware_log(&qemu, &mut cursor);

    stage("join the car's radio to the simulated medium");
    wait_for_path(&radio_sock, Duration::from_secs(10))?;
    let mut hub = Background::spawn(
        "almc radio hub",
        Command::new(&almc)
            .args(["radio", "hub", "--node"])
            .arg(format!("car{CAR}=unix:{}", radio_sock.display()))
            .arg("--ground-listen")
            .arg(&ground_sock),
        &logs.join("radio-hub.log"),
    )?;
    wait_for_path(&ground_sock, Duration::from_secs(10))?;
    println!(
        "  almc radio hub --node car{CAR}=unix:{} --ground-listen {}",
        radio_sock.display(),
        ground_sock.display()
    );

    let console = Console {
        almc: almc.clone(),
        ground: ground_sock.clone(),
        counter: logs.join("counter"),
    };

    stage("bring-up: the firmware initialises the lower board on its own");
    let deadline = Instant::now() + Duration::from_secs(30);
    let status = loop {
        emu.check_alive()?;
        hub.check_alive()?;
        match console.status() {
            Ok(s) if s["phase"] == "running" && s["drive_enabled"] == true => break s,
            Ok(s) => println!("    phase {}, waiting", s["phase"]),
            Err(e) if Instant::now() > deadline => return Err(e),
            Err(_) => {}
        }
        if Instant::now() > deadline {
            bail!("the car did not finish bring-up within 30 s");
        }
        thread::sleep(Duration::from_millis(500));
    };
    print_firmware_log(&qemu, &mut cursor);
    println!(
        "  car {} up: x {} y {} heading {} mrad",
        status["car_id"], status["x"], status["y"], status["heading_mrad"]
    );

    stage("status and LBC commands through the radio");
    console.show(&["status"])?;
    console.show(&["lbc", "read-id"])?;
    console.show(&["lbc", "read-bt"])?;
    console.show(&["lbc", "read-xy"])?;

    let mut reached = Vec::new();
    for (i, (x, y)) in TARGETS.iter().enumerate() {
        stage(&format!("MOVE_XY to point {} ({x}, {y})", i + 1));
        if !console.show(&["lbc", "move-xy", &x.to_string(), &y.to_string()])? {
            bail!("MOVE_XY was not accepted");
        }
        let t0 = Instant::now();
        let mut last_print = Instant::now() - Duration::from_secs(1);
        loop {
            let s = console.status()?;
            let (cx, cy) = (num(&s, "x"), num(&s, "y"));
            let dist = ((cx - f64::from(*x)).powi(2) + (cy - f64::from(*y)).powi(2)).sqrt();
            if last_print.elapsed() >= Duration::from_millis(900) {
                println!(
                    "    t={:>4.1}s  x {:>3} y {:>3}  heading {:>4} mrad  v {:>4} mm/s  to go {:>5.1} units",
                    t0.elapsed().as_secs_f64(),
                    s["x"],
                    s["y"],
                    s["heading_mrad"],
                    s["velocity_mm_s"],
                    dist
                );
                last_print = Instant::now();
            }
            if dist <= ARRIVED_UNITS && num(&s, "velocity_mm_s").abs() < 1.0 {
                println!(
                    "    reached ({cx}, {cy}) in {:.1} s, {:.1} units ({:.0} mm) from the target",
                    t0.elapsed().as_secs_f64(),
                    dist,
                    dist * 2.5
                );
                reached.push((t0.elapsed(), dist));
                break;
            }
            if t0.elapsed() > Duration::from_secs(30) {
                bail!("the car did not reach ({x}, {y}) within 30 s (at {cx}, {cy})");
            }
            thread::sleep(Duration::from_millis(300));
        }
    }

    stage("LED pattern and STOP");
    console.show(&["lbc", "writ-led", "--green", "0x35", "--red", "0x0a"])?;
    console.show(&["lbc", "stop"])?;

    stage("final report");
    console.show(&["status"])?;
    console.show(&["stats"])?;
    print_firmware_log(&qemu, &mut cursor);
    drop(qemu);
    drop(hub);
    drop(emu);
    println!();
    println!(
        "demo: the car came up, answered every command over the radio and drove to both targets"
    );
    for (i, (t, d)) in reached.iter().enumerate() {
        println!(
            "  point {}: {:.1} s, {:.0} mm from the target",
            i + 1,
            t.as_secs_f64(),
            d * 2.5
        );
    }
    println!(
        "  logs: {} (lbc-emu.log, radio-hub.log); total {:.0} s",
        logs.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
