//! A world of N cars in real time: each car is a QEMU instance running the real UBC firmware,
//! wired to its own emulated LBC; all radios share one [`Hub`] with a ground station, and an
//! overhead tracker feeds every LBC its car's true pose.
//!
//! One engine thread owns every [`Lbc`] (each behind its own Unix socket, which QEMU's LBC
//! UART connects to), the tracker (30 Hz by default, with Gaussian noise, latency and drops)
//! and a `radio_mac::GroundStation` on the hub's ground socket. The QEMU processes stay on
//! the thread that called [`World::start`]. Dropping the [`World`] stops the engine, kills
//! every QEMU and removes every socket, however the caller ends.

use crate::camera::CarPose;
use crate::camera_feed::{ram_file_name, CameraFeed, FeedConfig, FeedTarget};
use crate::hub::{EndpointSpec, Hub, HubConfig, HubStats, NodeConfig};
use crate::radio_medium::MediumParams;
use lbc_emu::{FaultConfig, Lbc, LbcConfig, LbcStats, Pose};
use qemu_harness::{Qemu, SharedRamSpec, SocketSpec, UartAttach};
use radio_mac::{Address, CarId, CarState, Event, GroundConfig, GroundStation, Key, RequestHandle};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};
use ubc_app::program::console::{self, Reply, Request};

pub use qemu_harness::firmware_elf;

/// Millimetres per tracking unit.
pub const MM_PER_UNIT: f64 = 2.5;
/// Largest bytes queued for one LBC client before the oldest are dropped.
const MAX_PENDING: usize = 64 * 1024;
/// Engine turn period.
const TURN: Duration = Duration::from_millis(1);

/// One car of the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarSpec {
    /// Car ID (1..=126), written to EEPROM register 0x00.
    pub id: u8,
    /// Start pose (mm, mm, rad counter-clockwise from +X).
    pub start: Pose,
}

/// The overhead tracker's imperfections.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingParams {
    /// Broadcast rate, Hz.
    pub rate_hz: f64,
    /// Standard deviation of the position noise, mm.
    pub noise_mm: f64,
    /// Standard deviation of the heading noise, mrad.
    pub heading_noise_mrad: f64,
    /// Delay from measuring a pose to the LBC receiving it.
    pub latency: Duration,
    /// Probability that one car's fix is lost.
    pub drop: f64,
}

impl Default for TrackingParams {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            noise_mm: 0.0,
            heading_noise_mrad: 0.0,
            latency: Duration::from_millis(10),
            drop: 0.0,
        }
    }
}

/// Everything that configures a world.
#[derive(Debug, Clone)]
pub struct WorldConfig {
    /// The firmware ELF (usually `qemu_harness::firmware_elf()`).
    pub firmware: PathBuf,
    /// The cars.
    pub cars: Vec<CarSpec>,
    /// The tracker.
    pub tracking: TrackingParams,
    /// The radio channel.
    pub radio: MediumParams,
    /// LBC link faults, applied to every car.
    pub lbc_faults: FaultConfig,
    /// Seed of every random source.
    pub seed: u64,
    /// The command key shared by the ground station and the firmware.
    pub key: [u8; 16],
    /// How long to wait for each firmware's banner.
    pub boot_timeout: Duration,
    /// Camera frames into every car's frame grabber (`camera_feed`); `None`: no camera.
    pub camera: Option<FeedConfig>,
}

impl WorldConfig {
    /// A world of `cars` with default tracking, radio and no faults.
    pub fn new(firmware: impl Into<PathBuf>, cars: Vec<CarSpec>) -> Self {
        Self {
            firmware: firmware.into(),
            cars,
            tracking: TrackingParams::default(),
            radio: MediumParams::default(),
            lbc_faults: FaultConfig::default(),
            seed: 1,
            key: ubc_app::program::DEFAULT_KEY,
            boot_timeout: Duration::from_secs(30),
            camera: None,
        }
    }
}

