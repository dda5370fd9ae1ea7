//! The recording's channels: one Foxglove context per run, its MCAP file (`run.mcap`) and,
//! with a live view, its WebSocket server on the same context, so both carry the same
//! channels and messages. Every message is logged with its world time (nanoseconds since the
//! world started) as MCAP `log_time` and `publish_time`, and the same time in the message's
//! own `timestamp`.

use super::schemas;
use super::spill::Spill;
use crate::metrics::{ARENA_MM, BODY_OFFSET_MM};
use crate::plot::colour_of;
use foxglove::schemas::{
    log::Level, Color, CubePrimitive, FrameTransform, Log, Pose, PoseInFrame, Quaternion, RawImage,
    SceneEntity, SceneUpdate, TextPrimitive, Timestamp, Vector3,
};
use foxglove::{
    Channel, ChannelBuilder, Context, McapCompression, McapWriteOptions, McapWriter,
    McapWriterHandle, PartialMetadata, RawChannel, Schema, WebSocketServer, WebSocketServerHandle,
};
use std::net::SocketAddr;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// The frame every pose is given in: the arena's floor, origin at a corner, X across the
/// 1.5 m width, Y along the 2 m length, Z up, metres.
pub const ARENA_FRAME: &str = "arena";
/// Bytes of uncompressed messages in one MCAP chunk (a chunk is also closed at every flush).
const CHUNK_BYTES: u64 = 256 * 1024;

/// Why a recording could not start.
#[derive(Debug)]
pub enum RecordingError {
    /// `run.mcap` could not be created.
    File(String),
    /// The live view's WebSocket server could not start.
    Live { addr: SocketAddr, reason: String },
    /// A channel could not be created.
    Channel(String),
}

impl std::fmt::Display for RecordingError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RecordingError::File(e) => write!(f, "cannot write run.mcap: {e}"),
            RecordingError::Live { addr, reason } => {
                write!(f, "cannot serve the live view on {addr}: {reason}")
            }
            RecordingError::Channel(e) => write!(f, "cannot create a recording channel: {e}"),
        }
    }
}

impl std::error::Error for RecordingError {}

/// A world time as a Foxglove timestamp.
pub fn stamp(t_ns: u64) -> Timestamp {
    let sec = u32::try_from(t_ns / 1_000_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, (t_ns % 1_000_000_000) as u32)
}

fn vec3(x: f64, y: f64, z: f64) -> Vector3 {
    Vector3 { x, y, z }
}

/// A rotation of `yaw` radians about +Z.
fn yaw(yaw: f64) -> Quaternion {
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: (yaw / 2.0).sin(),
        w: (yaw / 2.0).cos(),
    }
}

/// A pose on the floor: position in mm, heading in radians.
pub fn floor_pose(x_mm: f64, y_mm: f64, heading_rad: f64) -> Pose {
    Pose {
        position: Some(vec3(x_mm / 1000.0, y_mm / 1000.0, 0.0)),
        orientation: Some(yaw(heading_rad)),
    }
}

fn color(rgb: (u8, u8, u8), a: f64) -> Color {
    Color {
        r: f64::from(rgb.0) / 255.0,
        g: f64::from(rgb.1) / 255.0,
        b: f64::from(rgb.2) / 255.0,
        a,
    }
}

fn cube(x: f64, y: f64, z: f64, size: Vector3, heading: f64, c: Color) -> CubePrimitive {
    CubePrimitive {
        pose: Some(Pose {
            position: Some(vec3(x, y, z)),
            orientation: Some(yaw(heading)),
        }),
        size: Some(size),
        color: Some(c),
    }
}

