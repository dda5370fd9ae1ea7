//! Real-time radio hub: the [`RadioMedium`] run against the wall clock between byte-stream
//! endpoints, so that QEMU cars (whose radio UART is a `pci-serial` with a Unix-socket
//! chardev), host-side cars and a ground station share one simulated channel.
//!
//! One engine thread owns the medium and every socket, all non-blocking. Each turn it
//! accepts or (re)connects, writes the bytes it read into the medium at the current time,
//! steps the medium to now, and writes what the medium delivered back to each endpoint.
//! Collisions, CSMA, loss and distance come from the medium and its seeded parameters.
//! Dropping the [`Hub`] stops the thread and removes the socket files it created.
//!
//! [`RealtimeCar`] runs a `radio_mac::CarMac` on a socket in real time: a stand-in car for
//! tests and demonstrations that broadcasts a fixed state and echoes every request.

mod realtime_car;

pub use realtime_car::{CarReport, RealtimeCar};

use crate::radio_medium::{MediumParams, MediumStats, Nanos, NodeId, RadioMedium};
use radio_mac::{CarConfig, CarMac, CarState, Event};
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::os::unix::fs::FileTypeExt;
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Bytes delivered by the medium that may wait for a slow endpoint before being discarded.
pub const OUT_BACKLOG: usize = 64 * 1024;
/// Largest read from one endpoint per turn.
const READ_CHUNK: usize = 1024;
/// Longest a `tcp:` connection attempt may hold up the engine (the other nodes wait meanwhile).
const TCP_CONNECT_TIMEOUT: Duration = Duration::from_millis(2);

/// Where a node's byte stream comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum EndpointSpec {
    /// `unix:PATH`: connect to a listening Unix socket (e.g. QEMU's chardev server);
    /// reconnects when it goes away.
    UnixConnect(PathBuf),
    /// `unix-listen:PATH`: listen on PATH and serve one client at a time.
    UnixListen(PathBuf),
    /// `tcp:IP:PORT`: connect to a TCP port.
    TcpConnect(SocketAddr),
    /// `tcp-listen:IP:PORT`: listen on a loopback TCP port (0 picks a free one, see
    /// [`Hub::local_addr`]) and serve one client at a time.
    TcpListen(SocketAddr),
}

/// Why an endpoint spec was rejected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SpecError {
    /// No `scheme:` prefix.
    MissingScheme,
    /// A scheme other than `unix`, `unix-listen`, `tcp`, `tcp-listen`.
    UnknownScheme {
        /// The scheme given.
        scheme: String,
    },
    /// Nothing after the scheme.
    EmptyAddress,
    /// Not an `IP:PORT` socket address.
    BadSocketAddr {
        /// The text given.
        value: String,
    },
    /// Listening is allowed on loopback addresses only.
    NotLoopback {
        /// The address given.
        addr: SocketAddr,
    },
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MissingScheme => write!(
                f,
                "missing scheme (expected unix:PATH, unix-listen:PATH, tcp:IP:PORT or tcp-listen:IP:PORT)"
            ),
            Self::UnknownScheme { scheme } => write!(
                f,
                "unknown scheme `{scheme}` (expected unix, unix-listen, tcp or tcp-listen)"
            ),
            Self::EmptyAddress => write!(f, "empty path or address"),
            Self::BadSocketAddr { value } => {
                write!(f, "`{value}` is not an IP:PORT socket address")
            }
            Self::NotLoopback { addr } => {
                write!(f, "{addr} is not a loopback address; the hub listens on loopback only")
            }
        }
    }
}

impl std::error::Error for SpecError {}

impl FromStr for EndpointSpec {
    type Err = SpecError;

