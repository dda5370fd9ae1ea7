//! Real-time front end: the emulated LBC behind a listening Unix or TCP socket.
//!
//! One client at a time is the UBC side of the UART (QEMU connects with
//! `-chardev socket,id=lbc,path=PATH`). The LBC keeps running while no client is attached (a
//! UART with nothing on the other end: what it sends is lost), and a new client can attach
//! after the previous one left, as when QEMU restarts. A client that connects while another
//! is attached waits; it takes the line over as soon as the attached one leaves or has sent
//! nothing for [`IDLE_HANDOVER`], so an idle client never keeps another out. Every change of
//! client starts a clean line ([`Lbc::line_break`]): half a message from the one that left is
//! never completed by the next one's bytes. Time is the host's monotonic clock.

use std::fmt;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::lbc::{Lbc, LogEntry};

/// Longest the loop sleeps between polls.
pub const POLL_INTERVAL: Duration = Duration::from_millis(1);
/// Most input taken from the client in one poll, bytes (the rest is read on the next poll).
/// A 115200 baud UART delivers about 12 bytes per millisecond; this is far above that.
pub const MAX_INPUT_PER_POLL: usize = 64 * 1024;
/// Output held back for a slow client before it is discarded, bytes.
pub const MAX_PENDING_OUTPUT: usize = 64 * 1024;
/// A waiting client takes the line over from an attached one that has sent nothing for this
/// long. A UBC that only listens to the stream sends nothing either, so a second client does
/// displace it after this time: one LBC has one UBC, and the newcomer is taken to be its
/// replacement (a restarted QEMU whose old connection was never closed).
pub const IDLE_HANDOVER: Duration = Duration::from_secs(1);

/// Where to listen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ListenAddr {
    /// A Unix stream socket at this path.
    Unix(PathBuf),
    /// A TCP port on a loopback address.
    Tcp(SocketAddr),
}

/// Why a listen address was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ListenAddrError {
    /// Neither `unix:` nor `tcp:` prefix.
    UnknownScheme {
        /// The text as given.
        given: String,
    },
    /// `unix:` with an empty path.
    EmptyPath,
    /// `tcp:` with something that is not `IP:PORT`.
    BadSocketAddr {
        /// The text after `tcp:`.
        given: String,
    },
    /// `tcp:` with an address that is not loopback (the emulator serves this machine only).
    NotLoopback {
        /// The address.
        addr: SocketAddr,
    },
}

impl fmt::Display for ListenAddrError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownScheme { given } => {
                write!(f, "`{given}`: expected unix:PATH or tcp:127.0.0.1:PORT")
            }
            Self::EmptyPath => write!(f, "unix: needs a socket path"),
            Self::BadSocketAddr { given } => {
                write!(f, "`{given}` is not IP:PORT (e.g. tcp:127.0.0.1:5555)")
            }
            Self::NotLoopback { addr } => {
                write!(
                    f,
                    "{addr} is not a loopback address (use 127.0.0.1 or [::1])"
                )
            }
        }
    }
}

impl std::error::Error for ListenAddrError {}

impl FromStr for ListenAddr {
    type Err = ListenAddrError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if let Some(path) = s.strip_prefix("unix:") {
            if path.is_empty() {
                return Err(ListenAddrError::EmptyPath);
            }
            Ok(ListenAddr::Unix(PathBuf::from(path)))
        } else if let Some(a) = s.strip_prefix("tcp:") {
            let addr: SocketAddr = a.parse().map_err(|_| ListenAddrError::BadSocketAddr {
                given: a.to_owned(),
            })?;
            if !addr.ip().is_loopback() {
                return Err(ListenAddrError::NotLoopback { addr });
            }
            Ok(ListenAddr::Tcp(addr))
        } else {
            Err(ListenAddrError::UnknownScheme {
                given: s.to_owned(),
            })
        }
    }
}

impl fmt::Display for ListenAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ListenAddr::Unix(p) => write!(f, "unix:{}", p.display()),
            ListenAddr::Tcp(a) => write!(f, "tcp:{a}"),
        }
    }
}

enum Listener {
    Unix(UnixListener, PathBuf),
    Tcp(TcpListener),
}

enum Conn {
    Unix(UnixStream),
    Tcp(TcpStream),
}

impl Read for Conn {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self {
            Conn::Unix(s) => s.read(buf),
            Conn::Tcp(s) => s.read(buf),
        }
    }
}

impl Write for Conn {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self {
            Conn::Unix(s) => s.write(buf),
            Conn::Tcp(s) => s.write(buf),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match self {
            Conn::Unix(s) => s.flush(),
            Conn::Tcp(s) => s.flush(),
        }
    }
}

