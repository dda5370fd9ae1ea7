//! The harness itself, exercised in real QEMU with a tiny stand-in firmware
//! (`fixtures/standin.s`): log decoding, LBC echo, exit status and cleanup.

use std::path::{Path, PathBuf};
use std::time::Duration;

use qemu_harness::{skip_qemu_tests, Error, Level, Qemu, UartAttach};

fn standin() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/standin.elf")
}

fn process_alive(pid: u32) -> bool {
    Path::new(&format!("/proc/{pid}")).exists()
}

#[test]
fn standin_logs_echoes_exits_and_is_cleaned_up() {
    if skip_qemu_tests("standin_logs_echoes_exits_and_is_cleaned_up") {
        return;
    }
    let mut qemu = Qemu::builder(standin())
        .radio(UartAttach::Null)
        .spawn()
        .expect("spawn QEMU with the stand-in");
    let pid = qemu.pid();
    let dir = qemu.sock_dir().to_path_buf();
    assert!(dir.join("lbc.sock").exists());
    assert!(qemu.radio().is_none(), "radio is not harness-attached");

    let up = qemu
        .wait_for_log(|l| l.is(Level::Info, "standin up"), Duration::from_secs(10))
        .expect("boot line");
    assert_eq!(up.to_string(), "INFO  standin up timebase=10000000 Hz");
    assert_eq!(up.field("timebase"), Some("10000000"));

    let lbc = qemu.lbc().expect("lbc attached");
    let data: Vec<u8> = (0u8..=255)
        .filter(|&b| b != b'!')
        .cycle()
        .take(4000)
        .collect();
    lbc.write_all(&data).expect("write");
    let mut back = vec![0u8; data.len()];
    lbc.read_exact_timeout(&mut back, Duration::from_secs(10))
        .expect("echo");
    assert_eq!(back, data);
    assert!(lbc.drain().expect("drain").is_empty());

    let mut one = [0u8; 1];
    let err = lbc
        .read_exact_timeout(&mut one, Duration::from_millis(100))
        .expect_err("nothing more to echo");
    assert!(matches!(err, Error::UartTimeout { got: 0, .. }), "{err:?}");

    lbc.write_all(b"!").expect("write");
    let status = qemu.wait_exit(Duration::from_secs(10)).expect("exit");
    assert_eq!(status.code(), Some(1));
    let bye = qemu
        .wait_for_log(|l| l.level == Some(Level::Error), Duration::from_secs(5))
        .expect("error line");
    assert_eq!(bye.message, "standin exit requested");
    // The log's reader sees the end of the stream on its own thread, shortly after the exit.
    let t0 = std::time::Instant::now();
    while !qemu.log().is_closed() && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(qemu.log().is_closed());

    drop(qemu);
    assert!(!process_alive(pid), "QEMU {pid} still there");
    assert!(!dir.exists(), "socket dir {} left behind", dir.display());
}

#[test]
fn drop_kills_a_running_qemu_and_waits_fail_fast_after() {
    if skip_qemu_tests("drop_kills_a_running_qemu_and_waits_fail_fast_after") {
        return;
    }
    let mut qemu = Qemu::builder(standin())
        .radio(UartAttach::Null)
        .spawn()
        .expect("spawn");
    let pid = qemu.pid();
    let dir = qemu.sock_dir().to_path_buf();
    let err = qemu
        .wait_exit(Duration::from_millis(200))
        .expect_err("stand-in runs until told to stop");
    assert!(matches!(err, Error::ExitTimeout { .. }), "{err:?}");
    let log = qemu.log().clone();
    let mut lbc = qemu.take_lbc().expect("lbc");
    assert!(process_alive(pid));

    drop(qemu);
    assert!(!process_alive(pid), "QEMU {pid} survived drop");
    assert!(!dir.exists());
    let err = log
        .wait_for(|l| l.message == "never logged", Duration::from_secs(30))
        .expect_err("log is closed");
    assert!(matches!(err, Error::LogClosed { .. }), "{err:?}");
    let mut buf = [0u8; 1];
    let err = lbc
        .read_exact_timeout(&mut buf, Duration::from_secs(5))
        .expect_err("socket closed");
    assert!(matches!(err, Error::UartClosed { .. }), "{err:?}");
}

#[test]
fn qemu_failing_to_start_is_reported_with_its_stderr() {
    if skip_qemu_tests("qemu_failing_to_start_is_reported_with_its_stderr") {
        return;
    }
    let err = Qemu::builder(standin())
        .machine("no-such-machine")
        .spawn()
        .expect_err("bad machine");
    match err {
        Error::ExitedDuringStartup { stderr, .. } => {
            assert!(stderr.contains("unsupported machine type"), "{stderr}")
        }
        other => panic!("unexpected error {other:?}"),
    }
}