    fn from_str(s: &str) -> Result<Self, SpecError> {
        let (scheme, rest) = s.split_once(':').ok_or(SpecError::MissingScheme)?;
        if rest.is_empty() {
            return Err(SpecError::EmptyAddress);
        }
        let sock = |v: &str| {
            v.parse::<SocketAddr>()
                .map_err(|_| SpecError::BadSocketAddr { value: v.into() })
        };
        match scheme {
            "unix" => Ok(Self::UnixConnect(rest.into())),
            "unix-listen" => Ok(Self::UnixListen(rest.into())),
            "tcp" => Ok(Self::TcpConnect(sock(rest)?)),
            "tcp-listen" => {
                let addr = sock(rest)?;
                if !addr.ip().is_loopback() {
                    return Err(SpecError::NotLoopback { addr });
                }
                Ok(Self::TcpListen(addr))
            }
            other => Err(SpecError::UnknownScheme {
                scheme: other.into(),
            }),
        }
    }
}

impl fmt::Display for EndpointSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnixConnect(p) => write!(f, "unix:{}", p.display()),
            Self::UnixListen(p) => write!(f, "unix-listen:{}", p.display()),
            Self::TcpConnect(a) => write!(f, "tcp:{a}"),
            Self::TcpListen(a) => write!(f, "tcp-listen:{a}"),
        }
    }
}

/// One node of the hub.
#[derive(Debug, Clone)]
pub struct NodeConfig {
    /// Name used in statistics and [`Hub::set_position`].
    pub name: String,
    /// Its byte stream.
    pub endpoint: EndpointSpec,
    /// Position in metres (loss by distance, see [`MediumParams::range_m`]).
    pub position: (f64, f64),
}

impl NodeConfig {
    /// A node at `position` metres.
    pub fn new(name: impl Into<String>, endpoint: EndpointSpec, position: (f64, f64)) -> Self {
        Self {
            name: name.into(),
            endpoint,
            position,
        }
    }
}

/// Hub configuration.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct HubConfig {
    /// Channel model (loss, collisions, timing).
    pub params: MediumParams,
    /// Seed of the medium's randomness.
    pub seed: u64,
    /// Sleep between two engine turns; bounds the added latency.
    pub tick: Duration,
    /// Delay between two connection attempts of a `unix:`/`tcp:` node.
    pub reconnect: Duration,
}

impl Default for HubConfig {
    fn default() -> Self {
        Self {
            params: MediumParams::default(),
            seed: 0,
            tick: Duration::from_micros(500),
            reconnect: Duration::from_millis(100),
        }
    }
}

/// Why the hub could not start or could not do what was asked.
#[derive(Debug)]
pub enum HubError {
    /// Two nodes with one name.
    DuplicateName {
        /// The name.
        name: String,
    },
    /// A listening path exists and is not a stale socket.
    PathInUse {
        /// The path.
        path: PathBuf,
    },
    /// Listening failed.
    Bind {
        /// The endpoint.
        endpoint: EndpointSpec,
        /// The cause.
        source: io::Error,
    },
    /// No node of that name.
    UnknownNode {
        /// The name.
        name: String,
    },
    /// The engine thread could not be started.
    Thread(io::Error),
}

impl fmt::Display for HubError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::DuplicateName { name } => write!(f, "two nodes are named `{name}`"),
            Self::PathInUse { path } => write!(
                f,
                "{} exists and is not a stale socket (another hub running?)",
                path.display()
            ),
            Self::Bind { endpoint, source } => write!(f, "cannot listen on {endpoint}: {source}"),
            Self::UnknownNode { name } => write!(f, "no node named `{name}`"),
            Self::Thread(e) => write!(f, "cannot start the hub thread: {e}"),
        }
    }
}

impl std::error::Error for HubError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Bind { source, .. } => Some(source),
            Self::Thread(e) => Some(e),
            _ => None,
        }
    }
}

