//! `almc car` against a simulated car: the UBC program (ubc-app's library) and an emulated LBC
//! run in real time in a thread, the car's radio UART is a Unix socket the CLI connects to.

use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use lbc_emu::{Lbc, LbcConfig};
use serde_json::Value;
use ubc_app::program::{BytePort, Clock, Config, NoLog, Program};

struct WallClock(Instant);

impl Clock for WallClock {
    fn now_us(&self) -> u64 {
        self.0.elapsed().as_micros() as u64
    }
}

/// The LBC side: bytes the program writes go to the emulated LBC, what it sends comes back.
#[derive(Default)]
struct LbcWire {
    to_lbc: Vec<u8>,
    from_lbc: Vec<u8>,
}

impl BytePort for LbcWire {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        let n = buf.len().min(self.from_lbc.len());
        buf[..n].copy_from_slice(&self.from_lbc[..n]);
        self.from_lbc.drain(..n);
        n
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        self.to_lbc.extend_from_slice(bytes);
        bytes.len()
    }
}

/// The radio side: the connected CLI's socket (or nothing).
struct RadioWire(Option<UnixStream>);

impl BytePort for RadioWire {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        let Some(s) = self.0.as_mut() else {
            return 0;
        };
        match s.read(buf) {
            Ok(0) => {
                self.0 = None;
                0
            }
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::WouldBlock => 0,
            Err(_) => {
                self.0 = None;
                0
            }
        }
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        let Some(s) = self.0.as_mut() else {
            // Nobody listening: the bytes are lost on air.
            return bytes.len();
        };
        match s.write(bytes) {
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::WouldBlock => 0,
            Err(_) => {
                self.0 = None;
                bytes.len()
            }
        }
    }
}

struct Car {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    dir: PathBuf,
    path: PathBuf,
}

impl Car {
    fn start(name: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("almc-car-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("radio.sock");
        let listener = UnixListener::bind(&path).unwrap();
        listener.set_nonblocking(true).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let s = Arc::clone(&stop);
        let thread = thread::spawn(move || run_car(&listener, &s));
        Car {
            stop,
            thread: Some(thread),
            dir,
            path,
        }
    }

    fn almc(&self, args: &[&str], state: &Path) -> Output {
        let radio = format!("unix:{}", self.path.display());
        Command::new(env!("CARGO_BIN_EXE_almc"))
            .arg("car")
            .args(["--radio", &radio, "--state"])
            .arg(state)
            .args(args)
            .env_remove("ALMC_RADIO_KEY")
            .output()
            .unwrap()
    }
}

impl Drop for Car {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn run_car(listener: &UnixListener, stop: &AtomicBool) {
    let clock = WallClock(Instant::now());
    let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 7);
    let mut prog = Program::new(Config::default());
    let mut wire = LbcWire::default();
    let mut radio = RadioWire(None);
    while !stop.load(Ordering::Relaxed) {
        if radio.0.is_none() {
            if let Ok((s, _)) = listener.accept() {
                s.set_nonblocking(true).unwrap();
                radio.0 = Some(s);
            }
        }
        let now = clock.now_us();
        lbc.push_rx(now, &wire.to_lbc);
        wire.to_lbc.clear();
        lbc.step_until(now);
        lbc.drain_tx(now, &mut wire.from_lbc);
        prog.poll(&clock, &mut wire, &mut radio, &mut NoLog);
        thread::sleep(Duration::from_millis(1));
    }
}

fn json_of(out: &Output) -> Value {
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "not JSON ({e}): {text}\nstderr: {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

#[test]
fn car_console_over_a_socket() {
    let car = Car::start("console");
    let state = car.dir.join("counter");
    // Bring-up takes a moment; status says when the program runs.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let out = car.almc(&["--json", "status"], &state);
        if out.status.success() {
            let v = json_of(&out);
            if v["reply"]["phase"] == "running" {
                assert_eq!(v["reply"]["car_id"], 7);
                assert_eq!(v["reply"]["x"], 300);
                break;
            }
        }
        assert!(Instant::now() < deadline, "car never running");
        thread::sleep(Duration::from_millis(200));
    }
    let out = car.almc(&["--car", "7", "--json", "lbc", "read-id"], &state);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["reply"]["ReadId"], 7);

