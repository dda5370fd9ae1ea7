//! The world: N cars, each running the real UBC firmware on a car engine ([`crate::engine`]),
//! each wired to its own emulated LBC (`lbc-emu`, which also moves the vehicle); a radio
//! medium ([`RadioMedium`]) per radio channel in use, shared by the radios of the cars on that
//! channel and a ground station; the overhead tracker; the synthetic camera feeding each
//! car's frame grabber.
//!
//! The world owns time. It advances in fixed quanta of world time: every car runs to the end of
//! the quantum with the bytes due to it, then the world feeds what the cars sent to the LBCs
//! and the medium (merged in time order), steps them, the tracker, the camera and the ground
//! station to the same instant, and queues their output for the cars. Cars touch the world only
//! at these boundaries, so with the virtual-time engine a run is a function of its
//! configuration and seed, whatever the number of threads. With QEMU (or `realtime`) each
//! quantum also waits for the wall clock, so a person can talk to the cars.
//!
//! Dropping the [`World`] stops every car and removes its run directory.

mod config;
mod ground;
mod radio;
mod report;
mod tap;
mod tracker;

mod truth;

pub use config::{
    CarSpec, EngineKind, TrackingParams, WorldConfig, WorldError, DEFAULT_QUANTUM,
    MAX_RADIO_CHANNEL,
};
pub use truth::{CarTruth, GroundCounters, NodeCounters, WorldEvent};

pub use ground::PendingReply;
pub use qemu_harness::{firmware_elf, softcore_elf};
pub use tap::{LbcTraffic, NodeTraffic, Tap, TapConfig, TapFrame};

use crate::camera::{CarPose, SyntheticCamera};
use crate::camera_feed::{ram_file_name, FeedStats, WindowPublisher, RUN_DIR_PREFIX};
use crate::engine::iss::IssEngine;
use crate::engine::qemu::QemuEngine;
use crate::engine::{CarEngine, CarIo, Nanos};
use crate::radio_medium::NodeId;
use lbc_emu::{Lbc, LbcConfig, Pose};
use qemu_harness::{SharedRam, SharedRamSpec};
use radio::Channel;
use radio_mac::CarId;
use std::fmt;
use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tracker::Tracker;
use ubc_app::program::console::{Reply, Request};

/// Millimetres per tracking unit.
pub const MM_PER_UNIT: f64 = 2.5;

/// Removes a directory however the world ends.
#[derive(Debug)]
struct DirGuard(PathBuf);

impl Drop for DirGuard {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The camera: one synthetic camera and window writer per car.
struct Camera {
    period: Nanos,
    next: Nanos,
    cams: Vec<SyntheticCamera>,
    publishers: Vec<Option<WindowPublisher>>,
    /// Real-time virtual-time worlds also publish each frame into a RAM-file window in the run
    /// directory (`car<ID>-ram`, as a QEMU car's), so `almc camera snapshot` reads it.
    mirrors: Vec<Option<(WindowPublisher, SharedRam)>>,
    frame: Vec<u8>,
    stats: FeedStats,
}

/// A person's ground station attached over a socket (real-time worlds only).
struct UserLink {
    listener: UnixListener,
    conn: Option<UnixStream>,
    node: NodeId,
}

/// A running world.
pub struct World {
    engine: Box<dyn CarEngine>,
    lbcs: Vec<Lbc>,
    io: Vec<CarIo>,
    ids: Vec<u8>,
    /// Each car's node on its channel's medium.
    nodes: Vec<NodeId>,
    node_counters: Vec<NodeCounters>,
    /// The radio channels in use (see [`radio`]); the first carries a person's link.
    channels: Vec<Channel>,
    /// Each car's index into `channels`.
    channel_of: Vec<usize>,
    tracker: Tracker,
    camera: Option<Camera>,
    user: Option<UserLink>,
    failed: Vec<bool>,
    /// The engine's count of failed cars when the world last looked ([`CarEngine::failures`]).
    failures_seen: Option<usize>,
    events: Vec<WorldEvent>,
    now: Nanos,
    quantum: Nanos,
    paced: bool,
    wall_start: Instant,
    stop_failed: bool,
    scratch: Vec<(Nanos, usize, u8)>,
    rx_scratch: Vec<(Nanos, u8)>,
    tap: Option<tap::TapState>,
    _dir: DirGuard,
}

impl fmt::Debug for World {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("World")
            .field("engine", &self.engine.name())
            .field("cars", &self.ids)
            .field("now_ns", &self.now)
            .finish_non_exhaustive()
    }
}

