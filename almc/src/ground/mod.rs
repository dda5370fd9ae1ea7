//! The ground station: a `radio_mac::GroundStation` driven by the wall clock on a
//! background thread, over a socket (the simulated hub, QEMU) or a serial radio module.
//!
//! [`GroundLink`] is the session other commands build on: the cars heard with their latest
//! state, authenticated requests to one car (waiting for its reply), to every car heard, or
//! broadcast, and a stream of protocol events. Every run signs under a fresh random session
//! epoch (cars join it with a Hello, `docs/radio-protocol.md` section 6); command counters are
//! also persisted with [`CounterFile`], so they keep growing across runs.

pub mod counter;
pub mod key;
pub mod transport;

pub use counter::{CounterError, CounterFile};
pub use key::{resolve_key, KeyError, KeySource};
pub use transport::{OpenError, SpecError, TransportSpec};

use radio_mac::{
    Address, CarId, CarState, Event, GroundConfig, GroundStation, Heartbeat, Key, RequestHandle,
    SendError, MAX_PAYLOAD,
};
use std::fmt;
use std::io::{self, ErrorKind};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Capacity of one event subscription; events beyond it are counted and dropped.
pub const EVENT_BACKLOG: usize = 1024;

/// A car as last heard by the ground station.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CarInfo {
    /// Its ID.
    pub id: CarId,
    /// Latest state broadcast, if any.
    pub state: Option<CarState>,
    /// Age of that state.
    pub state_age: Option<Duration>,
    /// Latest heartbeat, if any.
    pub heartbeat: Option<Heartbeat>,
    /// Time since any valid frame from it.
    pub last_heard: Duration,
    /// Silent for longer than the staleness limit (1 s).
    pub stale: bool,
    /// State broadcasts received.
    pub states_heard: u32,
    /// Gaps in its state sequence.
    pub states_missed: u32,
}

/// A car's answer to a request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reply {
    /// Who answered.
    pub car: CarId,
    /// Reply tag.
    pub tag: u8,
    /// Reply bytes.
    pub payload: Vec<u8>,
    /// Counter of the command answered.
    pub counter: u32,
    /// Time from sending to the reply.
    pub round_trip: Duration,
}

/// A broadcast command was sent (broadcasts are not acknowledged).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BroadcastSent {
    /// Its counter.
    pub counter: u32,
    /// Time until every repeat had been handed to the radio.
    pub took: Duration,
}

/// One protocol event with its time since the link opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GroundEvent {
    /// Time since [`GroundLink::open`].
    pub at: Duration,
    /// The event.
    pub event: Event,
}

/// Byte-level counters of the link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Bytes received from the radio.
    pub bytes_in: u64,
    /// Bytes sent to the radio.
    pub bytes_out: u64,
    /// Events dropped because a subscriber did not keep up.
    pub events_dropped: u64,
    /// Requests from cars (notices) acknowledged with an empty reply.
    pub requests_acknowledged: u64,
}

/// Why the link stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkClosed {
    /// The other end closed or reset the connection.
    EndOfStream,
    /// Reading or writing failed.
    Io(ErrorKind),
}

impl LinkClosed {
    /// A reset or broken pipe means the other end went away (a Unix socket closed with
    /// unread data resets its peer).
    fn from_error(e: &io::Error) -> Self {
        match e.kind() {
            ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted | ErrorKind::BrokenPipe => {
                Self::EndOfStream
            }
            k => Self::Io(k),
        }
    }
}

impl fmt::Display for LinkClosed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::EndOfStream => write!(f, "the radio connection was closed"),
            Self::Io(k) => write!(f, "radio I/O error: {k}"),
        }
    }
}

