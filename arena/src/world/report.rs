//! What a running world reports: each car's truth, processor load and profile, the camera's,
//! ground stations' and radio channels' counters, events and firmware logs.

use super::{CarTruth, GroundCounters, NodeCounters, World, WorldEvent};
use crate::camera_feed::FeedStats;
use crate::engine::CoreLoad;
use crate::radio_medium::MediumStats;

impl World {
    /// The truth about every car, in configuration order.
    pub fn truth(&self) -> Vec<CarTruth> {
        self.lbcs
            .iter()
            .enumerate()
            .map(|(k, l)| CarTruth {
                id: self.ids[k],
                pose: l.vehicle().pose(),
                v_mm_s: l.vehicle().speed_mm_s(),
                lbc: l.stats(),
                lbc_faults: l.fault_stats(),
                connected: !self.failed[k],
                fixes_delivered: self.tracker.delivered[k],
                fixes_dropped: self.tracker.dropped[k],
                radio_state: self.channels[self.channel_of[k]].ground.states[k].0,
                states_heard: self.channels[self.channel_of[k]].ground.states[k].1,
                failure: self.engine.failure(k),
            })
            .collect()
    }

    /// Car `k`'s processor load (virtual-time engine).
    pub fn core_load(&self, k: usize) -> Option<CoreLoad> {
        self.engine.core_load(k)
    }

    /// Where car `id`'s processor spent its cycles so far, by function, largest first:
    /// `(cycles, share, function)` (cars in [`WorldConfig::profile_cars`] on the virtual-time
    /// engine).
    pub fn profile(&self, id: u8) -> Option<Vec<(u64, f64, String)>> {
        let k = self.ids.iter().position(|&i| i == id)?;
        self.engine.profile(k)
    }

    /// Ends car `id`'s firmware now, as a crash would (the world then stops its vehicle,
    /// unless told not to, and reports it). For tests and fault experiments.
    pub fn kill_car(&mut self, id: u8, why: &str) {
        if let Some(k) = self.ids.iter().position(|&i| i == id) {
            self.engine.kill(k, why);
        }
    }

    /// The camera's counters, if the world has a camera.
    pub fn camera_stats(&self) -> Option<FeedStats> {
        self.camera.as_ref().map(|c| c.stats)
    }

    /// Ground-station counters (every channel's ground station together).
    pub fn ground_counters(&self) -> GroundCounters {
        let mut c = GroundCounters::default();
        for ch in &self.channels {
            c += ch.ground.counters;
        }
        c
    }

    /// Ground-station protocol counters (every channel's together).
    pub fn ground_stats(&self) -> radio_mac::Stats {
        let mut s = radio_mac::Stats::default();
        for ch in &self.channels {
            s += ch.ground.stats();
        }
        s
    }

    /// Radio medium counters (every channel's together).
    pub fn medium_stats(&self) -> MediumStats {
        let mut s = MediumStats::default();
        for ch in &self.channels {
            s += *ch.medium.stats();
        }
        s
    }

    /// The radio channels in use, lowest first.
    pub fn radio_channels(&self) -> Vec<u8> {
        self.channels.iter().map(|c| c.number).collect()
    }

    /// Bytes through every radio node (the first channel's ground station, the cars, the other
    /// channels' ground stations, then `user`).
    pub fn node_counters(&self) -> &[NodeCounters] {
        &self.node_counters
    }

    /// Events recorded since the last call (LBC resets, notices, failures).
    pub fn take_events(&mut self) -> Vec<WorldEvent> {
        std::mem::take(&mut self.events)
    }

    /// The firmware log of car `id` (decoded defmt lines), if it is in the world.
    pub fn firmware_log(&self, id: u8) -> Option<Vec<String>> {
        let k = self.ids.iter().position(|&i| i == id)?;
        Some(self.engine.firmware_log(k))
    }
}