    let out = car.almc(&["--json", "lbc", "move-xy", "320", "480"], &state);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["lbc"], "answer");

    let out = car.almc(&["--json", "stats", "--page", "3"], &state);
    assert!(out.status.success(), "{out:?}");
    assert!(json_of(&out)["reply"]["counters"]["bringups"].as_u64() >= Some(1));

    // Text output and the maneuver commands.
    let out = car.almc(&["maneuver", "start", "300,420"], &state);
    assert!(out.status.success(), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stdout).contains("maneuver=started points=1"));
    let out = car.almc(&["maneuver", "stop"], &state);
    assert!(out.status.success(), "{out:?}");

    // Group maneuvers.
    let out = car.almc(
        &[
            "--json",
            "group",
            "start",
            "goto",
            "x=310",
            "y=430",
            "speed_mm_s=150",
        ],
        &state,
    );
    assert!(out.status.success(), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["group"], "started");
    let out = car.almc(&["--json", "status"], &state);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["group"]["kind"], "goto");
    assert_eq!(json_of(&out)["reply"]["maneuver"], true);
    // A waypoint goes to the running law (the go-to drives there instead).
    let out = car.almc(&["--json", "group", "waypoint", "300,300"], &state);
    assert!(out.status.success(), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["group"], "waypoint-set");
    let out = car.almc(
        &[
            "group",
            "start",
            "circle",
            "cx=300",
            "cy=400",
            "radius_units=100",
            "speed_mm_s=-120",
            "reverse=never",
        ],
        &state,
    );
    assert!(out.status.success(), "{out:?}");
    let out = car.almc(&["--json", "group", "stop"], &state);
    assert!(out.status.success(), "{out:?}");
    let out = car.almc(&["--json", "status"], &state);
    assert_eq!(json_of(&out)["reply"]["group"]["kind"], "none");
    let out = car.almc(&["group", "start", "rendezvous", "radius_units=0"], &state);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let out = car.almc(&["group", "start", "rendezvous", "radius=60"], &state);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("its parameters are radius_units"),
        "{out:?}"
    );
    // With no group maneuver running, a waypoint is refused.
    let out = car.almc(&["--json", "group", "waypoint", "300,300"], &state);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert_eq!(json_of(&out)["reply"]["refused"], "NoGroup");

    // A refusal is a non-zero exit with the reason.
    let out = car.almc(&["--json", "lbc", "drds"], &state);
    assert!(out.status.success(), "{out:?}");
    let out = car.almc(&["--json", "lbc", "move-sv", "0", "100"], &state);
    assert!(!out.status.success());
    assert_eq!(json_of(&out)["reply"]["refused"], "DriveDisabled");

    // The counter file only grows, so every session is accepted by the car.
    let c: u32 = std::fs::read_to_string(&state)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert!(c > 0);

    // A timeout beyond what the clock can represent is just a long wait.
    let out = car.almc(&["--timeout-ms", "18446744073709551615", "status"], &state);
    assert!(out.status.success(), "{out:?}");

    // Bad arguments: usage errors (exit 2), no panic.
    let out = car.almc(&["lbc", "move-xy", "700", "0"], &state);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let out = car.almc(&["--key", "12", "status"], &state);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let out = car.almc(&["maneuver", "start", "1"], &state);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
}

#[test]
fn wrong_key_gets_no_answer() {
    let car = Car::start("key");
    let state = car.dir.join("counter");
    // The car answers the default key...
    let deadline = Instant::now() + Duration::from_secs(20);
    while !car.almc(&["--car", "7", "status"], &state).status.success() {
        assert!(Instant::now() < deadline, "car never answered");
    }
    // ...and not another one.
    let out = car.almc(
        &[
            "--car",
            "7",
            "--timeout-ms",
            "2500",
            "--key",
            "00112233445566778899aabbccddeeff",
            "status",
        ],
        &state,
    );
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no reply") || err.contains("within"), "{err}");
}