/// Why a ground-station operation failed.
#[derive(Debug)]
pub enum GroundError {
    /// The radio spec is malformed.
    Spec(SpecError),
    /// The radio could not be opened.
    Open(OpenError),
    /// The counter file could not be used (nothing was sent).
    Counter(CounterError),
    /// The link is down.
    Closed(LinkClosed),
    /// Payload longer than [`MAX_PAYLOAD`].
    PayloadTooLong {
        /// Length given.
        len: usize,
    },
    /// The car did not answer any of the protocol's attempts: off, out of range, or it
    /// rejected the command (a different key, or a replayed counter).
    NoReply {
        /// The car.
        car: CarId,
        /// Transmissions made.
        attempts: u8,
    },
    /// The timeout elapsed before the reply (or before an earlier command finished).
    Timeout {
        /// Destination.
        dst: Address,
        /// Time waited.
        waited: Duration,
    },
    /// The protocol refused the command.
    Send(SendError),
    /// The background thread could not be started.
    Thread(io::Error),
}

impl fmt::Display for GroundError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Spec(e) => write!(f, "bad --radio spec: {e}"),
            Self::Open(e) => write!(f, "{e}"),
            Self::Counter(e) => write!(f, "{e}"),
            Self::Closed(c) => write!(f, "{c}"),
            Self::PayloadTooLong { len } => {
                write!(
                    f,
                    "payload of {len} bytes exceeds the {MAX_PAYLOAD}-byte maximum"
                )
            }
            Self::NoReply { car, attempts } => write!(
                f,
                "no reply from car {} after {attempts} attempts (car off or out of range, \
                 or it rejected the command: different key or old counter)",
                car.get()
            ),
            Self::Timeout { dst, waited } => write!(
                f,
                "no reply from {} within {} ms",
                describe(*dst),
                waited.as_millis()
            ),
            Self::Send(e) => write!(f, "the radio protocol refused the command: {e:?}"),
            Self::Thread(e) => write!(f, "cannot start the radio thread: {e}"),
        }
    }
}

impl std::error::Error for GroundError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Spec(e) => Some(e),
            Self::Open(e) => Some(e),
            Self::Counter(e) => Some(e),
            Self::Thread(e) => Some(e),
            _ => None,
        }
    }
}

fn describe(a: Address) -> String {
    match a {
        Address::Car(id) => format!("car {}", id.get()),
        Address::Broadcast => "broadcast".into(),
        Address::Ground => "ground station".into(),
    }
}

enum Outcome {
    Reply {
        from: Address,
        tag: u8,
        payload: Vec<u8>,
    },
    Failed,
    RepeatsDone,
    Closed(LinkClosed),
}

struct Inner {
    gs: GroundStation,
    waiters: Vec<(RequestHandle, Sender<Outcome>)>,
    subscribers: Vec<SyncSender<GroundEvent>>,
    link: LinkStats,
    closed: Option<LinkClosed>,
    /// Next counter last written to the counter file.
    persisted: Option<u32>,
}

impl Inner {
    fn close(&mut self, why: LinkClosed) {
        self.closed.get_or_insert(why);
        for (_, w) in self.waiters.drain(..) {
            let _ = w.send(Outcome::Closed(why));
        }
    }

    fn dispatch(&mut self, at: Duration) {
        while let Some(event) = self.gs.next_event() {
            if let Event::Request(inc) = &event {
                // Cars report to the ground station with requests (notices); an empty reply
                // with the same tag acknowledges them so that the car stops retrying.
                if !inc.id.broadcast && self.gs.reply(inc.id, inc.tag, &[]).is_ok() {
                    self.link.requests_acknowledged += 1;
                }
            }
            let (handle, outcome) = match &event {
                Event::Reply {
                    handle,
                    from,
                    tag,
                    payload,
                } => (
                    Some(*handle),
                    Outcome::Reply {
                        from: *from,
                        tag: *tag,
                        payload: payload.to_vec(),
                    },
                ),
                Event::Failed { handle, .. } => (Some(*handle), Outcome::Failed),
                Event::RepeatsDone { handle } => (Some(*handle), Outcome::RepeatsDone),
                _ => (None, Outcome::Failed),
            };
            if let Some(h) = handle {
                if let Some(i) = self.waiters.iter().position(|(w, _)| *w == h) {
                    let (_, tx) = self.waiters.swap_remove(i);
                    let _ = tx.send(outcome);
                }
            }
            let mut dropped = 0;
            self.subscribers.retain(|s| {
                match s.try_send(GroundEvent {
                    at,
                    event: event.clone(),
                }) {
                    Ok(()) => true,
                    Err(TrySendError::Full(_)) => {
                        dropped += 1;
                        true
                    }
                    Err(TrySendError::Disconnected(_)) => false,
                }
            });
            self.link.events_dropped += dropped;
        }
    }
}

