//! The real-time socket front end: connect, talk, disconnect, reconnect.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::net::UnixStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use lbc_emu::server::{ListenAddr, Server, ServerEvent};
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, Deframer, LbcMessage, Reply};

/// Writes `cmd` and reads until a non-STREAM message arrives (at most 2 s).
fn exchange<S: Read + Write>(s: &mut S, cmd: Command) -> LbcMessage {
    let mut buf = [0u8; 16];
    let n = cmd.emit(&mut buf).unwrap();
    s.write_all(&buf[..n]).unwrap();
    let mut d = Deframer::new();
    let deadline = Instant::now() + Duration::from_secs(2);
    let mut byte = [0u8; 1];
    while Instant::now() < deadline {
        match s.read(&mut byte) {
            Ok(0) => panic!("server closed the connection"),
            Ok(_) => {
                if let Some(Ok(m)) = d.push(byte[0]) {
                    let msg = LbcMessage::parse(&m).unwrap();
                    if !matches!(msg, LbcMessage::Stream(_)) {
                        return msg;
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("{e}"),
        }
    }
    panic!("no reply to {cmd:?}");
}

fn serve(
    addr: ListenAddr,
) -> (
    ListenAddr,
    Arc<AtomicBool>,
    std::thread::JoinHandle<Vec<ServerEvent>>,
) {
    let server = Server::bind(&addr).unwrap();
    let bound = server.local_addr().clone();
    let stop = Arc::new(AtomicBool::new(false));
    let s = Arc::clone(&stop);
    let handle = std::thread::spawn(move || {
        let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 5);
        let mut events = Vec::new();
        server
            .run(&mut lbc, &s, &mut |_| {}, &mut |e| events.push(e))
            .unwrap();
        events
    });
    (bound, stop, handle)
}

fn read_id() -> LbcMessage {
    LbcMessage::Reply(Reply::ReadId(lbc_link::VehicleId::new(5).unwrap()))
}

#[test]
fn unix_socket_session_survives_reconnects() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lbc.sock");
    let (_, stop, handle) = serve(ListenAddr::Unix(path.clone()));
    for round in 0..3 {
        let mut s = UnixStream::connect(&path).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(100)))
            .unwrap();
        assert_eq!(
            exchange(&mut s, Command::Init),
            LbcMessage::Reply(Reply::Echo(Command::Init)),
            "round {round}"
        );
        assert_eq!(
            exchange(&mut s, Command::ReadId),
            read_id(),
            "round {round}"
        );
        // Half a command, then hang up: the next client starts clean.
        s.write_all(&[0xE9]).unwrap();
        drop(s);
        std::thread::sleep(Duration::from_millis(20));
    }
    stop.store(true, Ordering::Relaxed);
    let events = handle.join().unwrap();
    assert_eq!(
        events
            .iter()
            .filter(|e| **e == ServerEvent::Connected)
            .count(),
        3
    );
    assert!(!path.exists(), "socket file removed on shutdown");
}

#[test]
fn tcp_loopback_session() {
    let (bound, stop, handle) = serve("tcp:127.0.0.1:0".parse().unwrap());
    let ListenAddr::Tcp(addr) = bound else {
        panic!("{bound:?}")
    };
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    assert_eq!(exchange(&mut s, Command::ReadId), read_id());
    drop(s);
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    assert_eq!(exchange(&mut s, Command::ReadId), read_id());
    stop.store(true, Ordering::Relaxed);
    handle.join().unwrap();
}

/// Reads whatever arrives within `window` and returns the non-STREAM messages.
fn replies_within<S: Read>(s: &mut S, window: Duration) -> Vec<LbcMessage> {
    let mut d = Deframer::new();
    let mut got = Vec::new();
    let deadline = Instant::now() + window;
    let mut buf = [0u8; 256];
    while Instant::now() < deadline {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                for &b in &buf[..n] {
                    if let Some(Ok(m)) = d.push(b) {
                        let msg = LbcMessage::parse(&m).unwrap();
                        if !matches!(msg, LbcMessage::Stream(_)) {
                            got.push(msg);
                        }
                    }
                }
            }
            Err(_) => {}
        }
    }
    got
}