/// Why the world could not start or answer.
#[derive(Debug)]
pub enum WorldError {
    /// No cars, a car ID outside 1..=126, or one ID twice.
    BadCar {
        /// The offending ID.
        id: u8,
    },
    /// A socket or directory could not be created.
    Io(io::Error),
    /// QEMU failed to start or the firmware did not boot.
    Qemu {
        /// The car.
        id: u8,
        /// The cause.
        source: qemu_harness::Error,
    },
    /// A socket QEMU should have created did not appear.
    SocketMissing {
        /// The path.
        path: PathBuf,
    },
    /// The radio hub failed.
    Hub(crate::hub::HubError),
    /// The engine thread is gone.
    EngineStopped,
    /// The request could not be encoded.
    Encode(console::EncodeError),
    /// The radio refused to send the request.
    Send(radio_mac::SendError),
    /// The car did not answer after every retransmission.
    NoReply {
        /// The car.
        id: u8,
    },
    /// No answer within the caller's timeout.
    Timeout {
        /// The car.
        id: u8,
    },
    /// The answer did not decode.
    BadReply(console::DecodeError),
}

impl fmt::Display for WorldError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadCar { id } => write!(f, "car ID {id} is outside 1..=126 or given twice"),
            Self::Io(e) => write!(f, "{e}"),
            Self::Qemu { id, source } => write!(f, "car {id}: {source}"),
            Self::SocketMissing { path } => write!(f, "{} did not appear", path.display()),
            Self::Hub(e) => write!(f, "radio hub: {e}"),
            Self::EngineStopped => write!(f, "the world's engine thread stopped"),
            Self::Encode(e) => write!(f, "request does not encode: {e:?}"),
            Self::Send(e) => write!(f, "radio refused the request: {e:?}"),
            Self::NoReply { id } => write!(f, "car {id} did not answer"),
            Self::Timeout { id } => write!(f, "car {id}: no answer in time"),
            Self::BadReply(e) => write!(f, "reply does not decode: {e:?}"),
        }
    }
}

impl std::error::Error for WorldError {}

impl From<io::Error> for WorldError {
    fn from(e: io::Error) -> Self {
        Self::Io(e)
    }
}

/// What the world knows of one car right now (the truth, not what the car believes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarTruth {
    /// Car ID.
    pub id: u8,
    /// Pose from the vehicle model.
    pub pose: Pose,
    /// Speed from the vehicle model, mm/s.
    pub v_mm_s: f64,
    /// The LBC's link counters.
    pub lbc: LbcStats,
    /// LBC fault counters (dropped, corrupted, suppressed, resets).
    pub lbc_faults: lbc_emu::faults::FaultStats,
    /// The firmware's LBC UART is connected.
    pub connected: bool,
    /// Tracking fixes delivered to the LBC.
    pub fixes_delivered: u64,
    /// Tracking fixes dropped by the tracker.
    pub fixes_dropped: u64,
    /// Latest radio state the ground station heard from the car.
    pub radio_state: Option<CarState>,
    /// Radio state broadcasts the ground station heard from the car.
    pub states_heard: u64,
}

/// Ground-station counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct GroundCounters {
    /// Requests sent.
    pub requests: u64,
    /// Replies received.
    pub replies: u64,
    /// Requests that got no reply after every retransmission.
    pub failed: u64,
    /// State broadcasts heard.
    pub states_heard: u64,
    /// Notices (requests from cars) acknowledged.
    pub notices: u64,
}

/// Something the world records as it runs (for event logs).
#[derive(Debug, Clone, PartialEq)]
pub struct WorldEvent {
    /// Time since the world started.
    pub at: Duration,
    /// The car concerned.
    pub car: u8,
    /// What happened.
    pub what: String,
}

struct CarEngine {
    id: u8,
    lbc: Lbc,
    listener: UnixListener,
    conn: Option<UnixStream>,
    pending: Vec<u8>,
    fixes: VecDeque<(u64, u16, u16, u16)>,
    fixes_delivered: u64,
    fixes_dropped: u64,
    radio_state: Option<CarState>,
    states_heard: u64,
}

#[derive(Debug)]
enum Outcome {
    Reply(u8, Vec<u8>),
    Failed,
}