/// Every channel of a run.
pub struct Channels {
    _context: Arc<Context>,
    mcap: Mutex<Option<McapWriterHandle<Spill>>>,
    file: Spill,
    live: Mutex<Option<WebSocketServerHandle>>,
    ids: Vec<u8>,
    pose: Vec<Channel<PoseInFrame>>,
    estimate: Vec<Channel<PoseInFrame>>,
    tf: Channel<FrameTransform>,
    scene: Channel<SceneUpdate>,
    log: Vec<Channel<Log>>,
    camera: Vec<Channel<RawImage>>,
    lbc: Vec<Arc<RawChannel>>,
    radio: Vec<Arc<RawChannel>>,
    events: Channel<Log>,
}

impl std::fmt::Debug for Channels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Channels")
            .field("cars", &self.ids)
            .finish_non_exhaustive()
    }
}

fn json_channel(
    ctx: &Arc<Context>,
    topic: String,
    schema: (&'static str, &'static str),
) -> Result<Arc<RawChannel>, RecordingError> {
    ChannelBuilder::new(topic)
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(schema.0, "jsonschema", schema.1.as_bytes()))
        .build_raw()
        .map_err(|e| RecordingError::Channel(e.to_string()))
}

impl Channels {
    /// Creates `out/run.mcap` for cars `ids` and radio nodes `nodes` (ground, cars, user),
    /// and, with `live`, a WebSocket server on that address serving the same channels.
    pub fn create(
        out: &Path,
        ids: &[u8],
        nodes: &[String],
        live: Option<SocketAddr>,
    ) -> Result<Self, RecordingError> {
        let ctx = Context::new();
        let path = out.join("run.mcap");
        let file = Spill::create(&path).map_err(|e| RecordingError::File(e.to_string()))?;
        let options = McapWriteOptions::new()
            .compression(Some(McapCompression::Zstd))
            .chunk_size(Some(CHUNK_BYTES));
        let mcap = McapWriter::with_options(options)
            .context(&ctx)
            .create(file.clone())
            .map_err(|e| RecordingError::File(e.to_string()))?;
        let server = match live {
            Some(addr) => Some(
                WebSocketServer::new()
                    .name("almc experiment")
                    .context(&ctx)
                    .bind(addr.ip().to_string(), addr.port())
                    .start_blocking()
                    .map_err(|e| RecordingError::Live {
                        addr,
                        reason: e.to_string(),
                    })?,
            ),
            None => None,
        };
        let per_car = |what: &str| -> Vec<String> {
            ids.iter().map(|id| format!("/car{id}/{what}")).collect()
        };
        let typed = |topic: &String| ChannelBuilder::new(topic.as_str()).context(&ctx);
        Ok(Channels {
            pose: per_car("pose").iter().map(|t| typed(t).build()).collect(),
            estimate: per_car("estimate")
                .iter()
                .map(|t| typed(t).build())
                .collect(),
            tf: typed(&"/tf".to_owned()).build(),
            scene: typed(&"/arena".to_owned()).build(),
            log: per_car("log").iter().map(|t| typed(t).build()).collect(),
            camera: per_car("camera").iter().map(|t| typed(t).build()).collect(),
            lbc: per_car("lbc")
                .into_iter()
                .map(|t| json_channel(&ctx, t, schemas::LBC_MESSAGE))
                .collect::<Result<_, _>>()?,
            radio: nodes
                .iter()
                .map(|n| json_channel(&ctx, format!("/radio/{n}"), schemas::RADIO_FRAME))
                .collect::<Result<_, _>>()?,
            events: typed(&"/events".to_owned()).build(),
            ids: ids.to_vec(),
            mcap: Mutex::new(Some(mcap)),
            file,
            live: Mutex::new(server),
            _context: ctx,
        })
    }

    /// The port the live view listens on, if there is one.
    pub fn live_port(&self) -> Option<u16> {
        let live = self.live.lock().ok()?;
        live.as_ref().map(WebSocketServerHandle::port)
    }