static NEXT_WORLD: AtomicU64 = AtomicU64::new(0);

/// The quantum of a world of QEMU cars when none other is asked for.
const QEMU_QUANTUM: Duration = Duration::from_millis(1);

/// Removes the run directories (sockets, RAM files) of worlds whose process is gone, as a
/// killed run leaves them.
fn remove_stale_run_dirs() {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with(RUN_DIR_PREFIX) && !crate::camera_feed::owner_alive(&name) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Metres on the radio medium from a pose in mm.
fn metres(p: &Pose) -> (f64, f64) {
    (p.x_mm / 1000.0, p.y_mm / 1000.0)
}

fn nanos(d: Duration) -> Nanos {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl World {
    /// Starts every car's firmware on the chosen engine with its LBC, the radio medium, the
    /// ground station and the tracker, at world time zero.
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
        if cfg.quantum.is_zero() || cfg.quantum > Duration::from_millis(10) {
            return Err(WorldError::BadQuantum(cfg.quantum));
        }
        remove_stale_run_dirs();
        let dir = std::env::temp_dir().join(format!(
            "{RUN_DIR_PREFIX}{}-{}",
            std::process::id(),
            NEXT_WORLD.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir)?;
        let dir = DirGuard(dir);
        let firmware: Vec<PathBuf> = cfg
            .cars
            .iter()
            .map(|c| c.firmware.clone().unwrap_or_else(|| cfg.firmware.clone()))
            .collect();
        let mut engine: Box<dyn CarEngine> = match cfg.engine {
            EngineKind::Iss => {
                let profiled: Vec<usize> = ids
                    .iter()
                    .enumerate()
                    .filter(|(_, id)| cfg.profile_cars.contains(id))
                    .map(|(k, _)| k)
                    .collect();
                Box::new(
                    IssEngine::new(&firmware, cfg.threads.max(1), &profiled)
                        .map_err(WorldError::Iss)?,
                )
            }
            EngineKind::Qemu => {
                let cars: Vec<(u8, PathBuf)> = ids.iter().copied().zip(firmware).collect();
                Box::new(
                    QemuEngine::start(
                        &dir.0,
                        &cars,
                        cfg.camera.map(|c| c.vision_unit),
                        cfg.boot_timeout,
                    )
                    .map_err(WorldError::Qemu)?,
                )
            }
        };
        let lbcs: Vec<Lbc> = cfg
            .cars
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let mut lc = LbcConfig::default();
                lc.start_pose = c.start;
                lc.faults = cfg.lbc_faults;
                lc.seed = cfg.seed.wrapping_add(i as u64 * 7919);
                Lbc::with_memory_eeprom(lc, c.id)
            })
            .collect();
        for c in &cfg.cars {
            if c.radio_channel > MAX_RADIO_CHANNEL {
                return Err(WorldError::BadChannel {
                    id: c.id,
                    channel: c.radio_channel,
                });
            }
        }
        let radio::Radio {
            mut channels,
            channel_of,
            nodes,
            counters: mut node_counters,
        } = radio::channels(&cfg.cars, &ids, &cfg.radio, cfg.key, cfg.seed);
        let engine_is_wall_clock = engine.wall_clock();
        let paced = cfg.realtime || engine_is_wall_clock;
        let user = if paced {
            let path = dir.0.join("ground.sock");
            let listener = UnixListener::bind(&path)?;
            listener.set_nonblocking(true)?;
            node_counters.push(NodeCounters {
                name: "user".into(),
                ..NodeCounters::default()
            });
            Some(UserLink {
                listener,
                conn: None,
                node: channels[0].medium.add_node((0.75, -0.3)),
            })
        } else {
            None
        };
        let camera = match cfg.camera {
            Some(config) => {
                let cams: Vec<SyntheticCamera> = ids
                    .iter()
                    .map(|&id| {
                        SyntheticCamera::new(config.camera, config.seed.wrapping_add(u64::from(id)))
                    })
                    .collect();
                let g = cams[0].geometry();
                let publishers = (0..ids.len())
                    .map(|k| {
                        let mut p = None;
                        engine.with_window(k, &mut |w| {
                            w.set_vision_unit(config.vision_unit);
                            p = WindowPublisher::init(w, &g)
                                .ok()
                                .map(|p| p.with_vision_unit(config.vision_unit));
                        });
                        p
                    })
                    .collect();
                let mirror = |id: u8| -> Option<(WindowPublisher, SharedRam)> {
                    let spec = SharedRamSpec::new(dir.0.join(ram_file_name(id)));
                    let mut ram = SharedRam::create(&spec.path, spec.len()).ok()?;
                    let p = WindowPublisher::init(&mut ram, &g).ok()?;
                    Some((p, ram))
                };
                let mirrors = ids
                    .iter()
                    .map(|&id| {
                        if paced && !engine.wall_clock() {
                            mirror(id)
                        } else {
                            None
                        }
                    })
                    .collect();
                Some(Camera {
                    period: (1e9 / config.fps.clamp(0.1, 1000.0)).round() as Nanos,
                    next: 0,
                    frame: vec![0; g.frame_len()],
                    cams,
                    publishers,
                    mirrors,
                    stats: FeedStats::default(),
                })
            }
            None => None,
        };
        let n = ids.len();
        Ok(World {
            engine,
            lbcs,
            io: vec![CarIo::default(); n],
            nodes,
            node_counters,
            channels,
            channel_of,
            tracker: Tracker::new(cfg.tracking, n, cfg.seed),
            camera,
            user,
            failed: vec![false; n],
            failures_seen: None,
            events: Vec::new(),
            now: 0,
            // QEMU cars run on their own; meeting them every millisecond (as a socket poll)
            // is plenty and leaves the host's cores to the emulators.
            quantum: if paced && engine_is_wall_clock && cfg.quantum == DEFAULT_QUANTUM {
                nanos(QEMU_QUANTUM)
            } else {
                nanos(cfg.quantum)
            },
            paced,
            wall_start: Instant::now(),
            stop_failed: cfg.stop_failed_cars,
            scratch: Vec::new(),
            rx_scratch: Vec::new(),
            tap: None,
            ids,
            _dir: dir,
        })
    }

    /// World time.
    pub fn now(&self) -> Duration {
        Duration::from_nanos(self.now)
    }

    /// The engine's name (`iss` or `qemu`).
    pub fn engine_name(&self) -> &'static str {
        self.engine.name()
    }

    /// Whether world time follows the wall clock.
    pub fn paced(&self) -> bool {
        self.paced
    }

    /// The directory holding the run's sockets (and QEMU cars' RAM files); removed when the
    /// world ends. In a real-time world, `ground.sock` in it is a radio node for `almc car`.
    pub fn run_dir(&self) -> &Path {
        &self._dir.0
    }

    /// Car IDs in configuration order.
    pub fn ids(&self) -> &[u8] {
        &self.ids
    }

    /// Runs the world until world time `t` (nothing happens if `t` has passed).
    pub fn run_until(&mut self, t: Duration) {
        let target = nanos(t);
        while self.now < target {
            self.step();
        }
    }

    /// Runs the world for `d` of world time.
    pub fn run_for(&mut self, d: Duration) {
        self.run_until(self.now() + d);
    }

    /// One quantum.
    fn step(&mut self) {
        let t0 = self.now;
        let t1 = t0 + self.quantum;
        self.feed_camera(t0);
        if self.paced {
            let due = self.wall_start + Duration::from_nanos(t1);
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        for io in &mut self.io {
            io.clear_outputs();
        }
        self.engine.advance(t1, &mut self.io);
        self.note_failures();
        // The cars' radio bytes, and a person's, into the medium in time order (each byte
        // leaves the host's UART one byte time before its stop bit ends).
        let byte_ns = self.channels[0].medium.params().uart_byte_ns;
        self.scratch.clear();
        for (k, io) in self.io.iter().enumerate() {
            for &(t, b) in &io.radio_out {
                self.scratch.push((t.saturating_sub(byte_ns), k, b));
            }
            if let Some(tap) = self.tap.as_mut() {
                tap.car_out(k, io, &mut *self.engine);
            }
        }
        self.scratch.sort_by_key(|&(t, k, _)| (t, k));
        for &(t, k, b) in &self.scratch {
            self.channels[self.channel_of[k]]
                .medium
                .write(self.nodes[k], t, &[b]);
            self.node_counters[k + 1].bytes_in += 1;
        }
        // The LBCs: what the cars sent, the tracker's fixes, then their own tasks to t1.
        let t1_us = t1 / 1000;
        for (lbc, io) in self.lbcs.iter_mut().zip(&self.io) {
            for &(t, b) in &io.lbc_out {
                lbc.push_rx(t / 1000, &[b]);
            }
        }
        if self.tracker.step(t1, &mut self.lbcs) {
            for (k, lbc) in self.lbcs.iter().enumerate() {
                self.channels[self.channel_of[k]]
                    .medium
                    .set_position(self.nodes[k], metres(&lbc.vehicle().pose()));
            }
        }
        let ahead_us = (t1 + self.quantum) / 1000;
        for (k, lbc) in self.lbcs.iter_mut().enumerate() {
            let resets = lbc.stats().resets;
            lbc.step_until(t1_us);
            if lbc.stats().resets != resets {
                self.events.push(WorldEvent {
                    at: Duration::from_nanos(t1),
                    car: self.ids[k],
                    what: "lbc-reset".into(),
                });
            }
            let before = self.io[k].lbc_in.len();
            while let Some((t, b)) = lbc.pop_tx(ahead_us) {
                self.io[k].lbc_in.push((t * 1000, b));
            }
            if let Some(tap) = self.tap.as_mut() {
                tap.lbc_out(k, &self.io[k].lbc_in[before..]);
            }
        }
        // The media to t1; bytes they have queued for the cars up to the next quantum's end.
        for ch in &mut self.channels {
            ch.medium.step(t1);
        }
        let ahead = t1 + self.quantum;
        for (k, &node) in self.nodes.iter().enumerate() {
            let before = self.io[k].radio_in.len();
            self.channels[self.channel_of[k]]
                .medium
                .take_rx(node, ahead, &mut self.io[k].radio_in);
            self.node_counters[k + 1].bytes_out += (self.io[k].radio_in.len() - before) as u64;
            if let Some(tap) = self.tap.as_mut() {
                tap.node(k + 1, &self.io[k].radio_in[before..], &[], t1);
            }
        }
        // The ground stations, and a person's ground station.
        for ch in &mut self.channels {
            self.rx_scratch.clear();
            ch.medium.take_rx(ch.ground_node, t1, &mut self.rx_scratch);
            let rx: Vec<u8> = self.rx_scratch.iter().map(|&(_, b)| b).collect();
            self.node_counters[ch.counter].bytes_out += rx.len() as u64;
            let tx = ch.ground.step(t1, &rx, &mut self.events).to_vec();
            if let Some(tap) = self.tap.as_mut() {
                tap.node(ch.counter, &self.rx_scratch, &tx, t1);
            }
            if !tx.is_empty() {
                ch.medium.write(ch.ground_node, t1, &tx);
                self.node_counters[ch.counter].bytes_in += tx.len() as u64;
            }
        }
        self.serve_user(t1);
        self.now = t1;
    }

    /// Publishes a camera frame into every camera car's window at each frame time before
    /// the quantum that starts at `t0` ends.
    fn feed_camera(&mut self, t0: Nanos) {
        let Some(cam) = self.camera.as_mut() else {
            return;
        };
        if cam.next > t0 {
            return;
        }
        let capture = cam.next;
        cam.next += cam.period;
        let poses: Vec<CarPose> = self
            .lbcs
            .iter()
            .zip(&self.ids)
            .map(|(l, &id)| {
                let p = l.vehicle().pose();
                CarPose {
                    id,
                    x_mm: p.x_mm as f32,
                    y_mm: p.y_mm as f32,
                    yaw_rad: p.heading_rad as f32,
                }
            })
            .collect();
        for k in 0..self.ids.len() {
            if self.failed[k] {
                continue;
            }
            let Some(publisher) = cam.publishers[k].as_mut() else {
                continue;
            };
            let mut ok = cam.cams[k]
                .render(&poses[k], &poses, &mut cam.frame)
                .is_ok();
            let frame = &cam.frame;
            let written = self.engine.with_window(k, &mut |w| {
                ok = ok && publisher.publish(w, frame, capture / 1000).is_ok();
            });
            if !written {
                continue;
            }
            if let Some((p, ram)) = cam.mirrors[k].as_mut() {
                let _ = p.publish(ram, &cam.frame, capture / 1000);
            }
            if ok {
                cam.stats.frames += 1;
                if let Some(tap) = self.tap.as_mut() {
                    tap.frame(k, capture, &cam.frame, &cam.cams[k].geometry());
                }
            } else {
                cam.stats.failed += 1;
            }
        }
    }

    /// Records cars whose firmware stopped, and stops their vehicles.
    fn note_failures(&mut self) {
        let count = self.engine.failures();
        if count.is_some() && count == self.failures_seen {
            return;
        }
        self.failures_seen = count;
        for k in 0..self.ids.len() {
            if self.failed[k] {
                continue;
            }
            let Some(f) = self.engine.failure(k) else {
                continue;
            };
            self.failed[k] = true;
            self.events.push(WorldEvent {
                at: Duration::from_nanos(f.at),
                car: self.ids[k],
                what: format!("car-failed: {}", f.kind),
            });
            if self.stop_failed {
                self.lbcs[k].emergency_stop();
                self.events.push(WorldEvent {
                    at: Duration::from_nanos(self.now + self.quantum),
                    car: self.ids[k],
                    what: "vehicle-stopped".into(),
                });
            }
        }
    }

    /// Carries bytes between a person's ground station on `ground.sock` and its radio node.
    fn serve_user(&mut self, now: Nanos) {
        let Some(u) = self.user.as_mut() else {
            return;
        };
        if u.conn.is_none() {
            if let Ok((s, _)) = u.listener.accept() {
                if s.set_nonblocking(true).is_ok() {
                    u.conn = Some(s);
                }
            }
        }
        let mut out = Vec::new();
        self.channels[0].medium.take_rx(u.node, now, &mut out);
        let Some(s) = u.conn.as_mut() else {
            return;
        };
        let mut lost = false;
        let mut got = 0u64;
        let mut buf = [0u8; 1024];
        loop {
            match s.read(&mut buf) {
                Ok(0) => {
                    lost = true;
                    break;
                }
                Ok(n) => {
                    self.channels[0].medium.write(u.node, now, &buf[..n]);
                    got += n as u64;
                    if let Some(tap) = self.tap.as_mut() {
                        tap.node(self.node_counters.len() - 1, &[], &buf[..n], now);
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
        if let Some(tap) = self.tap.as_mut() {
            tap.node(self.node_counters.len() - 1, &out, &[], now);
        }
        let bytes: Vec<u8> = out.iter().map(|&(_, b)| b).collect();
        if !bytes.is_empty() && s.write_all(&bytes).is_err() {
            lost = true;
        }
        if let Some(c) = self.node_counters.last_mut() {
            c.bytes_in += got;
            c.bytes_out += bytes.len() as u64;
        }
        if lost {
            u.conn = None;
        }
    }

    /// Sends a console request to car `id` without waiting: `Ok(None)` when the ground
    /// station is busy with another request (it carries one authenticated command at a time;
    /// try again later), else the [`PendingReply`] to poll with [`World::poll_reply`].
    pub fn try_request(
        &mut self,
        id: u8,
        req: &Request,
    ) -> Result<Option<PendingReply>, WorldError> {
        let k = self
            .ids
            .iter()
            .position(|&i| i == id)
            .ok_or(WorldError::BadCar { id })?;
        self.channels[self.channel_of[k]]
            .ground
            .try_request(self.now, id, req)
    }

    /// The outcome of a request once it is known (given once).
    pub fn poll_reply(&mut self, p: &PendingReply) -> Option<Result<Reply, WorldError>> {
        let k = self.ids.iter().position(|&i| i == p.car())?;
        self.channels[self.channel_of[k]].ground.poll(p)
    }

    /// Sends a console request to car `id` and runs the world until its reply, for at most
    /// `timeout` of world time.
    pub fn request(
        &mut self,
        id: u8,
        req: &Request,
        timeout: Duration,
    ) -> Result<Reply, WorldError> {
        let deadline = self.now() + timeout;
        let pending = loop {
            if let Some(p) = self.try_request(id, req)? {
                break p;
            }
            if self.now() >= deadline {
                return Err(WorldError::Timeout { id });
            }
            self.run_for(Duration::from_millis(5));
        };
        loop {
            if let Some(r) = self.poll_reply(&pending) {
                return r;
            }
            if self.now() >= deadline {
                return Err(WorldError::Timeout { id });
            }
            self.run_for(Duration::from_millis(1));
        }
    }

    /// Stops every car now (also done on drop).
    pub fn shutdown(mut self) {
        self.engine.shutdown();
    }
}

impl Drop for World {
    fn drop(&mut self) {
        self.engine.shutdown();
    }
}