struct Engine {
    cars: Vec<CarEngine>,
    ground: GroundStation,
    ground_path: PathBuf,
    ground_conn: Option<UnixStream>,
    waiters: Vec<(RequestHandle, Sender<Outcome>)>,
    counters: GroundCounters,
    tracking: TrackingParams,
    next_fix_us: u64,
    rng: ChaCha8Rng,
    events: Vec<WorldEvent>,
}

struct Shared {
    engine: Mutex<Engine>,
    stop: AtomicBool,
    started: Instant,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Engine> {
        self.engine.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn now_us(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_micros()).unwrap_or(u64::MAX)
    }
}

/// Removes a directory however the world ends.
struct DirGuard(PathBuf);

impl Drop for DirGuard {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A running world. Keep it on the thread that started it (its QEMU processes belong to it).
pub struct World {
    // Field order is drop order: the camera feed and QEMU first, then the hub, the engine,
    // the sockets.
    camera: Option<CameraFeed>,
    qemus: Vec<(u8, Qemu)>,
    hub: Option<Hub>,
    shared: Arc<Shared>,
    engine: Option<JoinHandle<()>>,
    ids: Vec<u8>,
    _dir: DirGuard,
}

impl fmt::Debug for World {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("World")
            .field("cars", &self.ids)
            .finish_non_exhaustive()
    }
}

