//! The whole chain with the real pieces: `almc car` (the user's console) on the radio UART of
//! the firmware running in QEMU, whose LBC UART is attached to an emulated lower board. Every
//! LBC command of Table 3-2 is issued with `almc`, reaches the emulated LBC through the radio
//! and the firmware, and its answer comes back to `almc`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use lbc_emu::lbc::LogEvent;
use lbc_emu::server::{ListenAddr, Server};
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::CommandKind;
use qemu_harness::{firmware_elf, skip_qemu_tests, Qemu, SocketSpec, UartAttach};
use serde_json::Value;

const CAR: u8 = 5;

/// An emulated LBC behind a Unix socket, recording the commands it executed.
struct LbcServer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    commands: Arc<Mutex<Vec<CommandKind>>>,
}

impl LbcServer {
    fn start(path: &Path) -> Self {
        let server = Server::bind(&ListenAddr::Unix(path.to_path_buf())).expect("bind LBC socket");
        let stop = Arc::new(AtomicBool::new(false));
        let commands = Arc::new(Mutex::new(Vec::new()));
        let (s, c) = (Arc::clone(&stop), Arc::clone(&commands));
        let thread = thread::spawn(move || {
            let mut cfg = LbcConfig::default();
            cfg.log = true;
            let mut lbc = Lbc::with_memory_eeprom(cfg, CAR);
            let _ = server.run(
                &mut lbc,
                &s,
                &mut |e| {
                    if let LogEvent::Command(cmd) = &e.event {
                        c.lock().unwrap_or_else(|p| p.into_inner()).push(cmd.kind());
                    }
                },
                &mut |_| {},
            );
        });
        Self {
            stop,
            thread: Some(thread),
            commands,
        }
    }

    fn executed(&self, kind: CommandKind) -> usize {
        let log = self.commands.lock().unwrap_or_else(|p| p.into_inner());
        log.iter().filter(|k| **k == kind).count()
    }
}

impl Drop for LbcServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Runs `almc car --json ... lbc <words>` and returns its JSON document.
fn almc_lbc(radio: &Path, state: &Path, words: &[&str]) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_almc"))
        .arg("car")
        .arg("--radio")
        .arg(format!("unix:{}", radio.display()))
        .args(["--car", &CAR.to_string(), "--json", "--state"])
        .arg(state)
        .arg("lbc")
        .args(words)
        .output()
        .expect("run almc");
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.trim()).unwrap_or_else(|e| {
        panic!(
            "almc car lbc {words:?}: no JSON ({e}): {text} {}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

#[test]
fn every_lbc_command_from_almc_reaches_the_lbc_through_radio_and_firmware() {
    if skip_qemu_tests("every_lbc_command_from_almc_reaches_the_lbc_through_radio_and_firmware") {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let lbc_sock: PathBuf = dir.path().join("lbc.sock");
    let radio_sock: PathBuf = dir.path().join("radio.sock");
    let state = dir.path().join("counter");
    let lbc = LbcServer::start(&lbc_sock);
    let qemu = Qemu::builder(firmware_elf().expect("firmware ELF"))
        .lbc(UartAttach::Connect(SocketSpec::Unix(lbc_sock.clone())))
        .radio(UartAttach::Listen(SocketSpec::Unix(radio_sock.clone())))
        .spawn()
        .expect("start QEMU");
    qemu.wait_for_log(|l| l.message.contains("lbc up"), Duration::from_secs(30))
        .expect("the firmware brings the LBC up");

    // (words, command the LBC must have executed); the order keeps the car still while it
    // calibrates and re-enables the drive after INIT before moving.
    let script: &[(&[&str], CommandKind)] = &[
        (&["read-id"], CommandKind::ReadId),
        (&["read-xy"], CommandKind::ReadXy),
        (&["read-sv"], CommandKind::ReadSv),
        (&["read-ay"], CommandKind::ReadAy),
        (&["read-pry"], CommandKind::ReadPry),
        (&["read-bt"], CommandKind::ReadBt),
        (&["read-rs"], CommandKind::ReadRs),
        (&["read-hd"], CommandKind::ReadHd),
        (&["read-sf"], CommandKind::ReadSf),
        (&["read-par", "3"], CommandKind::ReadPar),
        (&["upd-par", "3", "512"], CommandKind::UpdPar),
        (
            &["writ-led", "--green", "0x35", "--red", "0x0a"],
            CommandKind::WritLed,
        ),
        (
            &["writ-gpo", "--gpio0", "0x25", "--gpio1", "0x0a"],
            CommandKind::WritGpo,
        ),
        (&["writ-ep", "0x22", "0x1234"], CommandKind::WritEp),
        (&["read-ep", "0x22"], CommandKind::ReadEp),
        (&["calb-gs"], CommandKind::CalbGs),
        (&["calb-st"], CommandKind::CalbSt),
        (&["calb-dm"], CommandKind::CalbDm),
        (&["cmep"], CommandKind::Cmep),
        (&["rsep"], CommandKind::Rsep),
        (&["move-sv", "0", "100"], CommandKind::MoveSv),
        (&["stop"], CommandKind::Stop),
        (&["stds"], CommandKind::Stds),
        (&["sten"], CommandKind::Sten),
        (&["drds"], CommandKind::Drds),
        (&["dren"], CommandKind::Dren),
        (&["init"], CommandKind::Init),
        (&["upd-sf", "0x38016"], CommandKind::UpdSf),
        (&["sten"], CommandKind::Sten),
        (&["dren"], CommandKind::Dren),
        (&["move-xy", "320", "480"], CommandKind::MoveXy),
        (&["stop"], CommandKind::Stop),
    ];
    for (words, kind) in script {
        let before = lbc.executed(*kind);
        let doc = almc_lbc(&radio_sock, &state, words);
        assert_eq!(
            doc["ok"],
            Value::Bool(true),
            "almc car lbc {words:?}: {doc}"
        );
        assert_eq!(
            doc["reply"]["lbc"], "answer",
            "almc car lbc {words:?}: {doc}"
        );
        assert!(
            lbc.executed(*kind) > before,
            "{kind:?} did not reach the emulated LBC ({doc})"
        );
        if words[0] == "read-ep" {
            assert!(
                doc.to_string().contains("4660"),
                "READ_EP 0x22 returns 0x1234: {doc}"
            );
        }
    }
    // Every command of Table 3-2 went through.
    for &kind in CommandKind::ALL {
        assert!(lbc.executed(kind) > 0, "{kind:?} never reached the LBC");
    }

    // A command the LBC rejects comes back as its specific error (READ_EP of a register
    // below the user registers: 0x91).
    let doc = almc_lbc(&radio_sock, &state, &["read-ep", "0x10"]);
    assert_eq!(doc["ok"], Value::Bool(false), "{doc}");
    assert_eq!(doc["reply"]["lbc"], "error", "{doc}");
    assert_eq!(doc["reply"]["error_header"], "0x91", "{doc}");
    drop(qemu);
    drop(lbc);
}
