//! The world's tap: what crossed the world's boundaries, quantum by quantum, with the world
//! time of every byte, for recordings (`run.mcap`) and live views. Off unless
//! [`crate::world::World::start_tap`] turned it on; [`crate::world::World::take_tap`] hands
//! over what was collected since the last take.

use super::World;
use crate::engine::{CarEngine, CarIo, Nanos};
use qemu_harness::LogFormat;
use std::sync::Arc;
use vision::FrameGeometry;

/// Bytes through one radio node's UART, as its host saw them.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeTraffic {
    /// Bytes the node's host wrote to its radio, with the world time each left the host.
    pub wrote: Vec<(Nanos, u8)>,
    /// Bytes the radio delivered to the node's host, with the world time each is due.
    pub received: Vec<(Nanos, u8)>,
}

/// Bytes between one car and its LBC.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LbcTraffic {
    /// Bytes the car sent to its LBC, with the world time each left the car.
    pub to_lbc: Vec<(Nanos, u8)>,
    /// Bytes the LBC sent to the car, with the world time each reaches the car.
    pub from_lbc: Vec<(Nanos, u8)>,
}

/// One camera frame of one car, as 8-bit RGB.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TapFrame {
    /// The car's index (configuration order).
    pub car: usize,
    /// World time of the capture.
    pub at: Nanos,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Row-major RGB, 3 bytes a pixel.
    pub rgb: Vec<u8>,
}

/// What the tap collected since the last take.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tap {
    /// Radio bytes per node, in the order of [`crate::world::World::node_counters`] (ground
    /// station, then the cars, then `user` in a real-time world).
    pub radio: Vec<NodeTraffic>,
    /// LBC bytes per car (configuration order).
    pub lbc: Vec<LbcTraffic>,
    /// Console bytes (the firmware's log stream) per car, with the world time each was
    /// written (engines that see them: iss).
    pub console: Vec<Vec<(Nanos, u8)>>,
    /// Camera frames, at most one per car per [`TapConfig::camera_every`].
    pub frames: Vec<TapFrame>,
}

impl Tap {
    /// An empty tap for `nodes` radio nodes and `cars` cars.
    pub(super) fn new(nodes: usize, cars: usize) -> Self {
        Tap {
            radio: vec![NodeTraffic::default(); nodes],
            lbc: vec![LbcTraffic::default(); cars],
            console: vec![Vec::new(); cars],
            frames: Vec::new(),
        }
    }

    /// Whether nothing was collected.
    pub fn is_empty(&self) -> bool {
        self.radio
            .iter()
            .all(|n| n.wrote.is_empty() && n.received.is_empty())
            && self
                .lbc
                .iter()
                .all(|l| l.to_lbc.is_empty() && l.from_lbc.is_empty())
            && self.console.iter().all(Vec::is_empty)
            && self.frames.is_empty()
    }
}

/// What the tap collects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TapConfig {
    /// Camera frames: at most one per car this often (world time, ns); `None`: none.
    pub camera_every: Option<Nanos>,
}

/// The tap inside the world: what is being collected and when each car's next frame is due.
#[derive(Debug)]
pub(super) struct TapState {
    pub(super) config: TapConfig,
    pub(super) data: Tap,
    pub(super) next_frame: Vec<Nanos>,
    pub(super) nodes: usize,
}

impl TapState {
    pub(super) fn new(config: TapConfig, nodes: usize, cars: usize) -> Self {
        TapState {
            config,
            data: Tap::new(nodes, cars),
            next_frame: vec![0; cars],
            nodes,
        }
    }

    /// Hands over what was collected.
    pub(super) fn take(&mut self) -> Tap {
        let cars = self.data.lbc.len();
        std::mem::replace(&mut self.data, Tap::new(self.nodes, cars))
    }

    /// What car `k` sent in the quantum (radio and LBC), and its console bytes.
    pub(super) fn car_out(&mut self, k: usize, io: &CarIo, engine: &mut dyn CarEngine) {
        if let Some(node) = self.data.radio.get_mut(k + 1) {
            node.wrote.extend_from_slice(&io.radio_out);
        }
        if let (Some(lbc), Some(console)) = (self.data.lbc.get_mut(k), self.data.console.get_mut(k))
        {
            lbc.to_lbc.extend_from_slice(&io.lbc_out);
            engine.take_console(k, console);
        }
    }

    /// Bytes the LBC queued for car `k`.
    pub(super) fn lbc_out(&mut self, k: usize, bytes: &[(Nanos, u8)]) {
        if let Some(lbc) = self.data.lbc.get_mut(k) {
            lbc.from_lbc.extend_from_slice(bytes);
        }
    }

    /// Bytes radio node `node` delivered to its host, and bytes its host wrote at `at`.
    pub(super) fn node(&mut self, node: usize, received: &[(Nanos, u8)], wrote: &[u8], at: Nanos) {
        if let Some(n) = self.data.radio.get_mut(node) {
            n.received.extend_from_slice(received);
            n.wrote.extend(wrote.iter().map(|&b| (at, b)));
        }
    }

    /// Car `k`'s camera frame captured at `at`, kept at most once per
    /// [`TapConfig::camera_every`].
    pub(super) fn frame(&mut self, k: usize, at: Nanos, frame: &[u8], g: &FrameGeometry) {
        let Some(every) = self.config.camera_every else {
            return;
        };
        let Some(next) = self.next_frame.get_mut(k).filter(|n| at >= **n) else {
            return;
        };
        *next = at.saturating_add(every.max(1));
        if let Ok(rgb) = crate::camera::to_rgb8(frame, g) {
            self.data.frames.push(TapFrame {
                car: k,
                at,
                width: u32::from(g.width),
                height: u32::from(g.height),
                rgb,
            });
        }
    }
}

impl World {
    /// Turns the tap on ([`Tap`]): radio and LBC bytes, console bytes and camera frames are
    /// collected until [`World::take_tap`] hands them over.
    pub fn start_tap(&mut self, config: TapConfig) {
        self.engine.tap_console(true);
        self.tap = Some(TapState::new(
            config,
            self.node_counters.len(),
            self.ids.len(),
        ));
    }

    /// What the tap collected since the last call (empty while it is off).
    pub fn take_tap(&mut self) -> Tap {
        self.tap.as_mut().map(TapState::take).unwrap_or_default()
    }

    /// How car `k`'s console bytes become log lines (engines whose console bytes the tap
    /// sees: iss).
    pub fn log_format(&self, k: usize) -> Option<Arc<LogFormat>> {
        self.engine.log_format(k)
    }
}