    /// Car `k`'s true pose (from its vehicle model) at world time `t`: `/car<ID>/pose`,
    /// and the `arena` to `car<ID>` transform on `/tf`.
    pub fn truth(&self, t: u64, k: usize, x_mm: f64, y_mm: f64, heading_rad: f64) {
        let (Some(pose), Some(id)) = (self.pose.get(k), self.ids.get(k)) else {
            return;
        };
        pose.log_with_time(
            &PoseInFrame {
                timestamp: Some(stamp(t)),
                frame_id: ARENA_FRAME.into(),
                pose: Some(floor_pose(x_mm, y_mm, heading_rad)),
            },
            t,
        );
        let p = floor_pose(x_mm, y_mm, heading_rad);
        self.tf.log_with_time(
            &FrameTransform {
                timestamp: Some(stamp(t)),
                parent_frame_id: ARENA_FRAME.into(),
                child_frame_id: format!("car{id}"),
                translation: p.position,
                rotation: p.orientation,
            },
            t,
        );
    }

    /// What car `k` believes of itself, as its radio state broadcast heard by the ground
    /// station at world time `t` said: `/car<ID>/estimate`.
    pub fn estimate(&self, t: u64, k: usize, x_mm: f64, y_mm: f64, heading_rad: f64) {
        if let Some(c) = self.estimate.get(k) {
            c.log_with_time(
                &PoseInFrame {
                    timestamp: Some(stamp(t)),
                    frame_id: ARENA_FRAME.into(),
                    pose: Some(floor_pose(x_mm, y_mm, heading_rad)),
                },
                t,
            );
        }
    }

    /// The scene at world time `t` on `/arena`: every car as a box around its body centre
    /// (`(x_mm, y_mm, heading_rad)` of its rear axle) with its name, and, with `walls`, the
    /// floor and the walls.
    pub fn scene(&self, t: u64, cars: &[(f64, f64, f64)], walls: bool) {
        let mut entities = Vec::new();
        if walls {
            entities.push(arena_entity(t));
        }
        for (k, (&(x, y, h), id)) in cars.iter().zip(&self.ids).enumerate() {
            let (cx, cy) = (
                (x + BODY_OFFSET_MM * h.cos()) / 1000.0,
                (y + BODY_OFFSET_MM * h.sin()) / 1000.0,
            );
            let c = colour_of(k);
            entities.push(SceneEntity {
                timestamp: Some(stamp(t)),
                frame_id: ARENA_FRAME.into(),
                id: format!("car{id}"),
                cubes: vec![cube(cx, cy, 0.02, vec3(0.1, 0.05, 0.04), h, color(c, 1.0))],
                texts: vec![TextPrimitive {
                    pose: Some(Pose {
                        position: Some(vec3(cx, cy, 0.08)),
                        orientation: Some(yaw(0.0)),
                    }),
                    billboard: true,
                    font_size: 14.0,
                    scale_invariant: true,
                    color: Some(color(c, 1.0)),
                    text: format!("car {id}"),
                }],
                ..SceneEntity::default()
            });
        }
        self.scene.log_with_time(
            &SceneUpdate {
                deletions: Vec::new(),
                entities,
            },
            t,
        );
    }

    /// A line of car `k`'s firmware log: `/car<ID>/log`.
    pub fn firmware_log(&self, t: u64, k: usize, level: Option<qemu_harness::Level>, text: &str) {
        let (Some(c), Some(id)) = (self.log.get(k), self.ids.get(k)) else {
            return;
        };
        let level = match level {
            Some(qemu_harness::Level::Trace | qemu_harness::Level::Debug) => Level::Debug,
            Some(qemu_harness::Level::Info) | None => Level::Info,
            Some(qemu_harness::Level::Warn) => Level::Warning,
            Some(qemu_harness::Level::Error) => Level::Error,
        };
        c.log_with_time(
            &Log {
                timestamp: Some(stamp(t)),
                level: level as i32,
                message: text.into(),
                name: format!("car{id}"),
                file: String::new(),
                line: 0,
            },
            t,
        );
    }