fn wait_for_path(path: &Path, timeout: Duration) -> Result<(), WorldError> {
    let start = Instant::now();
    while !path.exists() {
        if start.elapsed() > timeout {
            return Err(WorldError::SocketMissing { path: path.into() });
        }
        thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

/// Metres on the radio medium from a pose in mm.
fn metres(p: &Pose) -> (f64, f64) {
    (p.x_mm / 1000.0, p.y_mm / 1000.0)
}

impl World {
    /// Starts the LBCs, boots every car's firmware in QEMU, joins the radios and the ground
    /// station to a hub, and starts the tracker. Returns once every firmware printed its banner.
    pub fn start(cfg: &WorldConfig) -> Result<World, WorldError> {
        let mut ids: Vec<u8> = Vec::new();
        for c in &cfg.cars {
            if CarId::new(c.id).is_none() || ids.contains(&c.id) {
                return Err(WorldError::BadCar { id: c.id });
            }
            ids.push(c.id);
        }
        if ids.is_empty() {
            return Err(WorldError::BadCar { id: 0 });
        }
        let dir = std::env::temp_dir().join(format!(
            "almc-arena-{}-{}",
            std::process::id(),
            NEXT_WORLD.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir)?;
        let dir = DirGuard(dir);
        let mut cars = Vec::new();
        for (i, c) in cfg.cars.iter().enumerate() {
            let mut lc = LbcConfig::default();
            lc.start_pose = c.start;
            lc.faults = cfg.lbc_faults;
            lc.seed = cfg.seed.wrapping_add(i as u64 * 7919);
            let path = dir.0.join(format!("car{}-lbc.sock", c.id));
            let listener = UnixListener::bind(&path)?;
            listener.set_nonblocking(true)?;
            cars.push(CarEngine {
                id: c.id,
                lbc: Lbc::with_memory_eeprom(lc, c.id),
                listener,
                conn: None,
                pending: Vec::new(),
                fixes: VecDeque::new(),
                fixes_delivered: 0,
                fixes_dropped: 0,
                radio_state: None,
                states_heard: 0,
            });
        }
        let ground_path = dir.0.join("ground.sock");
        let mut gcfg = GroundConfig::new(Key::new(cfg.key), 1);
        gcfg.retry.max_us = 1_000_000;
        gcfg.retry.max_attempts = 10;
        gcfg.seed = (cfg.seed as u32) ^ 0x5A5A;
        let shared = Arc::new(Shared {
            engine: Mutex::new(Engine {
                cars,
                ground: GroundStation::new(gcfg),
                ground_path: ground_path.clone(),
                ground_conn: None,
                waiters: Vec::new(),
                counters: GroundCounters::default(),
                tracking: cfg.tracking,
                next_fix_us: 0,
                rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x7472_6163),
                events: Vec::new(),
            }),
            stop: AtomicBool::new(false),
            started: Instant::now(),
        });
        let s = shared.clone();
        let engine = thread::Builder::new()
            .name("arena-world".into())
            .spawn(move || run_engine(&s))?;
        let mut world = World {
            camera: None,
            qemus: Vec::new(),
            hub: None,
            shared,
            engine: Some(engine),
            ids,
            _dir: dir,
        };
        let mut feed_targets = Vec::new();
        let mut nodes = vec![NodeConfig::new(
            "ground",
            EndpointSpec::UnixListen(ground_path),
            (0.75, -0.2),
        )];
        for c in &cfg.cars {
            let lbc = world._dir.0.join(format!("car{}-lbc.sock", c.id));
            let radio = world._dir.0.join(format!("car{}-radio.sock", c.id));
            let mut builder = Qemu::builder(&cfg.firmware)
                .lbc(UartAttach::Connect(SocketSpec::Unix(lbc)))
                .radio(UartAttach::Listen(SocketSpec::Unix(radio.clone())));
            if let Some(feed) = &cfg.camera {
                let spec = SharedRamSpec::new(world._dir.0.join(ram_file_name(c.id)));
                let target = FeedTarget::create(c.id, spec.path.clone(), spec.len(), feed)
                    .map_err(|e| WorldError::Io(io::Error::other(e)))?;
                feed_targets.push(target);
                builder = builder.shared_ram(spec);
            }
            let qemu = builder
                .spawn()
                .map_err(|source| WorldError::Qemu { id: c.id, source })?;
            world.qemus.push((c.id, qemu));
            wait_for_path(&radio, Duration::from_secs(10))?;
            nodes.push(NodeConfig::new(
                format!("car{}", c.id),
                EndpointSpec::UnixConnect(radio),
                metres(&c.start),
            ));
        }
        for (id, q) in &world.qemus {
            q.wait_for_log(|l| l.message.contains("ubc-app"), cfg.boot_timeout)
                .map_err(|source| WorldError::Qemu { id: *id, source })?;
        }
        let hub_cfg = HubConfig {
            params: cfg.radio.clone(),
            seed: cfg.seed,
            ..HubConfig::default()
        };
        world.hub = Some(Hub::start(hub_cfg, nodes).map_err(WorldError::Hub)?);
        if let Some(feed) = cfg.camera {
            let shared = world.shared.clone();
            let poses = move || {
                shared
                    .lock()
                    .cars
                    .iter()
                    .map(|c| {
                        let p = c.lbc.vehicle().pose();
                        CarPose {
                            id: c.id,
                            x_mm: p.x_mm as f32,
                            y_mm: p.y_mm as f32,
                            yaw_rad: p.heading_rad as f32,
                        }
                    })
                    .collect()
            };
            world.camera = Some(CameraFeed::start(feed, feed_targets, poses)?);
        }
        Ok(world)
    }

    /// The directory holding the world's sockets and, with a camera, each car's RAM file
    /// (`car<ID>-ram`, see `camera_feed`); removed when the world ends.
    pub fn run_dir(&self) -> &Path {
        &self._dir.0
    }

    /// The camera feed's counters, if the world has a camera.
    pub fn camera_stats(&self) -> Option<crate::camera_feed::FeedStats> {
        self.camera.as_ref().map(CameraFeed::stats)
    }

    /// Car IDs in configuration order.
    pub fn ids(&self) -> &[u8] {
        &self.ids
    }

    /// Each car's QEMU process ID (for resource accounting).
    pub fn qemu_pids(&self) -> Vec<(u8, u32)> {
        self.qemus.iter().map(|(id, q)| (*id, q.pid())).collect()
    }

    /// Time since the world started.
    pub fn elapsed(&self) -> Duration {
        self.shared.started.elapsed()
    }

    /// The truth about every car, in configuration order. Also moves each car's radio node to
    /// where the car is.
    pub fn truth(&self) -> Vec<CarTruth> {
        let truth: Vec<CarTruth> = {
            let e = self.shared.lock();
            e.cars
                .iter()
                .map(|c| CarTruth {
                    id: c.id,
                    pose: c.lbc.vehicle().pose(),
                    v_mm_s: c.lbc.vehicle().speed_mm_s(),
                    lbc: c.lbc.stats(),
                    lbc_faults: c.lbc.fault_stats(),
                    connected: c.conn.is_some(),
                    fixes_delivered: c.fixes_delivered,
                    fixes_dropped: c.fixes_dropped,
                    radio_state: c.radio_state,
                    states_heard: c.states_heard,
                })
                .collect()
        };
        if let Some(hub) = &self.hub {
            for t in &truth {
                let _ = hub.set_position(&format!("car{}", t.id), metres(&t.pose));
            }
        }
        truth
    }

    /// Ground-station counters.
    pub fn ground_counters(&self) -> GroundCounters {
        self.shared.lock().counters
    }

    /// Ground-station protocol counters.
    pub fn ground_stats(&self) -> radio_mac::Stats {
        *self.shared.lock().ground.stats()
    }

    /// Hub (radio medium) counters.
    pub fn hub_stats(&self) -> Option<HubStats> {
        self.hub.as_ref().map(Hub::stats)
    }

    /// Events recorded since the last call (connections, LBC resets, notices).
    pub fn take_events(&self) -> Vec<WorldEvent> {
        std::mem::take(&mut self.shared.lock().events)
    }

    /// The firmware log of car `id` (decoded defmt lines), if it is in the world.
    pub fn firmware_log(&self, id: u8) -> Option<Vec<String>> {
        self.qemus
            .iter()
            .find(|(i, _)| *i == id)
            .map(|(_, q)| q.log().lines().iter().map(|l| l.to_string()).collect())
    }

    /// Sends a console request to car `id` and waits up to `timeout` for its reply.
    pub fn request(&self, id: u8, req: &Request, timeout: Duration) -> Result<Reply, WorldError> {
        let deadline = Instant::now() + timeout;
        let pending = loop {
            if let Some(p) = self.try_request(id, req)? {
                break p;
            }
            if Instant::now() >= deadline {
                return Err(WorldError::Timeout { id });
            }
            thread::sleep(Duration::from_millis(5));
        };
        match pending
            .rx
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            Ok(Outcome::Reply(tag, payload)) => {
                Reply::decode(tag, &payload).map_err(WorldError::BadReply)
            }
            Ok(Outcome::Failed) => Err(WorldError::NoReply { id }),
            Err(_) => Err(WorldError::Timeout { id }),
        }
    }

    /// Sends a console request to car `id` without waiting: `Ok(None)` when the ground
    /// station is busy with another request (it carries one authenticated command at a time;
    /// try again later), else the [`PendingReply`] to poll.
    pub fn try_request(&self, id: u8, req: &Request) -> Result<Option<PendingReply>, WorldError> {
        let car = CarId::new(id).ok_or(WorldError::BadCar { id })?;
        let mut buf = [0u8; console::MAX_PAYLOAD];
        let n = req.encode(&mut buf).map_err(WorldError::Encode)?;
        let mut e = self.shared.lock();
        if self.shared.stop.load(Ordering::Relaxed) {
            return Err(WorldError::EngineStopped);
        }
        let now = self.shared.now_us();
        match e
            .ground
            .command(now, Address::Car(car), req.tag() as u8, &buf[..n])
        {
            Ok(h) => {
                let (tx, rx) = mpsc::channel();
                e.waiters.push((h, tx));
                e.counters.requests += 1;
                Ok(Some(PendingReply { id, rx }))
            }
            Err(radio_mac::SendError::Busy) | Err(radio_mac::SendError::TxQueueFull) => Ok(None),
            Err(err) => Err(WorldError::Send(err)),
        }
    }

    /// Stops everything now (also done on drop); returns the hub's final counters.
    pub fn shutdown(mut self) -> Option<HubStats> {
        self.stop()
    }

    fn stop(&mut self) -> Option<HubStats> {
        self.camera = None;
        for (_, q) in &mut self.qemus {
            let _ = q.kill();
        }
        self.qemus.clear();
        let stats = self.hub.take().map(Hub::shutdown);
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.engine.take() {
            let _ = t.join();
        }
        stats
    }
}

impl Drop for World {
    fn drop(&mut self) {
        self.stop();
    }
}

/// A console request on its way (see [`World::try_request`]).
#[derive(Debug)]
pub struct PendingReply {
    id: u8,
    rx: Receiver<Outcome>,
}

impl PendingReply {
    /// The car asked.
    pub fn car(&self) -> u8 {
        self.id
    }

    /// The outcome once it is known: the decoded reply, or `NoReply` after every
    /// retransmission failed (or the world stopped).
    pub fn poll(&self) -> Option<Result<Reply, WorldError>> {
        match self.rx.try_recv() {
            Ok(Outcome::Reply(tag, payload)) => {
                Some(Reply::decode(tag, &payload).map_err(WorldError::BadReply))
            }
            Ok(Outcome::Failed) | Err(mpsc::TryRecvError::Disconnected) => {
                Some(Err(WorldError::NoReply { id: self.id }))
            }
            Err(mpsc::TryRecvError::Empty) => None,
        }
    }
}

static NEXT_WORLD: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    lbc_emu::vehicle::gaussian(rng)
}

