//! Application-layer protocol over the ALMC's CSMA serial radio (seed 1.5.2).
//!
//! The radio module is a transparent 115200 bps byte pipe with its own CSMA; this crate adds
//! what the seed leaves to the user: COBS framing with CRC-16 and a version field, addresses
//! (car IDs, ground station, broadcast), a 16-byte periodic state broadcast sent in TDMA-like
//! slots, acknowledged requests with retries and exactly-once delivery, typed maneuver
//! messages, heartbeats, a neighbour table, and ground-station commands authenticated with
//! SipHash-2-4.
//!
//! Everything is sans-IO: feed UART bytes with `push_rx(now, bytes)`, call `poll(now)`,
//! drain `transmit(&mut buf)` into the UART and `next_event()` into the application. Time is
//! a `u64` in microseconds on any monotonic local clock. No heap, no `unsafe`.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod addr;
pub mod auth;
pub mod deframer;
pub mod endpoint;
pub mod neighbours;
pub mod schedule;
pub mod wire;

#[cfg(test)]
mod tests;

pub use addr::{Address, CarId};
pub use auth::{Key, ReplayGuard, Session};
pub use deframer::Deframer;
pub use endpoint::{
    Endpoint, Event, Incoming, IncomingId, ReplyError, RequestHandle, RetryConfig, SendError, Stats,
};
pub use neighbours::{Neighbour, NeighbourTable, NEIGHBOURS};
pub use schedule::{StateTiming, TimeBase};
pub use wire::{
    CarState, Frame, FrameError, GroupMsg, Heartbeat, Mode, Payload, Role, MAX_PAYLOAD,
};

use endpoint::{HEARTBEAT_US, STALE_AFTER_US};
use schedule::Schedule;

/// `a - b`, or 0 when `b` is later: the age of a timestamp (microseconds since `b` at `a`).
/// The UBC program's elapsed times use it too.
// Out of line: 64-bit saturating subtraction inlined at each of its dozen uses cost more
// image than the calls.
#[inline(never)]
#[must_use]
pub fn sat_sub(a: u64, b: u64) -> u64 {
    a.saturating_sub(b)
}

/// Neighbour-table capacity of the ground station.
pub const GROUND_CARS: usize = 32;

/// Configuration of a car.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct CarConfig {
    /// The car's ID (READ_ID).
    pub id: CarId,
    /// Testbed key for ground-station commands; without it every command is rejected.
    pub key: Option<Key>,
    /// A floor under every session's command counters, restored from persistent storage if
    /// the application keeps one (sessions alone already reject anything recorded before a
    /// restart).
    pub replay: ReplayGuard,
    /// A counter that grows at every start of the car and is persisted (the firmware keeps it
    /// in an EEPROM register). Hello nonces are `boot << 32 | n`, so no nonce, and no session
    /// opening recorded on air, is ever valid again after a restart.
    pub boot: u32,
    /// When the state is broadcast.
    pub timing: StateTiming,
    /// Heartbeat period (heartbeats are skipped while the state is being broadcast).
    pub heartbeat_us: u32,
    /// A neighbour silent this long is stale.
    pub stale_after_us: u32,
    /// Retransmission parameters.
    pub retry: RetryConfig,
    /// Seed of the jitter generator and of the first sequence number (e.g. a boot counter).
    pub seed: u32,
}

impl CarConfig {
    /// Defaults for car `id`: slotted state broadcast following the lowest ID heard.
    pub fn new(id: CarId) -> Self {
        Self {
            id,
            key: None,
            replay: ReplayGuard::new(),
            boot: 0,
            timing: StateTiming::slotted(id),
            heartbeat_us: HEARTBEAT_US,
            stale_after_us: STALE_AFTER_US,
            retry: RetryConfig::default(),
            seed: 0,
        }
    }
}

/// The car role.
#[derive(Debug)]
pub struct CarMac {
    ep: Endpoint<NEIGHBOURS>,
    id: CarId,
}

impl CarMac {
    /// A car endpoint.
    pub fn new(config: CarConfig) -> Self {
        let schedule = Schedule::new(config.id, config.timing);
        let mut ep = Endpoint::new(
            Address::Car(config.id),
            config.retry,
            config.stale_after_us,
            config.heartbeat_us,
            config.seed,
            config.key,
            config.replay,
            Some(schedule),
        );
        ep.set_boot(config.boot);
        Self { id: config.id, ep }
    }

    /// The car's ID.
    pub fn id(&self) -> CarId {
        self.id
    }

    /// Set the state to broadcast from now on (pose from tracking, velocity from the LBC).
    pub fn set_state(&mut self, state: CarState) {
        self.ep.mode = state.mode;
        self.ep.state = Some(state);
    }

