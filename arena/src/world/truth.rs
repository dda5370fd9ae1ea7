//! What the world reports: each car's truth, the ground station's counters, radio node
//! counters, and the events it records.

use crate::engine::Failure;
use lbc_emu::{LbcStats, Pose};
use radio_mac::CarState;
use std::time::Duration;

/// What the world knows of one car right now (the truth, not what the car believes).
#[derive(Debug, Clone, PartialEq)]
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
    /// The car's firmware runs.
    pub connected: bool,
    /// Tracking fixes delivered to the LBC.
    pub fixes_delivered: u64,
    /// Tracking fixes dropped by the tracker.
    pub fixes_dropped: u64,
    /// Latest radio state the ground station heard from the car.
    pub radio_state: Option<CarState>,
    /// Radio state broadcasts the ground station heard from the car.
    pub states_heard: u64,
    /// The firmware stopped: when and why.
    pub failure: Option<Failure>,
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

impl std::ops::AddAssign for GroundCounters {
    /// Counts of two ground stations together (one per radio channel).
    fn add_assign(&mut self, other: Self) {
        let GroundCounters {
            requests,
            replies,
            failed,
            states_heard,
            notices,
        } = other;
        self.requests += requests;
        self.replies += replies;
        self.failed += failed;
        self.states_heard += states_heard;
        self.notices += notices;
    }
}

/// Bytes through one node's radio UART.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeCounters {
    /// Node name (`ground`, `car<ID>`, `ground<N>` for radio channel N after the first,
    /// `user`).
    pub name: String,
    /// Bytes the node's host wrote to its radio.
    pub bytes_in: u64,
    /// Bytes the radio delivered to the node's host.
    pub bytes_out: u64,
}

/// Something the world records as it runs (for event logs).
#[derive(Debug, Clone, PartialEq)]
pub struct WorldEvent {
    /// World time.
    pub at: Duration,
    /// The car concerned.
    pub car: u8,
    /// What happened.
    pub what: String,
}
