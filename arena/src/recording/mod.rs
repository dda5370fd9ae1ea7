//! What a run records for people to look at: `run.mcap` as it goes (and the same channels
//! live over the Foxglove WebSocket protocol with [`RunOptions::live`]), and at the end the
//! plots (`<name>.svg`, `<name>.png`, [`crate::plot`]) and `report.html` ([`crate::report`]).
//!
//! Channels of `run.mcap` (Foxglove's well-known schemas are protobuf-encoded as Foxglove
//! defines them; the others are JSON with a JSON schema):
//!
//! | topic | schema | what |
//! |---|---|---|
//! | `/car<ID>/pose` | `foxglove.PoseInFrame` | the car's true pose (vehicle model), every 100 ms |
//! | `/car<ID>/estimate` | `foxglove.PoseInFrame` | the car's own estimate: each radio state broadcast the ground station heard |
//! | `/tf` | `foxglove.FrameTransform` | `arena` to `car<ID>` (true pose), every 100 ms |
//! | `/arena` | `foxglove.SceneUpdate` | the cars as boxes every 100 ms; the floor and walls every second |
//! | `/radio/<node>` | `almc.RadioFrame` (JSON) | every radio frame each node's host wrote or received, decoded |
//! | `/car<ID>/lbc` | `almc.LbcMessage` (JSON) | every message between the car and its LBC, decoded |
//! | `/car<ID>/log` | `foxglove.Log` | the firmware's log lines |
//! | `/car<ID>/camera` | `foxglove.RawImage` | the car's camera, at most 2 frames a second (with `camera_fps`) |
//! | `/events` | `foxglove.Log` | the lines of `events.jsonl` |
//!
//! Every time is world time (nanoseconds since the world started), so on the virtual-time
//! engine the file is a function of the experiment and its seed.

mod channels;
mod decode;
mod schemas;
mod spill;

pub use channels::{Channels, RecordingError, ARENA_FRAME};

use crate::engine::Nanos;
use crate::experiment::{Experiment, PhaseKind};
use crate::metrics::Sample;
use crate::plot::{self, PhaseSpan, RunPlots};
use crate::world::{TapConfig, World, MM_PER_UNIT};
use decode::{state_of, ConsoleStream, LbcStream, RadioStream};
use lbc_link::StreamFormat;
use qemu_harness::LogFormat;
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Arc;

/// Camera frames in the recording: at most one per car this often.
pub const CAMERA_EVERY_NS: Nanos = 500_000_000;
/// The floor and walls are sent again this often, so a live view that joins late has them.
const WALLS_EVERY_NS: Nanos = 1_000_000_000;

/// How a run is played besides its experiment file.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RunOptions {
    /// Serve the run's channels over the Foxglove WebSocket protocol on this address while
    /// it runs (a loopback address), pacing world time to the wall clock.
    pub live: Option<SocketAddr>,
}

/// The log formats of a world's cars, for [`Recording::start`] (kept by the caller, which
/// the console decoders borrow).
pub fn log_formats(world: &World) -> Vec<Option<Arc<LogFormat>>> {
    (0..world.ids().len())
        .map(|k| world.log_format(k))
        .collect()
}

/// A run's recording.
pub struct Recording<'f> {
    channels: Arc<Channels>,
    ids: Vec<u8>,
    nodes: Vec<String>,
    radio: Vec<[RadioStream; 2]>,
    lbc: Vec<[LbcStream; 2]>,
    formats: Vec<Option<StreamFormat>>,
    console: Vec<Option<ConsoleStream<'f>>>,
    /// Lines of the engine's own firmware log already recorded, per car (engines whose
    /// console bytes the tap does not see: QEMU), and when to look again.
    lines_seen: Vec<usize>,
    next_lines: Nanos,
    next_walls: Nanos,
    plots: RunPlots,
}

impl std::fmt::Debug for Recording<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recording")
            .field("cars", &self.ids)
            .finish_non_exhaustive()
    }
}

/// A point in tracking units, in mm.
fn units_mm(p: [u16; 2]) -> (f64, f64) {
    (f64::from(p[0]) * MM_PER_UNIT, f64::from(p[1]) * MM_PER_UNIT)
}