/// Per-node counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Bytes read from the endpoint and accepted by the node's radio module.
    pub bytes_in: u64,
    /// Bytes the medium delivered and the endpoint was sent.
    pub bytes_out: u64,
    /// Bytes read from the endpoint that overflowed the module's transmit buffer.
    pub bytes_refused: u64,
    /// Delivered bytes discarded: no client connected, or [`OUT_BACKLOG`] exceeded.
    pub bytes_discarded: u64,
    /// `0x00` delimiters read (radio-mac frames sent, when the node speaks radio-mac).
    pub frames_in: u64,
    /// `0x00` delimiters sent (radio-mac frames received).
    pub frames_out: u64,
    /// Connections made or accepted.
    pub connects: u64,
    /// Connections lost.
    pub disconnects: u64,
    /// A client is connected now.
    pub connected: bool,
}

/// Statistics of a running hub.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HubStats {
    /// Per node, in configuration order.
    pub nodes: Vec<(String, NodeStats)>,
    /// Channel-wide counters: packets, deliveries, collisions, losses, CSMA drops.
    pub medium: MediumStats,
    /// Time since the hub started.
    pub elapsed: Duration,
}

impl HubStats {
    /// Counters of one node.
    pub fn node(&self, name: &str) -> Option<&NodeStats> {
        self.nodes.iter().find(|(n, _)| n == name).map(|(_, s)| s)
    }
}

#[derive(Debug)]
enum Stream {
    Unix(UnixStream),
    Tcp(TcpStream),
}

impl Stream {
    fn set_nonblocking(&self) -> io::Result<()> {
        match self {
            Self::Unix(s) => s.set_nonblocking(true),
            Self::Tcp(s) => {
                s.set_nodelay(true)?;
                s.set_nonblocking(true)
            }
        }
    }

    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self {
            Self::Unix(s) => s.read(buf),
            Self::Tcp(s) => s.read(buf),
        }
    }

    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self {
            Self::Unix(s) => s.write(buf),
            Self::Tcp(s) => s.write(buf),
        }
    }
}

#[derive(Debug)]
enum Listener {
    Unix(UnixListener),
    Tcp(TcpListener),
}

#[derive(Debug)]
struct Port {
    name: String,
    endpoint: EndpointSpec,
    listener: Option<Listener>,
    conn: Option<Stream>,
    out: VecDeque<u8>,
    next_connect: Instant,
    node: NodeId,
    stats: NodeStats,
}

impl Port {
    fn attach(&mut self, stream: Stream) {
        if stream.set_nonblocking().is_ok() {
            self.conn = Some(stream);
            self.out.clear();
            self.stats.connects += 1;
            self.stats.connected = true;
        }
    }

    fn detach(&mut self) {
        if self.conn.take().is_some() {
            self.stats.disconnects += 1;
        }
        self.stats.connected = false;
        self.stats.bytes_discarded += self.out.len() as u64;
        self.out.clear();
    }

    /// Accept a waiting client or (re)connect, when no client is attached.
    fn service(&mut self, now: Instant, reconnect: Duration) {
        if self.conn.is_some() {
            return;
        }
        let stream = match (&self.listener, &self.endpoint) {
            (Some(Listener::Unix(l)), _) => l.accept().ok().map(|(s, _)| Stream::Unix(s)),
            (Some(Listener::Tcp(l)), _) => l.accept().ok().map(|(s, _)| Stream::Tcp(s)),
            (None, _) if now < self.next_connect => None,
            (None, EndpointSpec::UnixConnect(p)) => {
                self.next_connect = now + reconnect;
                UnixStream::connect(p).ok().map(Stream::Unix)
            }
            (None, EndpointSpec::TcpConnect(a)) => {
                self.next_connect = now + reconnect;
                TcpStream::connect_timeout(a, TCP_CONNECT_TIMEOUT)
                    .ok()
                    .map(Stream::Tcp)
            }
            (None, _) => None,
        };
        if let Some(s) = stream {
            self.attach(s);
        }
    }