struct Shared {
    inner: Mutex<Inner>,
    stop: AtomicBool,
    started: Instant,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn now_us(&self) -> u64 {
        self.started.elapsed().as_micros() as u64
    }
}

/// Longest wait honoured; a longer timeout (e.g. `Duration::MAX` from a command line) would
/// overflow `Instant`.
const MAX_WAIT: Duration = Duration::from_secs(365 * 24 * 3600);

fn deadline_after(start: Instant, timeout: Duration) -> Instant {
    start + timeout.min(MAX_WAIT)
}

/// An open ground-station session. Dropping it stops the radio thread.
pub struct GroundLink {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    counter_file: Option<CounterFile>,
    spec: TransportSpec,
    max_attempts: u8,
}

impl fmt::Debug for GroundLink {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GroundLink")
            .field("spec", &self.spec)
            .field("counter_file", &self.counter_file)
            .finish_non_exhaustive()
    }
}

/// Retry ceiling of the user's requests (radio-mac's default is 320 ms).
const USER_RETRY_MAX_US: u32 = 1_000_000;
/// Transmissions of a user's request before it fails (40 ms doubling to 1 s: about 6.2 s).
const USER_MAX_ATTEMPTS: u8 = 10;

impl GroundLink {
    /// Open the radio at `spec` (`unix:PATH`, `tcp:IP:PORT`, `serial:DEV[@BAUD]`) and start
    /// the ground station with `key` in a new random session epoch; the first command uses
    /// `first_counter`.
    pub fn open(spec: &str, key: Key, first_counter: u32) -> Result<Self, GroundError> {
        let spec: TransportSpec = spec.parse().map_err(GroundError::Spec)?;
        let mut config = GroundConfig::new(key, first_counter);
        config.epoch = random_epoch();
        // A car answers a console request once its LBC has answered, which for EEPROM and
        // calibration commands (and their retries on the LBC link) can take several seconds:
        // keep retrying for about 6 s instead of radio-mac's default 1.9 s.
        config.retry.max_us = USER_RETRY_MAX_US;
        config.retry.max_attempts = USER_MAX_ATTEMPTS;
        Self::open_spec(spec, config)
    }

    /// Open with a full ground-station configuration.
    pub fn open_spec(spec: TransportSpec, config: GroundConfig) -> Result<Self, GroundError> {
        let mut port = transport::open(&spec).map_err(GroundError::Open)?;
        let max_attempts = config.retry.max_attempts;
        let shared = Arc::new(Shared {
            inner: Mutex::new(Inner {
                gs: GroundStation::new(config),
                waiters: Vec::new(),
                subscribers: Vec::new(),
                link: LinkStats::default(),
                closed: None,
                persisted: None,
            }),
            stop: AtomicBool::new(false),
            started: Instant::now(),
        });
        let s = shared.clone();
        let thread = thread::Builder::new()
            .name("ground-radio".into())
            .spawn(move || run_radio(&s, &mut *port))
            .map_err(GroundError::Thread)?;
        Ok(Self {
            shared,
            thread: Some(thread),
            counter_file: None,
            spec,
            max_attempts,
        })
    }

