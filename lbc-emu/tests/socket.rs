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
