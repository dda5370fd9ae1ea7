//! EEPROM durability: the real `lbc-emu` process is SIGKILLed at random moments of CMEP
//! traffic, and the EEPROM file must always parse and hold either the previous or the new
//! committed parameter set, never a mix and never garbage.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

use lbc_emu::eeprom::{reg, FileStore};
use lbc_link::{Command, Deframer, LbcMessage, Param, ParamValue, Reply};

struct Emulator(Child);

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn spawn(sock: &Path, eeprom: &Path) -> (Emulator, UnixStream) {
    let child = Process::new(env!("CARGO_BIN_EXE_lbc-emu"))
        .arg("--listen")
        .arg(format!("unix:{}", sock.display()))
        .arg("--eeprom")
        .arg(eeprom)
        .args(["--id", "3", "--eeprom-write-pause-ms", "30"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("lbc-emu starts");
    let emu = Emulator(child);
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        if let Ok(s) = UnixStream::connect(sock) {
            s.set_read_timeout(Some(Duration::from_millis(5))).unwrap();
            return (emu, s);
        }
        assert!(Instant::now() < deadline, "lbc-emu did not start listening");
        std::thread::sleep(Duration::from_millis(5));
    }
}

fn send(s: &mut UnixStream, cmd: Command) {
    let mut buf = [0u8; 16];
    let n = cmd.emit(&mut buf).unwrap();
    s.write_all(&buf[..n]).unwrap();
}

/// Reads messages until `pred` accepts one or `deadline` passes (or `abort` says so).
fn wait_for(
    s: &mut UnixStream,
    d: &mut Deframer,
    deadline: Instant,
    mut abort: impl FnMut() -> bool,
    pred: impl Fn(&LbcMessage) -> bool,
) -> bool {
    let mut buf = [0u8; 64];
    while Instant::now() < deadline && !abort() {
        match s.read(&mut buf) {
            Ok(0) => return false,
            Ok(n) => {
                for &b in &buf[..n] {
                    if let Some(Ok(m)) = d.push(b) {
                        if LbcMessage::parse(&m).is_ok_and(|m| pred(&m)) {
                            return true;
                        }
                    }
                }
            }
            Err(_) => {}
        }
    }
    false
}

fn temp_file_present(dir: &Path) -> bool {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .any(|e| e.file_name().to_string_lossy().contains(".tmp."))
}

#[test]
fn eeprom_survives_sigkill_during_cmep() {
    let dir = tempfile::tempdir().unwrap();
    let eeprom = dir.path().join("car.eeprom");
    let sock = dir.path().join("lbc.sock");
    // xorshift: a fixed sequence of kill moments.
    let mut seed: u64 = 0x2545_F491_4F6C_DD1D;
    let mut rand = move |n: u64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed % n
    };
    // (P gain, I gain) last acknowledged, and the pair being committed.
    let mut committed: (u16, u16) = (512, 5120);
    let mut value: u16 = 1000;
    let mut mid_commit_kills = 0;
    for round in 0..10 {
        let (mut emu, mut s) = spawn(&sock, &eeprom);
        let mut d = Deframer::new();
        // Even rounds: one parameter update, killed as soon as its commit is under way;
        // odd rounds: continuous traffic, killed at a random moment.
        let watch_temp = round % 2 == 0;
        let kill_at =
            Instant::now() + Duration::from_millis(if watch_temp { 2000 } else { 50 + rand(400) });
        let mut in_flight: Option<(u16, u16)> = None;
        'traffic: loop {
            value += 1;
            let pair = (value, value + 7);
            for (p, v) in [(Param::MotorPGain, pair.0), (Param::MotorIGain, pair.1)] {
                let pv = ParamValue::new(p, v as i16).unwrap();
                send(&mut s, Command::UpdPar(pv));
                let acked = wait_for(
                    &mut s,
                    &mut d,
                    kill_at,
                    || false,
                    |m| *m == LbcMessage::Reply(Reply::Echo(Command::UpdPar(pv))),
                );
                if !acked {
                    break 'traffic;
                }
            }
            in_flight = Some(pair);
            send(&mut s, Command::Cmep);
            let dirp = dir.path().to_owned();
            let acked = wait_for(
                &mut s,
                &mut d,
                kill_at,
                || watch_temp && temp_file_present(&dirp),
                |m| *m == LbcMessage::Reply(Reply::Echo(Command::Cmep)),
            );
            if !acked || watch_temp || Instant::now() >= kill_at {
                break;
            }
            committed = pair;
            in_flight = None;
        }
        emu.0.kill().unwrap();
        emu.0.wait().unwrap();
        if temp_file_present(dir.path()) {
            mid_commit_kills += 1;
        }
        let image = FileStore::load(&eeprom)
            .unwrap_or_else(|e| panic!("round {round}: EEPROM file damaged: {e}"));
        let got = (image.get(reg::MPG).unwrap(), image.get(reg::MIG).unwrap());
        assert_eq!(image.car_id(), 3);
        if Some(got) == in_flight {
            committed = got;
        } else {
            assert_eq!(
                got, committed,
                "round {round}: neither old nor new value set"
            );
        }
        drop(s);
    }
    eprintln!("{mid_commit_kills} of 10 kills landed inside a commit");
    assert!(
        mid_commit_kills >= 3,
        "only {mid_commit_kills} kills landed inside a commit"
    );
    // A restarted emulator boots with the committed parameters.
    let (_emu, mut s) = spawn(&sock, &eeprom);
    let mut d = Deframer::new();
    send(&mut s, Command::ReadPar(Param::MotorPGain));
    let want = ParamValue::new(Param::MotorPGain, committed.0 as i16).unwrap();
    assert!(wait_for(
        &mut s,
        &mut d,
        Instant::now() + Duration::from_secs(2),
        || false,
        |m| *m == LbcMessage::Reply(Reply::ReadPar(want))
    ));
}