    /// Role and phase advertised in heartbeats while no state is broadcast.
    pub fn set_mode(&mut self, mode: Mode) {
        self.ep.mode = mode;
    }

    /// Stop broadcasting the state (heartbeats resume).
    pub fn clear_state(&mut self) {
        self.ep.state = None;
    }

    /// A shared time tick (overhead tracking frame) arrived, for [`TimeBase::External`].
    pub fn sync_tick(&mut self, now: u64) {
        if let Some(s) = self.ep.schedule.as_mut() {
            s.external_tick(now);
        }
    }

    /// Slot schedule state.
    pub fn schedule(&self) -> Option<&Schedule> {
        self.ep.schedule.as_ref()
    }

    /// Feed radio UART bytes read at `now`.
    pub fn push_rx(&mut self, now: u64, bytes: &[u8]) {
        self.ep.push_rx(now, bytes)
    }
    /// The state broadcast queued last started on the radio UART at `at`: see
    /// [`Endpoint::state_written`].
    pub fn state_written(&mut self, at: u64) {
        self.ep.state_written(at);
    }

    /// The learned send lead of the state broadcast, microseconds.
    pub fn send_lead_us(&self) -> u64 {
        self.ep.send_lead_us()
    }

    /// Advance timers to `now`.
    pub fn poll(&mut self, now: u64) {
        self.ep.poll(now)
    }

    /// Earliest time at which `poll` has work.
    pub fn poll_at(&mut self, now: u64) -> u64 {
        self.ep.poll_at(now)
    }

    /// When the next state broadcast is due to be written to the radio (see
    /// [`CarMac::state_written`]): a program busy when it comes (handling a batch of input)
    /// can look at its clock as it goes and poll then, so the broadcast keeps its slot.
    pub fn next_state_due(&mut self, now: u64) -> Option<u64> {
        self.ep.next_state_due(now)
    }

    /// Bytes for the radio UART.
    pub fn transmit(&mut self, buf: &mut [u8]) -> usize {
        self.ep.transmit(buf)
    }

    /// Next event.
    pub fn next_event(&mut self) -> Option<Event> {
        self.ep.next_event()
    }

    /// Send an acknowledged request to a car or the ground station.
    pub fn request(
        &mut self,
        now: u64,
        dst: Address,
        tag: u8,
        payload: &[u8],
    ) -> Result<RequestHandle, SendError> {
        self.ep.request(now, dst, tag, payload)
    }

    /// Answer a request or command delivered as [`Event::Request`].
    pub fn reply(&mut self, id: IncomingId, tag: u8, payload: &[u8]) -> Result<(), ReplyError> {
        self.ep.reply(id, tag, payload)
    }

    /// Send a maneuver message.
    pub fn send_group(
        &mut self,
        now: u64,
        dst: Address,
        group: u8,
        msg: GroupMsg,
    ) -> Result<RequestHandle, SendError> {
        self.ep.send_group(now, dst, group, msg)
    }

    /// Counters.
    pub fn stats(&self) -> &Stats {
        self.ep.stats()
    }

    /// Nodes heard.
    pub fn neighbours(&self) -> &NeighbourTable<NEIGHBOURS> {
        self.ep.neighbours()
    }

    /// Staleness limit of neighbours.
    pub fn stale_after_us(&self) -> u64 {
        self.ep.stale_after_us()
    }

    /// Command counters accepted in the current session.
    pub fn replay_guard(&self) -> ReplayGuard {
        self.ep.replay_guard()
    }

    /// The session with the ground station, once one is open.
    pub fn session(&self) -> Option<Session> {
        self.ep.session()
    }

    /// The underlying engine.
    pub fn endpoint(&mut self) -> &mut Endpoint<NEIGHBOURS> {
        &mut self.ep
    }
}

/// Configuration of the ground station.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub struct GroundConfig {
    /// Testbed key.
    pub key: Key,
    /// Counter of the first command. Within one epoch counters only grow; across runs the
    /// epoch separates them (persisting [`GroundStation::next_counter`] as well keeps them
    /// growing across runs too).
    pub first_counter: u32,
    /// Session epoch: part of every command's MAC and sent in every heartbeat. Use a value
    /// never used before with this key (e.g. random, per run); [`GroundConfig::new`] takes
    /// `first_counter`. When a counter reaches `u32::MAX` the station moves to the next epoch.
    pub epoch: u32,
    /// Heartbeat period.
    pub heartbeat_us: u32,
    /// A car silent this long is stale.
    pub stale_after_us: u32,
    /// Retransmission parameters.
    pub retry: RetryConfig,
    /// Jitter seed.
    pub seed: u32,
    /// Pipeline latency of a state frame, to learn the cars' slot phase (heartbeats go in a
    /// free slot).
    pub state_latency_us: u32,
}