#[test]
fn half_a_frame_from_a_client_that_left_is_not_completed_by_the_next() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lbc.sock");
    let (_, stop, handle) = serve(ListenAddr::Unix(path.clone()));
    // READ_ID without its terminator: the header and the checksum byte.
    let mut full = [0u8; 8];
    let n = Command::ReadId.emit(&mut full).unwrap();
    assert_eq!(full[n - 1], 0xFF);
    let mut a = UnixStream::connect(&path).unwrap();
    a.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    assert_eq!(exchange(&mut a, Command::ReadId), read_id());
    a.write_all(&full[..n - 1]).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    drop(a);
    std::thread::sleep(Duration::from_millis(20));
    // The next client starts with a lone terminator (a common line resync): on a spliced
    // line it would complete the READ_ID the first client left half-sent.
    let mut b = UnixStream::connect(&path).unwrap();
    b.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    b.write_all(&[0xFF]).unwrap();
    let spliced = replies_within(&mut b, Duration::from_millis(400));
    assert!(
        spliced.is_empty(),
        "answered another client's half frame: {spliced:?}"
    );
    assert_eq!(exchange(&mut b, Command::ReadId), read_id());
    stop.store(true, Ordering::Relaxed);
    handle.join().unwrap();
}

#[test]
fn an_idle_client_does_not_keep_another_out() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lbc.sock");
    let (_, stop, handle) = serve(ListenAddr::Unix(path.clone()));
    // Connects, says nothing, never leaves.
    let idle = UnixStream::connect(&path).unwrap();
    std::thread::sleep(Duration::from_millis(50));
    let mut busy = UnixStream::connect(&path).unwrap();
    busy.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let t = Instant::now();
    // `exchange` waits 2 s for the answer; the handover comes after 1 s of silence.
    let mut buf = [0u8; 16];
    let n = Command::ReadId.emit(&mut buf).unwrap();
    let mut answered = false;
    while !answered && t.elapsed() < Duration::from_secs(4) {
        busy.write_all(&buf[..n]).unwrap();
        answered = replies_within(&mut busy, Duration::from_millis(300)).contains(&read_id());
    }
    assert!(answered, "the idle client kept the line");
    assert!(t.elapsed() < Duration::from_secs(3), "{:?}", t.elapsed());
    // The new client keeps the line while it talks, although the idle one is still there.
    for _ in 0..3 {
        assert_eq!(exchange(&mut busy, Command::ReadId), read_id());
    }
    drop(idle);
    stop.store(true, Ordering::Relaxed);
    let events = handle.join().unwrap();
    assert_eq!(
        events,
        [
            ServerEvent::Connected,
            ServerEvent::Disconnected,
            ServerEvent::Connected
        ]
    );
}

#[test]
fn a_second_emulator_on_the_same_eeprom_file_is_refused() {
    use std::process::{Command as Process, Stdio};
    let dir = tempfile::tempdir().unwrap();
    let eeprom = dir.path().join("car.eeprom");
    let run = |sock: &str| {
        Process::new(env!("CARGO_BIN_EXE_lbc-emu"))
            .arg("--listen")
            .arg(format!("unix:{}", dir.path().join(sock).display()))
            .arg("--eeprom")
            .arg(&eeprom)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let mut first = run("a.sock");
    let deadline = Instant::now() + Duration::from_secs(5);
    while !dir.path().join("a.sock").exists() {
        assert!(Instant::now() < deadline, "first emulator did not start");
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut second = run("b.sock");
    let deadline = Instant::now() + Duration::from_secs(5);
    while second.try_wait().unwrap().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = second.kill();
    let second = second.wait_with_output().unwrap();
    let _ = first.kill();
    let _ = first.wait();
    assert_eq!(second.status.code(), Some(1), "{second:?}");
    let err = String::from_utf8_lossy(&second.stderr);
    assert!(err.contains("in use by another process"), "{err}");
    assert!(err.contains("car.eeprom.lock"), "{err}");
    // Once the first is gone the file is free again.
    let mut third = run("c.sock");
    let deadline = Instant::now() + Duration::from_secs(5);
    while !dir.path().join("c.sock").exists() {
        assert!(
            third.try_wait().unwrap().is_none(),
            "third emulator exited: the lock outlived its process"
        );
        assert!(Instant::now() < deadline, "third emulator did not start");
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = third.kill();
    let _ = third.wait();
}