fn run_engine(shared: &Shared) {
    let mut inbuf = [0u8; 4096];
    let mut out = Vec::new();
    let mut radio_out = [0u8; 512];
    while !shared.stop.load(Ordering::Relaxed) {
        {
            let mut guard = shared.lock();
            let e = &mut *guard;
            let now = shared.now_us();
            let at = shared.started.elapsed();
            track(e, now);
            for c in &mut e.cars {
                serve_lbc(c, now, &mut inbuf, &mut out, &mut e.events, at);
            }
            serve_ground(e, now, at, &mut inbuf, &mut radio_out);
        }
        thread::sleep(TURN);
    }
}

/// The tracker: samples every car at its rate, queues the fix with latency, delivers due fixes.
fn track(e: &mut Engine, now: u64) {
    let period_us = (1e6 / e.tracking.rate_hz.max(0.1)) as u64;
    let latency_us = u64::try_from(e.tracking.latency.as_micros()).unwrap_or(u64::MAX);
    if now >= e.next_fix_us {
        e.next_fix_us = e.next_fix_us.max(now.saturating_sub(period_us)) + period_us;
        for c in &mut e.cars {
            if e.rng.random::<f64>() < e.tracking.drop {
                c.fixes_dropped += 1;
                continue;
            }
            let p = c.lbc.vehicle().pose();
            let x = p.x_mm + gaussian(&mut e.rng) * e.tracking.noise_mm;
            let y = p.y_mm + gaussian(&mut e.rng) * e.tracking.noise_mm;
            let h = p.heading_rad * 1000.0 + gaussian(&mut e.rng) * e.tracking.heading_noise_mrad;
            let units = |mm: f64, max: f64| (mm / MM_PER_UNIT).round().clamp(0.0, max) as u16;
            let h = h
                .rem_euclid(std::f64::consts::TAU * 1000.0)
                .round()
                .min(6283.0) as u16;
            c.fixes
                .push_back((now + latency_us, units(x, 640.0), units(y, 960.0), h));
        }
    }
    for c in &mut e.cars {
        while let Some(&(t, x, y, h)) = c.fixes.front() {
            if t > now {
                break;
            }
            c.fixes.pop_front();
            c.lbc.set_tracked_pose(now, x, y, h);
            c.fixes_delivered += 1;
        }
    }
}