    /// Persist the next counter to `file` before every command from now on.
    pub fn with_counter_file(mut self, file: CounterFile) -> Self {
        self.counter_file = Some(file);
        self
    }

    /// The transport in use.
    pub fn spec(&self) -> &TransportSpec {
        &self.spec
    }

    /// Counter the next command will use.
    pub fn next_counter(&self) -> u32 {
        self.shared.lock().gs.next_counter()
    }

    /// Why the link stopped, if it did.
    pub fn closed(&self) -> Option<LinkClosed> {
        self.shared.lock().closed
    }

    /// Cars heard so far, by ID.
    pub fn cars(&self) -> Vec<CarInfo> {
        let inner = self.shared.lock();
        let now = self.shared.now_us();
        let stale_after = inner.gs.stale_after_us();
        let age = |t: u64| Duration::from_micros(now.saturating_sub(t));
        let mut cars: Vec<CarInfo> = inner
            .gs
            .cars()
            .filter_map(|n| {
                let Address::Car(id) = n.addr else {
                    return None;
                };
                Some(CarInfo {
                    id,
                    state: n.state.map(|(s, _)| s),
                    state_age: n.state.map(|(_, t)| age(t)),
                    heartbeat: n.heartbeat,
                    last_heard: age(n.last_heard),
                    stale: n.is_stale(now, stale_after),
                    states_heard: n.states_heard,
                    states_missed: n.states_missed,
                })
            })
            .collect();
        cars.sort_by_key(|c| c.id);
        cars
    }

    /// Protocol and link counters.
    pub fn stats(&self) -> (radio_mac::Stats, LinkStats) {
        let inner = self.shared.lock();
        (*inner.gs.stats(), inner.link)
    }

    /// A stream of every protocol event from now on (states, heartbeats, replies, requests
    /// from cars, failures). Requests from cars have already been acknowledged with an empty
    /// reply of the same tag when they arrive here. A subscriber that falls [`EVENT_BACKLOG`]
    /// events behind loses the newest ones (counted in [`LinkStats::events_dropped`]).
    pub fn subscribe(&self) -> Receiver<GroundEvent> {
        let (tx, rx) = mpsc::sync_channel(EVENT_BACKLOG);
        self.shared.lock().subscribers.push(tx);
        rx
    }

    /// Queue a command once no other command is outstanding; returns its handle, counter,
    /// and the receiver of its outcome.
    fn submit(
        &self,
        dst: Address,
        tag: u8,
        payload: &[u8],
        deadline: Instant,
        started: Instant,
    ) -> Result<(u32, Receiver<Outcome>, RequestHandle), GroundError> {
        if payload.len() > MAX_PAYLOAD {
            return Err(GroundError::PayloadTooLong { len: payload.len() });
        }
        loop {
            {
                let mut inner = self.shared.lock();
                if let Some(c) = inner.closed {
                    return Err(GroundError::Closed(c));
                }
                let counter = inner.gs.next_counter();
                // After u32::MAX the station starts its next epoch at counter 1.
                let next = counter.checked_add(1).unwrap_or(1);
                if let Some(file) = &self.counter_file {
                    // Persist before the command can reach the radio: a crash never leads
                    // to a counter being sent twice.
                    if inner.persisted != Some(next) {
                        file.store(next).map_err(GroundError::Counter)?;
                        inner.persisted = Some(next);
                    }
                }
                let now = self.shared.now_us();
                match inner.gs.command(now, dst, tag, payload) {
                    Ok(h) => {
                        let (tx, rx) = mpsc::channel();
                        inner.waiters.push((h, tx));
                        return Ok((counter, rx, h));
                    }
                    Err(SendError::Busy) | Err(SendError::TxQueueFull) => {}
                    Err(e) => return Err(GroundError::Send(e)),
                }
            }
            if Instant::now() >= deadline {
                return Err(GroundError::Timeout {
                    dst,
                    waited: started.elapsed(),
                });
            }
            thread::sleep(Duration::from_millis(5));
        }
    }