impl<'f> Recording<'f> {
    /// Starts recording `world` into `out/run.mcap` (turning its tap on), with a live view
    /// when `opts` asks for one. `formats` are the cars' log formats ([`log_formats`]).
    pub fn start(
        world: &mut World,
        formats: &'f [Option<Arc<LogFormat>>],
        out: &Path,
        exp: &Experiment,
        opts: &RunOptions,
    ) -> Result<Self, RecordingError> {
        let ids = world.ids().to_vec();
        let nodes: Vec<String> = world
            .node_counters()
            .iter()
            .map(|n| n.name.clone())
            .collect();
        let channels = Arc::new(Channels::create(out, &ids, &nodes, opts.live)?);
        world.start_tap(TapConfig {
            camera_every: exp.camera_fps.map(|_| CAMERA_EVERY_NS),
        });
        let n = ids.len();
        let targets = ids
            .iter()
            .map(|&id| {
                let mut pts = Vec::new();
                for p in &exp.phases {
                    pts.extend(p.goto_points(id).into_iter().map(units_mm));
                    if let Some(plan) = p.waypoint_plan() {
                        if plan.cars.first() == Some(&id) {
                            pts.extend(plan.waypoints.iter().copied().map(units_mm));
                        }
                    }
                }
                pts
            })
            .collect();
        let circles = exp
            .phases
            .iter()
            .filter_map(|p| match &p.kind {
                PhaseKind::Circle {
                    centre,
                    radius_units,
                    ..
                } => Some((units_mm(*centre), f64::from(*radius_units) * MM_PER_UNIT)),
                _ => None,
            })
            .collect();
        Ok(Recording {
            channels,
            radio: (0..nodes.len()).map(|_| Default::default()).collect(),
            lbc: (0..n).map(|_| Default::default()).collect(),
            formats: vec![None; n],
            console: formats
                .iter()
                .map(|f| f.as_deref().map(ConsoleStream::new))
                .collect(),
            nodes,
            lines_seen: vec![0; n],
            next_lines: 0,
            next_walls: 0,
            plots: RunPlots {
                title: exp.name.clone(),
                ids: ids.clone(),
                tracks: vec![Vec::new(); n],
                targets,
                circles,
                states_heard: vec![Vec::new(); n],
                ..RunPlots::default()
            },
            ids,
        })
    }

    /// The channels (shared with the event log).
    pub fn channels(&self) -> Arc<Channels> {
        self.channels.clone()
    }

    /// Decodes and records what the world's tap collected since the last call.
    pub fn drain(&mut self, world: &mut World) {
        let tap = world.take_tap();
        let ch = &self.channels;
        for (n, traffic) in tap.radio.iter().enumerate() {
            let (Some(streams), Some(node)) = (self.radio.get_mut(n), self.nodes.get(n)) else {
                continue;
            };
            for (dir, bytes, s) in [
                ("sent", &traffic.wrote, 0),
                ("received", &traffic.received, 1),
            ] {
                for &(t, b) in bytes {
                    let Some((json, frame)) = streams[s].push(t, b, node, dir) else {
                        continue;
                    };
                    ch.radio(t, n, json.to_string().as_bytes());
                    // What the ground station heard of a car's own estimate.
                    if let (0, 1, Some((id, st))) = (n, s, frame.as_ref().and_then(state_of)) {
                        if let Some(k) = self.ids.iter().position(|&i| i == id) {
                            let (x, y) = units_mm([st.x, st.y]);
                            ch.estimate(t, k, x, y, f64::from(st.heading_mrad) / 1000.0);
                        }
                    }
                }
            }
        }
        for (k, traffic) in tap.lbc.iter().enumerate() {
            let (Some(streams), Some(format)) = (self.lbc.get_mut(k), self.formats.get_mut(k))
            else {
                continue;
            };
            for (to_lbc, bytes, s) in [(true, &traffic.to_lbc, 0), (false, &traffic.from_lbc, 1)] {
                for &(t, b) in bytes {
                    if let Some(json) = streams[s].push(t, b, to_lbc, format) {
                        ch.lbc(t, k, json.to_string().as_bytes());
                    }
                }
            }
        }
        for (k, bytes) in tap.console.iter().enumerate() {
            if let Some(Some(c)) = self.console.get_mut(k) {
                c.push(bytes, &mut |t, line| {
                    let text = match &line.timestamp {
                        Some(fw) => format!("[{fw}] {}", line.message),
                        None => line.message.clone(),
                    };
                    ch.firmware_log(t, k, line.level, &text);
                });
            }
        }
        for f in tap.frames {
            ch.camera(f.at, f.car, f.width, f.height, f.rgb);
        }
        self.engine_log_lines(world);
    }