    /// Car `k`'s camera frame (8-bit RGB) captured at `t`: `/car<ID>/camera`.
    pub fn camera(&self, t: u64, k: usize, width: u32, height: u32, rgb: Vec<u8>) {
        let (Some(c), Some(id)) = (self.camera.get(k), self.ids.get(k)) else {
            return;
        };
        c.log_with_time(
            &RawImage {
                timestamp: Some(stamp(t)),
                frame_id: format!("car{id}"),
                width,
                height,
                encoding: "rgb8".into(),
                step: width * 3,
                data: rgb.into(),
            },
            t,
        );
    }

    /// A decoded LBC message of car `k` (JSON): `/car<ID>/lbc`.
    pub fn lbc(&self, t: u64, k: usize, json: &[u8]) {
        if let Some(c) = self.lbc.get(k) {
            c.log_with_meta(json, PartialMetadata::with_log_time(t));
        }
    }

    /// A decoded radio frame of node `n` (JSON): `/radio/<node>`.
    pub fn radio(&self, t: u64, n: usize, json: &[u8]) {
        if let Some(c) = self.radio.get(n) {
            c.log_with_meta(json, PartialMetadata::with_log_time(t));
        }
    }

    /// An event of the run (the `events.jsonl` line): `/events`.
    pub fn event(&self, t: u64, line: &str, warning: bool) {
        self.events.log_with_time(
            &Log {
                timestamp: Some(stamp(t)),
                level: if warning { Level::Warning } else { Level::Info } as i32,
                message: line.into(),
                name: "experiment".into(),
                file: String::new(),
                line: 0,
            },
            t,
        );
    }

    /// Ends the current chunk and writes everything logged so far to the file, ended so that
    /// it is a complete MCAP file: a run killed from now on leaves a readable recording up to
    /// here ([`Spill`]).
    pub fn flush(&self) -> Result<(), String> {
        let g = self
            .mcap
            .lock()
            .map_err(|_| "recording lock poisoned".to_owned())?;
        if let Some(h) = g.as_ref() {
            h.flush().map_err(|e| e.to_string())?;
            self.file.commit(true).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Writes the file's summary and closes it, and stops the live view.
    pub fn close(&self) -> Result<(), String> {
        self.stop_live();
        let handle = self.mcap.lock().ok().and_then(|mut g| g.take());
        match handle {
            Some(h) => {
                let file = h.close().map_err(|e| e.to_string())?;
                file.commit(false).map_err(|e| e.to_string())
            }
            None => Ok(()),
        }
    }

    fn stop_live(&self) {
        let server = self.live.lock().ok().and_then(|mut g| g.take());
        if let Some(s) = server {
            s.stop().wait_blocking();
        }
    }
}

impl Drop for Channels {
    fn drop(&mut self) {
        // The MCAP handle closes its file when dropped; the server would run on.
        self.stop_live();
    }
}

/// The floor and the four walls of the 1.5 m x 2 m arena.
fn arena_entity(t: u64) -> SceneEntity {
    let (w, l) = (ARENA_MM.0 / 1000.0, ARENA_MM.1 / 1000.0);
    let (th, ht) = (0.02, 0.1);
    let wall = color((90, 90, 90), 1.0);
    SceneEntity {
        timestamp: Some(stamp(t)),
        frame_id: ARENA_FRAME.into(),
        id: "arena".into(),
        cubes: vec![
            cube(
                w / 2.0,
                l / 2.0,
                -0.001,
                vec3(w, l, 0.002),
                0.0,
                color((235, 235, 235), 1.0),
            ),
            cube(
                w / 2.0,
                -th / 2.0,
                ht / 2.0,
                vec3(w + 2.0 * th, th, ht),
                0.0,
                wall,
            ),
            cube(
                w / 2.0,
                l + th / 2.0,
                ht / 2.0,
                vec3(w + 2.0 * th, th, ht),
                0.0,
                wall,
            ),
            cube(-th / 2.0, l / 2.0, ht / 2.0, vec3(th, l, ht), 0.0, wall),
            cube(w + th / 2.0, l / 2.0, ht / 2.0, vec3(th, l, ht), 0.0, wall),
        ],
        ..SceneEntity::default()
    }
}