    /// Bytes from the endpoint into the medium.
    fn pump_in(&mut self, medium: &mut RadioMedium, now: Nanos) {
        let mut buf = [0u8; READ_CHUNK];
        for _ in 0..4 {
            let Some(conn) = self.conn.as_mut() else {
                return;
            };
            match conn.read(&mut buf) {
                Ok(0) => return self.detach(),
                Ok(n) => {
                    let bytes = &buf[..n];
                    let taken = medium.write(self.node, now, bytes);
                    self.stats.bytes_in += taken as u64;
                    self.stats.bytes_refused += (n - taken) as u64;
                    self.stats.frames_in += bytes.iter().filter(|b| **b == 0).count() as u64;
                    if n < buf.len() {
                        return;
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock => return,
                Err(_) => return self.detach(),
            }
        }
    }

    /// Bytes from the medium out to the endpoint.
    fn pump_out(&mut self, medium: &mut RadioMedium, now: Nanos) {
        let delivered = medium.read(self.node, now);
        if self.conn.is_none() {
            self.stats.bytes_discarded += delivered.len() as u64;
            return;
        }
        let room = OUT_BACKLOG.saturating_sub(self.out.len());
        let take = delivered.len().min(room);
        self.stats.bytes_discarded += (delivered.len() - take) as u64;
        self.out.extend(&delivered[..take]);
        while !self.out.is_empty() {
            let Some(conn) = self.conn.as_mut() else {
                return;
            };
            let (front, _) = self.out.as_slices();
            match conn.write(front) {
                Ok(0) => return self.detach(),
                Ok(n) => {
                    let sent: Vec<u8> = self.out.drain(..n).collect();
                    self.stats.bytes_out += n as u64;
                    self.stats.frames_out += sent.iter().filter(|b| **b == 0).count() as u64;
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock => return,
                Err(_) => return self.detach(),
            }
        }
    }
}

#[derive(Debug)]
struct Engine {
    medium: RadioMedium,
    ports: Vec<Port>,
}

/// A running hub. Dropping it stops the engine thread and removes its socket files.
#[derive(Debug)]
pub struct Hub {
    engine: Arc<Mutex<Engine>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    started: Instant,
    socket_files: Vec<PathBuf>,
    local_addrs: Vec<(String, SocketAddr)>,
}

fn lock(engine: &Mutex<Engine>) -> MutexGuard<'_, Engine> {
    // A panic inside the engine leaves consistent-enough counters; keep serving statistics.
    engine.lock().unwrap_or_else(|e| e.into_inner())
}

/// Bind a Unix listener at `path`, replacing a stale socket file left by a dead process.
fn bind_unix(path: &Path, endpoint: &EndpointSpec) -> Result<UnixListener, HubError> {
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        let stale = meta.file_type().is_socket() && UnixStream::connect(path).is_err();
        if !stale {
            return Err(HubError::PathInUse { path: path.into() });
        }
        let _ = std::fs::remove_file(path);
    }
    let l = UnixListener::bind(path).map_err(|source| HubError::Bind {
        endpoint: endpoint.clone(),
        source,
    })?;
    l.set_nonblocking(true).map_err(|source| HubError::Bind {
        endpoint: endpoint.clone(),
        source,
    })?;
    Ok(l)
}

impl Hub {
    /// Bind every listening endpoint and start the engine thread.
    pub fn start(config: HubConfig, nodes: Vec<NodeConfig>) -> Result<Hub, HubError> {
        let mut medium = RadioMedium::new(config.params.clone(), config.seed);
        let mut ports: Vec<Port> = Vec::with_capacity(nodes.len());
        let mut socket_files = Vec::new();
        let mut local_addrs = Vec::new();
        let started = Instant::now();
        // Build every port first; on error, the files bound so far are removed below.
        let result = (|| {
            for n in nodes {
                if ports.iter().any(|p| p.name == n.name) {
                    return Err(HubError::DuplicateName { name: n.name });
                }
                let listener = match &n.endpoint {
                    EndpointSpec::UnixListen(path) => {
                        let l = bind_unix(path, &n.endpoint)?;
                        socket_files.push(path.clone());
                        Some(Listener::Unix(l))
                    }
                    EndpointSpec::TcpListen(addr) => {
                        let bind_err = |source| HubError::Bind {
                            endpoint: n.endpoint.clone(),
                            source,
                        };
                        let l = TcpListener::bind(addr).map_err(bind_err)?;
                        l.set_nonblocking(true).map_err(bind_err)?;
                        local_addrs.push((n.name.clone(), l.local_addr().map_err(bind_err)?));
                        Some(Listener::Tcp(l))
                    }
                    _ => None,
                };
                ports.push(Port {
                    name: n.name,
                    endpoint: n.endpoint,
                    listener,
                    conn: None,
                    out: VecDeque::new(),
                    next_connect: started,
                    node: medium.add_node(n.position),
                    stats: NodeStats::default(),
                });
            }
            Ok(())
        })();
        if let Err(e) = result {
            drop(ports);
            for f in &socket_files {
                let _ = std::fs::remove_file(f);
            }
            return Err(e);
        }
        let engine = Arc::new(Mutex::new(Engine { medium, ports }));
        let stop = Arc::new(AtomicBool::new(false));
        let mut hub = Hub {
            engine: engine.clone(),
            stop: stop.clone(),
            thread: None,
            started,
            socket_files,
            local_addrs,
        };
        let (tick, reconnect) = (config.tick, config.reconnect);
        let thread = thread::Builder::new()
            .name("radio-hub".into())
            .spawn(move || run_engine(&engine, &stop, started, tick, reconnect))
            .map_err(HubError::Thread)?;
        hub.thread = Some(thread);
        Ok(hub)
    }