    /// Cars whose console bytes the tap does not see (QEMU): the new lines of the engine's
    /// own decoded log, once a second, stamped with the world time they were found.
    fn engine_log_lines(&mut self, world: &World) {
        let now = u64::try_from(world.now().as_nanos()).unwrap_or(u64::MAX);
        if now < self.next_lines || self.console.iter().all(Option::is_some) {
            return;
        }
        self.next_lines = now + WALLS_EVERY_NS;
        for (k, &id) in self.ids.iter().enumerate() {
            if self.console.get(k).is_some_and(Option::is_some) {
                continue;
            }
            let lines = world.firmware_log(id).unwrap_or_default();
            let seen = &mut self.lines_seen[k];
            for line in lines.iter().skip(*seen) {
                self.channels.firmware_log(now, k, None, line);
            }
            *seen = (*seen).max(lines.len());
        }
    }

    /// One sample of every car's true pose (`sample`, configuration order) at the world's
    /// current time: poses, transforms and the scene, and the plots' data.
    pub fn sample(&mut self, world: &World, sample: &[Sample]) {
        let t = u64::try_from(world.now().as_nanos()).unwrap_or(u64::MAX);
        let mut cars = Vec::with_capacity(sample.len());
        for (k, s) in sample.iter().enumerate() {
            let h = s.heading_mrad / 1000.0;
            self.channels.truth(t, k, s.x_mm, s.y_mm, h);
            cars.push((s.x_mm, s.y_mm, h));
            if let Some(track) = self.plots.tracks.get_mut(k) {
                track.push(*s);
            }
        }
        let walls = t >= self.next_walls;
        if walls {
            self.next_walls = t + WALLS_EVERY_NS;
        }
        self.channels.scene(t, &cars, walls);
        let st = sample.first().map_or(0.0, |s| s.t);
        for (k, truth) in world.truth().iter().enumerate() {
            if let Some(c) = self.plots.states_heard.get_mut(k) {
                c.push((st, truth.states_heard));
            }
        }
    }

    /// The phase error at `t` (s since the first phase started).
    pub fn phase_error(&mut self, t: f64, phase: usize, error_mm: f64) {
        self.plots.phase_errors.push((t, phase, error_mm));
    }

    /// Ends the recording: records what is left in the tap, closes `run.mcap`, and writes
    /// the plots and `report.html` for `summary` into `out`.
    pub fn finish(
        mut self,
        world: &mut World,
        summary: &crate::runner::Summary,
        out: &Path,
    ) -> Result<(), String> {
        self.drain(world);
        self.channels.close()?;
        self.plots.phases = summary
            .phases
            .iter()
            .map(|p| PhaseSpan {
                phase: p.phase,
                kind: p.kind.to_owned(),
                start_s: p.start_s,
                end_s: p.end_s,
                tolerance_mm: p.tolerance_mm,
            })
            .collect();
        let figures = plot::render_all(&self.plots).map_err(|e| e.to_string())?;
        let write = |name: String, bytes: &[u8]| {
            std::fs::write(out.join(&name), bytes).map_err(|e| format!("{name}: {e}"))
        };
        for f in &figures {
            write(format!("{}.svg", f.name), f.svg.as_bytes())?;
            write(format!("{}.png", f.name), &f.png)?;
        }
        let doc = serde_json::to_value(summary).map_err(|e| e.to_string())?;
        write(
            "report.html".into(),
            crate::report::html(&doc, &figures).as_bytes(),
        )
    }
}