impl GroundConfig {
    /// Defaults with `key`, starting at counter `first_counter`.
    pub fn new(key: Key, first_counter: u32) -> Self {
        Self {
            key,
            first_counter,
            epoch: first_counter,
            heartbeat_us: HEARTBEAT_US,
            stale_after_us: STALE_AFTER_US,
            retry: RetryConfig::default(),
            seed: 0,
            state_latency_us: schedule::DEFAULT_STATE_LATENCY_US,
        }
    }
}

/// The ground-station role: authenticated commands to one car or all, cars heard, replies.
#[derive(Debug)]
pub struct GroundStation {
    ep: Endpoint<GROUND_CARS>,
    exhausted: bool,
}

impl GroundStation {
    /// A ground-station endpoint.
    pub fn new(config: GroundConfig) -> Self {
        let mut ep = Endpoint::new(
            Address::Ground,
            config.retry,
            config.stale_after_us,
            config.heartbeat_us,
            config.seed,
            Some(config.key),
            ReplayGuard::new(),
            Some(Schedule::listener(config.state_latency_us)),
        );
        ep.set_ground_session(config.epoch, config.first_counter);
        Self {
            ep,
            exhausted: false,
        }
    }

    /// Counter the next command will use (1 in the next epoch once `u32::MAX` was used).
    pub fn next_counter(&self) -> u32 {
        if self.exhausted {
            1
        } else {
            self.ep.next_command
        }
    }

    /// The current session epoch.
    pub fn epoch(&self) -> u32 {
        self.ep.epoch
    }

    /// Send an authenticated command to one car (acknowledged by its [`Event::Reply`]) or to
    /// [`Address::Broadcast`] (repeated, unanswered). One command is outstanding at a time, so
    /// that every car sees counters in increasing order.
    pub fn command(
        &mut self,
        now: u64,
        dst: Address,
        tag: u8,
        payload: &[u8],
    ) -> Result<RequestHandle, SendError> {
        if self.exhausted {
            // The last counter of the epoch went out: this command starts the next epoch
            // (cars join it with a Hello) instead of using a counter every car would take for
            // a replay. Only once nothing of the old epoch is outstanding.
            if self.ep.auth_outstanding() {
                return Err(SendError::Busy);
            }
            self.ep.next_epoch();
            self.exhausted = false;
        }
        let counter = self.ep.next_command;
        let h = self.ep.command(now, dst, counter, tag, payload)?;
        match counter.checked_add(1) {
            Some(c) => self.ep.next_command = c,
            None => self.exhausted = true,
        }
        Ok(h)
    }

    /// Cars heard, with their latest state; use [`Neighbour::is_stale`] for freshness.
    pub fn cars(&self) -> impl Iterator<Item = &Neighbour> {
        self.ep
            .neighbours()
            .iter()
            .filter(|n| matches!(n.addr, Address::Car(_)))
    }

    /// Feed radio UART bytes read at `now`.
    pub fn push_rx(&mut self, now: u64, bytes: &[u8]) {
        self.ep.push_rx(now, bytes)
    }

    /// Advance timers to `now`.
    pub fn poll(&mut self, now: u64) {
        self.ep.poll(now)
    }

    /// Earliest time at which `poll` has work.
    pub fn poll_at(&mut self, now: u64) -> u64 {
        self.ep.poll_at(now)
    }

    /// Bytes for the radio UART.
    pub fn transmit(&mut self, buf: &mut [u8]) -> usize {
        self.ep.transmit(buf)
    }

    /// Next event.
    pub fn next_event(&mut self) -> Option<Event> {
        self.ep.next_event()
    }

    /// Nodes heard.
    pub fn neighbours(&self) -> &NeighbourTable<GROUND_CARS> {
        self.ep.neighbours()
    }

    /// Staleness limit of cars.
    pub fn stale_after_us(&self) -> u64 {
        self.ep.stale_after_us()
    }

    /// Answer a request a car sent to the ground station.
    pub fn reply(&mut self, id: IncomingId, tag: u8, payload: &[u8]) -> Result<(), ReplyError> {
        self.ep.reply(id, tag, payload)
    }

    /// Send a maneuver message.
    pub fn send_group(
        &mut self,
        now: u64,
        dst: Address,
        group: u8,
        msg: GroupMsg,
    ) -> Result<RequestHandle, SendError> {
        self.ep.send_group(now, dst, group, msg)
    }

    /// Counters.
    pub fn stats(&self) -> &Stats {
        self.ep.stats()
    }

    /// The underlying engine.
    pub fn endpoint(&mut self) -> &mut Endpoint<GROUND_CARS> {
        &mut self.ep
    }
}