fn serve_lbc(
    c: &mut CarEngine,
    now: u64,
    inbuf: &mut [u8],
    out: &mut Vec<u8>,
    events: &mut Vec<WorldEvent>,
    at: Duration,
) {
    if c.conn.is_none() {
        if let Ok((s, _)) = c.listener.accept() {
            if s.set_nonblocking(true).is_ok() {
                c.conn = Some(s);
                c.pending.clear();
                events.push(WorldEvent {
                    at,
                    car: c.id,
                    what: "lbc-connected".into(),
                });
            }
        }
    }
    let mut lost = false;
    let mut got = 0;
    if let Some(s) = c.conn.as_mut() {
        loop {
            match s.read(&mut inbuf[got..]) {
                Ok(0) => {
                    lost = true;
                    break;
                }
                Ok(n) => {
                    got += n;
                    if got == inbuf.len() {
                        break;
                    }
                }
                Err(err) if err.kind() == ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
    }
    out.clear();
    let resets = c.lbc.stats().resets;
    c.lbc.poll(now, &inbuf[..got], out);
    if c.lbc.stats().resets != resets {
        events.push(WorldEvent {
            at,
            car: c.id,
            what: "lbc-reset".into(),
        });
    }
    if let Some(s) = c.conn.as_mut() {
        c.pending.extend_from_slice(out);
        if c.pending.len() > MAX_PENDING {
            let excess = c.pending.len() - MAX_PENDING;
            c.pending.drain(..excess);
        }
        match write_some(s, &c.pending) {
            Ok(n) => {
                c.pending.drain(..n);
            }
            Err(_) => lost = true,
        }
    }
    if lost {
        c.conn = None;
        c.pending.clear();
        events.push(WorldEvent {
            at,
            car: c.id,
            what: "lbc-disconnected".into(),
        });
    }
}

fn write_some(s: &mut UnixStream, buf: &[u8]) -> io::Result<usize> {
    let mut done = 0;
    while done < buf.len() {
        match s.write(&buf[done..]) {
            Ok(0) => return Err(ErrorKind::WriteZero.into()),
            Ok(n) => done += n,
            Err(e) if e.kind() == ErrorKind::WouldBlock => break,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(done)
}

fn serve_ground(e: &mut Engine, now: u64, at: Duration, inbuf: &mut [u8], radio_out: &mut [u8]) {
    if e.ground_conn.is_none() {
        match UnixStream::connect(&e.ground_path) {
            Ok(s) if s.set_nonblocking(true).is_ok() => e.ground_conn = Some(s),
            _ => return,
        }
    }
    let mut lost = false;
    if let Some(s) = e.ground_conn.as_mut() {
        loop {
            match s.read(inbuf) {
                Ok(0) => {
                    lost = true;
                    break;
                }
                Ok(n) => e.ground.push_rx(now, &inbuf[..n]),
                Err(err) if err.kind() == ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
    }
    e.ground.poll(now);
    while let Some(ev) = e.ground.next_event() {
        match ev {
            Event::Request(inc) if !inc.id.broadcast => {
                // Cars report with requests (notices); an empty reply acknowledges them.
                let acked = e.ground.reply(inc.id, inc.tag, &[]).is_ok();
                if acked {
                    e.counters.notices += 1;
                    if let Address::Car(id) = inc.id.from {
                        let what = match console::Notice::decode(&inc.payload) {
                            Ok(n) => format!("notice {n:?}"),
                            Err(_) => format!("notice tag {}", inc.tag),
                        };
                        e.events.push(WorldEvent {
                            at,
                            car: id.get(),
                            what,
                        });
                    }
                }
            }
            Event::State { from, state, .. } => {
                e.counters.states_heard += 1;
                if let Some(c) = e.cars.iter_mut().find(|c| c.id == from.get()) {
                    c.radio_state = Some(state);
                    c.states_heard += 1;
                }
            }
            Event::Reply {
                handle,
                tag,
                payload,
                ..
            } => {
                e.counters.replies += 1;
                resolve(e, handle, Outcome::Reply(tag, payload.to_vec()));
            }
            Event::Failed { handle, .. } => {
                e.counters.failed += 1;
                resolve(e, handle, Outcome::Failed);
            }
            Event::RepeatsDone { handle } => resolve(e, handle, Outcome::Failed),
            _ => {}
        }
    }
    let n = e.ground.transmit(radio_out);
    if n > 0 {
        if let Some(s) = e.ground_conn.as_mut() {
            // The hub's socket buffer is large; a short write loses radio bytes like a
            // module buffer overflow would.
            if write_some(s, &radio_out[..n]).is_err() {
                lost = true;
            }
        }
    }
    if lost {
        e.ground_conn = None;
    }
}

fn resolve(e: &mut Engine, h: RequestHandle, o: Outcome) {
    if let Some(i) = e.waiters.iter().position(|(w, _)| *w == h) {
        let (_, tx) = e.waiters.swap_remove(i);
        let _ = tx.send(o);
    }
}