    /// Actual address of a `tcp-listen:` node (useful with port 0).
    pub fn local_addr(&self, name: &str) -> Option<SocketAddr> {
        self.local_addrs
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, a)| *a)
    }

    /// Move a node (metres).
    pub fn set_position(&self, name: &str, position: (f64, f64)) -> Result<(), HubError> {
        let mut e = lock(&self.engine);
        let Engine { medium, ports } = &mut *e;
        let port = ports
            .iter()
            .find(|p| p.name == name)
            .ok_or_else(|| HubError::UnknownNode { name: name.into() })?;
        medium.set_position(port.node, position);
        Ok(())
    }

    /// Current statistics.
    pub fn stats(&self) -> HubStats {
        let e = lock(&self.engine);
        HubStats {
            nodes: e.ports.iter().map(|p| (p.name.clone(), p.stats)).collect(),
            medium: *e.medium.stats(),
            elapsed: self.started.elapsed(),
        }
    }

    /// Channel model in use.
    pub fn params(&self) -> MediumParams {
        lock(&self.engine).medium.params().clone()
    }

    /// Stop the hub and return its final statistics.
    pub fn shutdown(mut self) -> HubStats {
        self.stop_thread();
        self.stats()
    }

    fn stop_thread(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        // Close every socket before removing the files.
        for p in lock(&self.engine).ports.iter_mut() {
            p.detach();
            p.listener = None;
        }
        for f in self.socket_files.drain(..) {
            let _ = std::fs::remove_file(f);
        }
    }
}

impl Drop for Hub {
    fn drop(&mut self) {
        self.stop_thread();
    }
}

fn run_engine(
    engine: &Mutex<Engine>,
    stop: &AtomicBool,
    started: Instant,
    tick: Duration,
    reconnect: Duration,
) {
    while !stop.load(Ordering::Relaxed) {
        {
            let mut e = lock(engine);
            let Engine { medium, ports } = &mut *e;
            let wall = Instant::now();
            let now = wall.duration_since(started).as_nanos() as Nanos;
            for p in ports.iter_mut() {
                p.service(wall, reconnect);
                p.pump_in(medium, now);
            }
            medium.step(now);
            for p in ports.iter_mut() {
                p.pump_out(medium, now);
            }
        }
        thread::sleep(tick);
    }
}