    fn forget(&self, h: RequestHandle) {
        self.shared.lock().waiters.retain(|(w, _)| *w != h);
    }

    /// Send an authenticated command to `car` and wait up to `timeout` for its reply. The
    /// command is retransmitted for about 6.2 s (10 attempts, 40 ms doubling to 1 s) before
    /// the link gives up ([`GroundError::NoReply`]).
    pub fn request(
        &self,
        car: CarId,
        tag: u8,
        payload: &[u8],
        timeout: Duration,
    ) -> Result<Reply, GroundError> {
        let started = Instant::now();
        let deadline = deadline_after(started, timeout);
        let dst = Address::Car(car);
        let (counter, rx, h) = self.submit(dst, tag, payload, deadline, started)?;
        let wait = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(wait) {
            Ok(Outcome::Reply { from, tag, payload }) => Ok(Reply {
                car: match from {
                    Address::Car(id) => id,
                    _ => car,
                },
                tag,
                payload,
                counter,
                round_trip: started.elapsed(),
            }),
            Ok(Outcome::Failed) => Err(GroundError::NoReply {
                car,
                attempts: self.max_attempts,
            }),
            Ok(Outcome::RepeatsDone) => Err(GroundError::Send(SendError::InvalidDestination)),
            Ok(Outcome::Closed(c)) => Err(GroundError::Closed(c)),
            Err(RecvTimeoutError::Timeout) | Err(RecvTimeoutError::Disconnected) => {
                self.forget(h);
                Err(GroundError::Timeout {
                    dst,
                    waited: started.elapsed(),
                })
            }
        }
    }

    /// Send an authenticated command to every car (radio broadcast, repeated three times,
    /// not acknowledged: cars cannot answer a broadcast). Returns once every repeat went to
    /// the radio.
    pub fn broadcast(
        &self,
        tag: u8,
        payload: &[u8],
        timeout: Duration,
    ) -> Result<BroadcastSent, GroundError> {
        let started = Instant::now();
        let deadline = deadline_after(started, timeout);
        let dst = Address::Broadcast;
        let (counter, rx, h) = self.submit(dst, tag, payload, deadline, started)?;
        let wait = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(wait) {
            Ok(Outcome::Closed(c)) => Err(GroundError::Closed(c)),
            Ok(_) => Ok(BroadcastSent {
                counter,
                took: started.elapsed(),
            }),
            Err(_) => {
                self.forget(h);
                Err(GroundError::Timeout {
                    dst,
                    waited: started.elapsed(),
                })
            }
        }
    }

    /// Send the command to each car heard (not stale), one after the other, collecting each
    /// reply or error; `timeout` applies per car.
    pub fn request_each(
        &self,
        tag: u8,
        payload: &[u8],
        timeout: Duration,
    ) -> Vec<(CarId, Result<Reply, GroundError>)> {
        let ids: Vec<CarId> = self
            .cars()
            .into_iter()
            .filter(|c| !c.stale)
            .map(|c| c.id)
            .collect();
        ids.into_iter()
            .map(|id| (id, self.request(id, tag, payload, timeout)))
            .collect()
    }

    /// Stop the radio thread.
    pub fn close(mut self) -> (radio_mac::Stats, LinkStats) {
        self.stop();
        self.stats()
    }

    fn stop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for GroundLink {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A session epoch no earlier run is likely to have used: 32 bits from the standard library's
/// randomly keyed hasher (seeded by the operating system), the time and the process ID.
pub fn random_epoch() -> u32 {
    use std::hash::{BuildHasher, Hasher};
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos()),
    );
    h.write_u32(std::process::id());
    h.finish() as u32
}