/// What the server reports besides the LBC's own log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerEvent {
    /// A client attached.
    Connected,
    /// The client left (or its connection failed).
    Disconnected,
}

/// A bound listening socket.
pub struct Server {
    listener: Listener,
    addr: ListenAddr,
}

impl fmt::Debug for Server {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Server").field("addr", &self.addr).finish()
    }
}

impl Server {
    /// Binds. A stale Unix socket file at the path is replaced; any other file there is an error.
    pub fn bind(addr: &ListenAddr) -> io::Result<Self> {
        let (listener, addr) = match addr {
            ListenAddr::Unix(path) => {
                remove_stale_socket(path)?;
                let l = UnixListener::bind(path)?;
                l.set_nonblocking(true)?;
                (Listener::Unix(l, path.clone()), addr.clone())
            }
            ListenAddr::Tcp(a) => {
                let l = TcpListener::bind(a)?;
                l.set_nonblocking(true)?;
                let bound = l.local_addr()?;
                (Listener::Tcp(l), ListenAddr::Tcp(bound))
            }
        };
        Ok(Self { listener, addr })
    }

    /// The address actually bound (a TCP port 0 is replaced by the chosen port).
    pub fn local_addr(&self) -> &ListenAddr {
        &self.addr
    }

    fn accept(&self) -> io::Result<Option<Conn>> {
        let r = match &self.listener {
            Listener::Unix(l, _) => l
                .accept()
                .map(|(s, _)| s.set_nonblocking(true).map(|_| Conn::Unix(s))),
            Listener::Tcp(l) => l.accept().map(|(s, _)| {
                let _ = s.set_nodelay(true);
                s.set_nonblocking(true).map(|_| Conn::Tcp(s))
            }),
        };
        match r {
            Ok(Ok(c)) => Ok(Some(c)),
            Ok(Err(e)) => Err(e),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Runs `lbc` in real time until `stop` is set. Emulator time continues from
    /// [`Lbc::now_us`]. `on_log` receives the LBC's log entries and `on_event` connection events
    /// (a handover from an idle client to a waiting one is a `Disconnected` then a `Connected`).
    pub fn run(
        &self,
        lbc: &mut Lbc,
        stop: &AtomicBool,
        on_log: &mut dyn FnMut(&LogEntry),
        on_event: &mut dyn FnMut(ServerEvent),
    ) -> io::Result<()> {
        let start = Instant::now();
        let base_us = lbc.now_us();
        let mut client: Option<Conn> = None;
        // When the attached client last sent something (or attached).
        let mut heard = Instant::now();
        // The newest client that connected while another was attached.
        let mut waiting: Option<Conn> = None;
        let mut pending: Vec<u8> = Vec::new();
        let mut inbuf = [0u8; 4096];
        let mut rx: Vec<u8> = Vec::new();
        while !stop.load(Ordering::Relaxed) {
            // Take every connection out of the backlog; the newest one waits.
            while let Some(c) = self.accept()? {
                waiting = Some(c);
            }
            if client.is_some() && waiting.is_some() && heard.elapsed() >= IDLE_HANDOVER {
                client = None;
                on_event(ServerEvent::Disconnected);
            }
            if client.is_none() {
                if let Some(c) = waiting.take() {
                    client = Some(c);
                    heard = Instant::now();
                    pending.clear();
                    lbc.line_break();
                    on_event(ServerEvent::Connected);
                }
            }
            let now = base_us + start.elapsed().as_micros() as u64;
            rx.clear();
            let mut lost = false;
            if let Some(c) = client.as_mut() {
                lost = read_available(c, &mut inbuf, &mut rx, MAX_INPUT_PER_POLL);
            }
            if !rx.is_empty() {
                heard = Instant::now();
            }
            lbc.push_rx(now, &rx);
            lbc.step_until(now);
            let mut out = Vec::new();
            lbc.drain_tx(now, &mut out);
            for entry in lbc.take_log() {
                on_log(&entry);
            }
            if let Some(c) = client.as_mut() {
                pending.extend_from_slice(&out);
                if pending.len() > MAX_PENDING_OUTPUT {
                    let excess = pending.len() - MAX_PENDING_OUTPUT;
                    pending.drain(..excess);
                }
                match write_some(c, &pending) {
                    Ok(n) => {
                        pending.drain(..n);
                    }
                    Err(_) => lost = true,
                }
            }
            if lost {
                client = None;
                pending.clear();
                lbc.line_break();
                on_event(ServerEvent::Disconnected);
            }
            std::thread::sleep(POLL_INTERVAL);
        }
        Ok(())
    }
}

/// Reads what `c` has ready into `rx`, at most about `limit` bytes, so that a client that
/// sends faster than the loop reads cannot keep it reading forever. Returns `true` when the
/// connection ended or failed.
fn read_available<R: Read>(c: &mut R, buf: &mut [u8], rx: &mut Vec<u8>, limit: usize) -> bool {
    while rx.len() < limit {
        match c.read(buf) {
            Ok(0) => return true,
            Ok(n) => rx.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => return false,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(_) => return true,
        }
    }
    false
}

fn write_some(c: &mut Conn, buf: &[u8]) -> io::Result<usize> {
    let mut done = 0;
    while done < buf.len() {
        match c.write(&buf[done..]) {
            Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
            Ok(n) => done += n,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(done)
}

fn remove_stale_socket(path: &Path) -> io::Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_socket() => std::fs::remove_file(path),
        Ok(_) => Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!("{} exists and is not a socket", path.display()),
        )),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e),
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if let Listener::Unix(_, path) = &self.listener {
            let _ = std::fs::remove_file(path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn listen_addresses_parse() {
        assert_eq!(
            "unix:/tmp/lbc.sock".parse::<ListenAddr>(),
            Ok(ListenAddr::Unix("/tmp/lbc.sock".into()))
        );
        assert_eq!(
            "tcp:127.0.0.1:5555".parse::<ListenAddr>(),
            Ok(ListenAddr::Tcp("127.0.0.1:5555".parse().unwrap()))
        );
        assert_eq!(
            "unix:".parse::<ListenAddr>(),
            Err(ListenAddrError::EmptyPath)
        );
        assert!(matches!(
            "tcp:0.0.0.0:5555".parse::<ListenAddr>(),
            Err(ListenAddrError::NotLoopback { .. })
        ));
        assert!(matches!(
            "tcp:localhost".parse::<ListenAddr>(),
            Err(ListenAddrError::BadSocketAddr { .. })
        ));
        assert!(matches!(
            "/tmp/x".parse::<ListenAddr>(),
            Err(ListenAddrError::UnknownScheme { .. })
        ));
        assert_eq!(
            ListenAddr::Unix("/a".into())
                .to_string()
                .parse::<ListenAddr>(),
            Ok(ListenAddr::Unix("/a".into()))
        );
    }

    proptest::proptest! {
        #[test]
        fn display_parses_back(path in "/[a-z0-9_./-]{1,40}", port in 0u16.., v6 in proptest::bool::ANY) {
            let unix = ListenAddr::Unix(path.into());
            proptest::prop_assert_eq!(unix.to_string().parse::<ListenAddr>(), Ok(unix));
            let ip: std::net::IpAddr = if v6 { "::1".parse().unwrap() } else { "127.0.0.1".parse().unwrap() };
            let tcp = ListenAddr::Tcp(SocketAddr::new(ip, port));
            proptest::prop_assert_eq!(tcp.to_string().parse::<ListenAddr>(), Ok(tcp));
        }
    }

    #[test]
    fn a_client_that_never_stops_sending_cannot_stall_the_loop() {
        // io::repeat never runs dry and never blocks, like a peer flooding the socket.
        let mut flood = io::repeat(0xE8);
        let mut buf = [0u8; 4096];
        let mut rx = Vec::new();
        assert!(!read_available(&mut flood, &mut buf, &mut rx, 10_000));
        assert!((10_000..10_000 + buf.len()).contains(&rx.len()));
    }

    #[test]
    fn end_of_stream_and_would_block_are_told_apart() {
        let mut buf = [0u8; 8];
        let mut rx = Vec::new();
        let mut closed: &[u8] = &[1, 2, 3];
        assert!(read_available(&mut closed, &mut buf, &mut rx, 1024));
        assert_eq!(rx, [1, 2, 3]);

        struct Idle;
        impl Read for Idle {
            fn read(&mut self, _: &mut [u8]) -> io::Result<usize> {
                Err(io::ErrorKind::WouldBlock.into())
            }
        }
        rx.clear();
        assert!(!read_available(&mut Idle, &mut buf, &mut rx, 1024));
        assert!(rx.is_empty());
    }

    #[test]
    fn a_regular_file_is_not_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f");
        std::fs::write(&p, "keep").unwrap();
        assert!(Server::bind(&ListenAddr::Unix(p.clone())).is_err());
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "keep");
    }
}