/// The radio thread: read with a short timeout, feed the protocol, run its timers, write.
fn run_radio(shared: &Shared, port: &mut dyn transport::Port) {
    let mut buf = [0u8; 512];
    let mut out = [0u8; 512];
    while !shared.stop.load(Ordering::Relaxed) {
        let got = match port.read(&mut buf) {
            Ok(0) => {
                shared.lock().close(LinkClosed::EndOfStream);
                return;
            }
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                ) =>
            {
                0
            }
            Err(e) => {
                shared.lock().close(LinkClosed::from_error(&e));
                return;
            }
        };
        let n = {
            let mut inner = shared.lock();
            let now = shared.now_us();
            if got > 0 {
                inner.gs.push_rx(now, &buf[..got]);
                inner.link.bytes_in += got as u64;
            }
            inner.gs.poll(now);
            inner.dispatch(shared.started.elapsed());
            let n = inner.gs.transmit(&mut out);
            inner.link.bytes_out += n as u64;
            n
        };
        if n > 0 {
            if let Err(e) = port.write_all(&out[..n]).and_then(|()| port.flush()) {
                shared.lock().close(LinkClosed::from_error(&e));
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arena::hub::{CarReport, EndpointSpec, Hub, HubConfig, NodeConfig, RealtimeCar};
    use radio_mac::{CarConfig, Mode, Role};
    use std::path::PathBuf;

    const KEY: [u8; 16] = key::DEFAULT_KEY;

    struct World {
        hub: Hub,
        cars: Vec<RealtimeCar>,
        ground: PathBuf,
    }

    impl World {
        fn stop(self) -> (Vec<CarReport>, arena::hub::HubStats) {
            let reports = self.cars.into_iter().map(RealtimeCar::stop).collect();
            (reports, self.hub.shutdown())
        }
    }

    fn world(tag: &str, car_key: [u8; 16]) -> World {
        let path = |n: &str| {
            std::env::temp_dir().join(format!("almc-gl-{}-{tag}-{n}.sock", std::process::id()))
        };
        let ground = path("ground");
        let mut nodes = vec![NodeConfig::new(
            "ground",
            EndpointSpec::UnixListen(ground.clone()),
            (0.0, 2.0),
        )];
        for id in 1..=2u8 {
            let p = path(&format!("car{id}"));
            nodes.push(NodeConfig::new(
                format!("car{id}"),
                EndpointSpec::UnixListen(p),
                (f64::from(id), 0.0),
            ));
        }
        let hub = Hub::start(HubConfig::default(), nodes).unwrap();
        let cars = (1..=2u8)
            .map(|id| {
                let mut cfg = CarConfig::new(CarId::new(id).unwrap());
                cfg.key = Some(Key::new(car_key));
                cfg.seed = u32::from(id);
                let state = CarState {
                    x: 100 * u16::from(id),
                    y: 480,
                    heading_mrad: 1571,
                    velocity_mm_s: -200,
                    mode: Mode {
                        role: Role::Follower,
                        phase: id,
                    },
                };
                RealtimeCar::spawn(
                    EndpointSpec::UnixConnect(path(&format!("car{id}"))),
                    cfg,
                    state,
                    Duration::from_secs(2),
                )
                .unwrap()
            })
            .collect();
        World { hub, cars, ground }
    }

    fn open(w: &World, key: [u8; 16], first: u32) -> GroundLink {
        let spec = format!("unix:{}", w.ground.display());
        GroundLink::open(&spec, Key::new(key), first).unwrap()
    }

    fn wait_for_cars(link: &GroundLink, n: usize) {
        let t = Instant::now();
        while link.cars().iter().filter(|c| c.state.is_some()).count() < n
            && t.elapsed() < Duration::from_secs(3)
        {
            thread::sleep(Duration::from_millis(20));
        }
    }

    #[test]
    fn cars_replies_events_and_counter_file() {
        let w = world("ok", KEY);
        let file = CounterFile::new(
            std::env::temp_dir().join(format!("almc-gl-{}-counter", std::process::id())),
        );
        let link = open(&w, KEY, 500).with_counter_file(file.clone());
        let events = link.subscribe();
        wait_for_cars(&link, 2);
        let cars = link.cars();
        assert_eq!(cars.len(), 2, "{cars:?}");
        assert_eq!(cars[1].id.get(), 2);
        let s = cars[1].state.unwrap();
        assert_eq!(
            (s.x, s.y, s.velocity_mm_s, s.mode.phase),
            (200, 480, -200, 2)
        );
        assert!(!cars[1].stale);

        let r = link
            .request(
                CarId::new(2).unwrap(),
                7,
                &[1, 2, 3],
                Duration::from_secs(3),
            )
            .unwrap();
        assert_eq!(
            (r.car.get(), r.tag, r.payload.clone(), r.counter),
            (2, 7, vec![1, 2, 3], 500)
        );
        assert_eq!(file.load().unwrap(), Some(501), "persisted before sending");
        let each = link.request_each(8, b"hi", Duration::from_secs(3));
        assert_eq!(each.len(), 2);
        assert!(each.iter().all(|(_, r)| r.is_ok()), "{each:?}");
        assert_eq!(link.next_counter(), 503);
        assert_eq!(file.load().unwrap(), Some(503));

        let b = link.broadcast(9, &[], Duration::from_secs(2)).unwrap();
        assert_eq!(b.counter, 503);
        assert!(matches!(
            link.request(CarId::new(1).unwrap(), 1, &[0; 33], Duration::from_secs(1)),
            Err(GroundError::PayloadTooLong { len: 33 })
        ));

        let heard: Vec<GroundEvent> = events.try_iter().collect();
        assert!(heard.iter().any(|e| matches!(e.event, Event::State { .. })));
        assert!(heard
            .iter()
            .any(|e| matches!(e.event, Event::Reply { tag: 7, .. })));
        let (mac, io) = link.close();
        assert!(
            mac.rx_frames > 5 && io.bytes_in > 80 && io.bytes_out > 0,
            "{mac:?} {io:?}"
        );
        thread::sleep(Duration::from_millis(100));
        let (reports, _) = w.stop();
        // Car 2: the request, the round to each car, and the broadcast; all authenticated.
        assert_eq!(
            reports[1].executed,
            vec![
                (7, vec![1, 2, 3], true),
                (8, b"hi".to_vec(), true),
                (9, vec![], true)
            ]
        );
        assert_eq!(reports[0].executed.len(), 2);
        let _ = std::fs::remove_file(file.path());
    }

    #[test]
    fn wrong_key_gets_no_reply_and_the_car_counts_it() {
        let w = world("key", *b"another-key-0123");
        let link = open(&w, KEY, 1);
        wait_for_cars(&link, 1);
        let t = Instant::now();
        let r = link.request(CarId::new(1).unwrap(), 7, &[1], Duration::from_secs(10));
        assert!(
            matches!(
                r,
                Err(GroundError::NoReply {
                    attempts: USER_MAX_ATTEMPTS,
                    ..
                })
            ),
            "{r:?}"
        );
        // The user's requests are retried for about 6.2 s before giving up.
        assert!(t.elapsed() > Duration::from_millis(5500));
        drop(link);
        let (reports, _) = w.stop();
        assert!(reports[0].executed.is_empty());
        assert!(
            reports[0].stats.auth_bad_mac >= u32::from(USER_MAX_ATTEMPTS) - 1,
            "{:?}",
            reports[0].stats
        );
    }

    #[test]
    fn requests_from_a_car_are_acknowledged_and_delivered() {
        use std::io::{Read, Write};
        use std::os::unix::net::UnixListener;
        let path = std::env::temp_dir().join(format!("almc-gl-{}-notice.sock", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let listener = UnixListener::bind(&path).unwrap();
        let link = GroundLink::open(&format!("unix:{}", path.display()), Key::new(KEY), 1).unwrap();
        let events = link.subscribe();
        let (mut s, _) = listener.accept().unwrap();
        s.set_read_timeout(Some(Duration::from_millis(1))).unwrap();
        let mut car = radio_mac::CarMac::new(CarConfig::new(CarId::new(5).unwrap()));
        let t0 = Instant::now();
        let now = || t0.elapsed().as_micros() as u64;
        let h = car
            .request(now(), Address::Ground, 0x10, &[1, 5, 0])
            .unwrap();
        let mut buf = [0u8; 256];
        let mut acked = None;
        while acked.is_none() && t0.elapsed() < Duration::from_secs(2) {
            if let Ok(n) = s.read(&mut buf) {
                car.push_rx(now(), &buf[..n]);
            }
            car.poll(now());
            let n = car.transmit(&mut buf);
            s.write_all(&buf[..n]).unwrap();
            while let Some(ev) = car.next_event() {
                if let Event::Reply {
                    handle,
                    tag,
                    payload,
                    ..
                } = ev
                {
                    acked = Some((handle, tag, payload.to_vec()));
                }
            }
        }
        assert_eq!(acked, Some((h, 0x10, vec![])));
        assert_eq!(car.stats().retries, 0);
        let notice = events.try_iter().find_map(|e| match e.event {
            Event::Request(inc) => Some((inc.tag, inc.payload.to_vec())),
            _ => None,
        });
        assert_eq!(notice, Some((0x10, vec![1, 5, 0])));
        assert_eq!(link.stats().1.requests_acknowledged, 1);
        drop(link);
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn the_last_counter_leads_to_a_new_session_not_a_deaf_car() {
        let w = world("wrap", KEY);
        let link = open(&w, KEY, u32::MAX - 1);
        wait_for_cars(&link, 2);
        let car = CarId::new(1).unwrap();
        let mut counters = Vec::new();
        for i in 0..3u8 {
            let r = link.request(car, 7, &[i], Duration::from_secs(5)).unwrap();
            counters.push(r.counter);
        }
        // After u32::MAX the station moves to its next epoch and the car joins it.
        assert_eq!(counters, [u32::MAX - 1, u32::MAX, 1]);
        assert_eq!(link.next_counter(), 2);
        drop(link);
        let (reports, _) = w.stop();
        assert_eq!(reports[0].executed.len(), 3);
    }

    #[test]
    fn every_run_has_its_own_session_epoch() {
        let a: std::collections::HashSet<u32> = (0..50).map(|_| random_epoch()).collect();
        assert_eq!(a.len(), 50);
    }

    #[test]
    fn timeout_and_closed_link_are_reported() {
        let w = world("closed", KEY);
        let link = open(&w, KEY, 1);
        let r = link.request(CarId::new(9).unwrap(), 1, &[], Duration::from_millis(100));
        assert!(matches!(r, Err(GroundError::Timeout { .. })), "{r:?}");
        let t = Instant::now();
        while !w.hub.stats().node("ground").is_some_and(|n| n.connected)
            && t.elapsed() < Duration::from_secs(2)
        {
            thread::sleep(Duration::from_millis(10));
        }
        let _ = w.stop();
        let t = Instant::now();
        while link.closed().is_none() && t.elapsed() < Duration::from_secs(2) {
            thread::sleep(Duration::from_millis(10));
        }
        assert_eq!(link.closed(), Some(LinkClosed::EndOfStream));
        assert!(matches!(
            link.request(CarId::new(1).unwrap(), 1, &[], Duration::from_secs(1)),
            Err(GroundError::Closed(LinkClosed::EndOfStream))
        ));
        assert!(matches!(
            GroundLink::open("bogus", Key::new(KEY), 0),
            Err(GroundError::Spec(_))
        ));
        assert!(matches!(
            GroundLink::open("unix:/nonexistent/x.sock", Key::new(KEY), 0),
            Err(GroundError::Open(_))
        ));
    }
}
