//! The sans-IO protocol engine shared by the car and ground-station roles.
//!
//! Bytes from the radio UART go in through [`Endpoint::push_rx`], time advances through
//! [`Endpoint::poll`], bytes for the radio UART come out of [`Endpoint::transmit`] and
//! everything the application must know comes out of [`Endpoint::next_event`]. Nothing
//! allocates; every queue is a `heapless` collection with a named capacity, and every
//! dropped frame or byte increments one counter in [`Stats`].

use crate::addr::{Address, CarId};
use crate::auth::{self, Freshness, Key, ReplayGuard, Session};
use crate::deframer::Deframer;
use crate::neighbours::{CachedReply, NeighbourTable, SeqCheck, SeqWindow};
use crate::schedule::Schedule;
use crate::wire::{
    encode_frame, CarState, Encoded, Frame, FrameError, GroupMsg, Heartbeat, Mode, Payload,
};
use heapless::{Deque, Vec};

mod broadcast;
mod session;

/// Bytes waiting for the radio UART.
pub const TX_QUEUE: usize = 512;
/// Events waiting for the application.
pub const EVENT_QUEUE: usize = 16;
/// Outstanding requests, commands and repeated broadcasts.
pub const MAX_PENDING: usize = 4;
/// First retransmission timeout.
pub const RETRY_BASE_US: u32 = 40_000;
/// Largest retransmission timeout (the doubling stops here).
pub const RETRY_MAX_US: u32 = 320_000;
/// Transmissions of one request before it fails (first try included).
pub const MAX_ATTEMPTS: u8 = 8;
/// Transmissions of an unacknowledged broadcast (group messages, broadcast commands).
pub const REPEATS: u8 = 3;
/// Spacing of those transmissions (plus up to half of it as random jitter).
pub const REPEAT_SPACING_US: u32 = 20_000;
/// Default heartbeat period.
pub const HEARTBEAT_US: u32 = 1_000_000;
/// A ground station heard within this long counts as around (for ground frames).
pub const GROUND_AROUND_US: u64 = 10_000_000;
/// Default staleness limit of a neighbour.
pub const STALE_AFTER_US: u32 = 1_000_000;
/// Silence after which a peer's duplicate window is forgotten (longer than a full retry run).
pub const DEDUP_RESET_US: u64 = 5_000_000;
/// A car without a session sends a Hello this often.
pub const HELLO_RETRY_US: u64 = 1_000_000;
/// Shortest gap between two Hellos of a car (a command or heartbeat it cannot verify asks for
/// one at once; the ground station's retransmissions come at least 40 ms apart).
pub const HELLO_GAP_US: u64 = 20_000;
/// Shortest gap between two session openings the ground station sends one car.
pub const SESSION_OPEN_GAP_US: u64 = 20_000;
/// Largest random delay of a car's first Hello.
pub const HELLO_FIRST_JITTER_US: u64 = 50_000;
/// Largest random delay of a Hello asked for by a frame every car hears at the same instant
/// (a GroundBeat of another epoch, a broadcast command a car cannot verify): without it every
/// car of a restarted station answers its first heartbeat at once, the Hellos collide, and
/// they collide again at every heartbeat.
pub const HELLO_REACT_JITTER_US: u64 = 50_000;

/// Retransmission parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RetryConfig {
    /// First timeout; doubles per attempt.
    pub base_us: u32,
    /// Timeout ceiling.
    pub max_us: u32,
    /// Transmissions before failure.
    pub max_attempts: u8,
    /// Transmissions of unacknowledged broadcasts.
    pub repeats: u8,
    /// Spacing of broadcast repeats.
    pub repeat_spacing_us: u32,
}

impl Default for RetryConfig {
    fn default() -> Self {
        Self {
            base_us: RETRY_BASE_US,
            max_us: RETRY_MAX_US,
            max_attempts: MAX_ATTEMPTS,
            repeats: REPEATS,
            repeat_spacing_us: REPEAT_SPACING_US,
        }
    }
}

/// Identifies an outgoing request, command or broadcast in later events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RequestHandle(pub u32);

/// Identifies an incoming request for [`Endpoint::reply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IncomingId {
    /// Sender.
    pub from: Address,
    /// Sender's sequence number (low 16 bits of the counter for authenticated commands).
    pub seq: u16,
    /// Counter of an authenticated command; `None` for plain requests.
    pub counter: Option<u32>,
    /// Sent to broadcast: no reply is possible.
    pub broadcast: bool,
}

/// A request or authenticated command to execute; delivered exactly once.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Incoming {
    /// Pass to [`Endpoint::reply`].
    pub id: IncomingId,
    /// Application tag.
    pub tag: u8,
    /// Request bytes.
    pub payload: Payload,
}

/// Something the application must know.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// A car's state broadcast.
    State {
        /// Sender.
        from: CarId,
        /// Its state counter.
        seq: u8,
        /// Its state.
        state: CarState,
    },
    /// A heartbeat.
    Heartbeat {
        /// Sender.
        from: Address,
        /// Contents.
        beat: Heartbeat,
    },
    /// A request (or authenticated command) to execute and answer with [`Endpoint::reply`].
    Request(Incoming),
    /// The answer to one of our requests or commands.
    Reply {
        /// Which request.
        handle: RequestHandle,
        /// Who answered.
        from: Address,
        /// Reply tag.
        tag: u8,
        /// Reply bytes.
        payload: Payload,
    },
    /// A request or command got no answer after all attempts.
    Failed {
        /// Which request.
        handle: RequestHandle,
        /// Its destination.
        dst: Address,
    },
    /// All repeats of a broadcast were handed to the radio.
    RepeatsDone {
        /// Which broadcast.
        handle: RequestHandle,
    },
    /// A maneuver message.
    Group {
        /// Sender.
        from: Address,
        /// Group number.
        group: u8,
        /// The message.
        msg: GroupMsg,
        /// Sent to broadcast.
        broadcast: bool,
    },
}

/// Why a message could not be queued.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SendError {
    /// Payload longer than [`crate::wire::MAX_PAYLOAD`].
    PayloadTooLong {
        /// Length given.
        len: usize,
    },
    /// Destination not allowed (broadcast for a request, ourselves, ...).
    InvalidDestination,
    /// A request to the same destination, a command, or [`MAX_PENDING`] messages are
    /// already outstanding.
    Busy,
    /// Not enough room in the transmit queue.
    TxQueueFull,
    /// A field out of range.
    Encode(crate::wire::EncodeError),
    /// No key configured.
    NoKey,
}

/// Why a reply could not be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReplyError {
    /// The request was a broadcast.
    Broadcast,
    /// No request with this id awaits a reply (already answered or forgotten).
    NotPending,
    /// Payload longer than [`crate::wire::MAX_PAYLOAD`].
    PayloadTooLong {
        /// Length given.
        len: usize,
    },
    /// Not enough room in the transmit queue.
    TxQueueFull,
}

/// Drop and activity counters; one per reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub struct Stats {
    /// Valid frames received.
    pub rx_frames: u32,
    /// Runs longer than a frame before a delimiter.
    pub rx_oversize: u32,
    /// Invalid COBS.
    pub rx_cobs: u32,
    /// Frames too short to hold a CRC.
    pub rx_too_short: u32,
    /// CRC mismatches.
    pub rx_checksum: u32,
    /// Intact frames of another protocol version.
    pub rx_version: u32,
    /// Unknown frame kinds.
    pub rx_unknown_kind: u32,
    /// Bad lengths, addresses or field values.
    pub rx_malformed: u32,
    /// Frames carrying our own source address (ID conflict).
    pub rx_own_address: u32,
    /// Unicast frames for someone else.
    pub not_for_us: u32,
    /// Retransmitted requests suppressed.
    pub duplicates: u32,
    /// Cached replies resent for retransmitted requests.
    pub replies_resent: u32,
    /// Retransmissions arriving while the application had not answered yet.
    pub duplicates_pending: u32,
    /// Requests older than the duplicate window.
    pub too_old: u32,
    /// Replies matching no outstanding request.
    pub unexpected_replies: u32,
    /// Repeated group messages suppressed.
    pub group_duplicates: u32,
    /// Senders not tracked because the neighbour table was full of fresh entries.
    pub neighbour_table_full: u32,
    /// Events lost because the application did not drain the queue.
    pub event_overflow: u32,
    /// Frames not queued for lack of transmit space.
    pub tx_queue_full: u32,
    /// Retransmissions sent.
    pub retries: u32,
    /// Requests or commands that failed after all attempts.
    pub failures: u32,
    /// Authenticated commands received without a configured key.
    pub auth_no_key: u32,
    /// Authenticated frames that did not verify: forged or altered, another key, or signed
    /// for another session; also commands received without a session once two Hellos went
    /// unanswered (a ground station with another key never answers them). On the ground
    /// station: Hellos that did not verify.
    pub auth_bad_mac: u32,
    /// Authenticated commands and heartbeats received while the car had no session with the
    /// ground station's epoch (it sends a Hello).
    pub auth_no_session: u32,
    /// Hellos sent (car).
    pub hellos_sent: u32,
    /// Sessions opened: accepted by a car, sent by the ground station.
    pub sessions_opened: u32,
    /// Session openings a car refused (not for its last Hello, or a bad MAC).
    pub sessions_refused: u32,
    /// Authenticated commands with an old counter (replayed).
    pub auth_replay: u32,
    /// Retransmissions of the last accepted command.
    pub auth_repeat: u32,
    /// State broadcasts sent.
    pub states_sent: u32,
    /// Heartbeats sent.
    pub heartbeats_sent: u32,
    /// State broadcasts left out in ground frames (see `schedule::GROUND_FRAME_EVERY`).
    pub ground_frames_kept: u32,
    /// State broadcasts left out because the channel ran behind just before their slot (see
    /// `schedule::LATE_YIELD_US`).
    pub states_yielded: u32,
}

impl core::ops::AddAssign for Stats {
    /// Counts of two endpoints together (e.g. the ground stations of several channels).
    fn add_assign(&mut self, other: Self) {
        // Exhaustive, so a new counter cannot be left out.
        let Stats {
            rx_frames,
            rx_oversize,
            rx_cobs,
            rx_too_short,
            rx_checksum,
            rx_version,
            rx_unknown_kind,
            rx_malformed,
            rx_own_address,
            not_for_us,
            duplicates,
            replies_resent,
            duplicates_pending,
            too_old,
            unexpected_replies,
            group_duplicates,
            neighbour_table_full,
            event_overflow,
            tx_queue_full,
            retries,
            failures,
            auth_no_key,
            auth_bad_mac,
            auth_no_session,
            hellos_sent,
            sessions_opened,
            sessions_refused,
            auth_replay,
            auth_repeat,
            states_sent,
            heartbeats_sent,
            ground_frames_kept,
            states_yielded,
        } = other;
        self.rx_frames = self.rx_frames.wrapping_add(rx_frames);
        self.rx_oversize = self.rx_oversize.wrapping_add(rx_oversize);
        self.rx_cobs = self.rx_cobs.wrapping_add(rx_cobs);
        self.rx_too_short = self.rx_too_short.wrapping_add(rx_too_short);
        self.rx_checksum = self.rx_checksum.wrapping_add(rx_checksum);
        self.rx_version = self.rx_version.wrapping_add(rx_version);
        self.rx_unknown_kind = self.rx_unknown_kind.wrapping_add(rx_unknown_kind);
        self.rx_malformed = self.rx_malformed.wrapping_add(rx_malformed);
        self.rx_own_address = self.rx_own_address.wrapping_add(rx_own_address);
        self.not_for_us = self.not_for_us.wrapping_add(not_for_us);
        self.duplicates = self.duplicates.wrapping_add(duplicates);
        self.replies_resent = self.replies_resent.wrapping_add(replies_resent);
        self.duplicates_pending = self.duplicates_pending.wrapping_add(duplicates_pending);
        self.too_old = self.too_old.wrapping_add(too_old);
        self.unexpected_replies = self.unexpected_replies.wrapping_add(unexpected_replies);
        self.group_duplicates = self.group_duplicates.wrapping_add(group_duplicates);
        self.neighbour_table_full = self.neighbour_table_full.wrapping_add(neighbour_table_full);
        self.event_overflow = self.event_overflow.wrapping_add(event_overflow);
        self.tx_queue_full = self.tx_queue_full.wrapping_add(tx_queue_full);
        self.retries = self.retries.wrapping_add(retries);
        self.failures = self.failures.wrapping_add(failures);
        self.auth_no_key = self.auth_no_key.wrapping_add(auth_no_key);
        self.auth_bad_mac = self.auth_bad_mac.wrapping_add(auth_bad_mac);
        self.auth_no_session = self.auth_no_session.wrapping_add(auth_no_session);
        self.hellos_sent = self.hellos_sent.wrapping_add(hellos_sent);
        self.sessions_opened = self.sessions_opened.wrapping_add(sessions_opened);
        self.sessions_refused = self.sessions_refused.wrapping_add(sessions_refused);
        self.auth_replay = self.auth_replay.wrapping_add(auth_replay);
        self.auth_repeat = self.auth_repeat.wrapping_add(auth_repeat);
        self.states_sent = self.states_sent.wrapping_add(states_sent);
        self.heartbeats_sent = self.heartbeats_sent.wrapping_add(heartbeats_sent);
        self.ground_frames_kept = self.ground_frames_kept.wrapping_add(ground_frames_kept);
        self.states_yielded = self.states_yielded.wrapping_add(states_yielded);
    }
}

#[derive(Debug, Clone)]
enum PendingKind {
    Acked,
    Repeat { left: u8 },
}

#[derive(Debug, Clone)]
struct Pending {
    handle: RequestHandle,
    dst: Address,
    seq: u16,
    auth: bool,
    /// Counter of an authenticated command.
    counter: u32,
    frame: Encoded,
    attempts: u8,
    due: u64,
    kind: PendingKind,
}

/// The protocol engine; [`crate::CarMac`] and [`crate::GroundStation`] wrap it per role.
#[derive(Debug)]
pub struct Endpoint<const N: usize> {
    own: Address,
    deframer: Deframer,
    tx: Deque<u8, TX_QUEUE>,
    events: Deque<Event, EVENT_QUEUE>,
    neighbours: NeighbourTable<N>,
    pending: Vec<Pending, MAX_PENDING>,
    retry: RetryConfig,
    stale_after_us: u64,
    heartbeat_us: u64,
    next_heartbeat: Option<u64>,
    heartbeat_aligned: bool,
    started: Option<u64>,
    next_seq: u16,
    next_gseq: u8,
    next_handle: u32,
    rng: u32,
    key: Option<Key>,
    /// Car: the floor restored from storage, applied to every session.
    guard: ReplayGuard,
    /// Car: the session with the ground station.
    session: Option<Session>,
    /// Car: nonce of the next Hello; of the last one sent, while unanswered.
    next_nonce: u64,
    hello_nonce: Option<u64>,
    hello_at: Option<u64>,
    /// Car: Hellos sent since the last session opened.
    hellos_unanswered: u8,
    /// Car: when the next periodic Hello is due (the first one after a random delay of up
    /// to [`HELLO_FIRST_JITTER_US`], so that cars started together do not collide).
    hello_due: Option<u64>,
    /// Car: when the Hello asked for by a frame every car heard is due (see
    /// [`HELLO_REACT_JITTER_US`]).
    hello_soon: Option<u64>,
    /// Ground station: session epoch, next command and heartbeat counters.
    pub(crate) epoch: u32,
    pub(crate) next_command: u32,
    next_beat: u32,
    auth_pending: Option<u32>,
    auth_reply: Option<CachedReply>,
    pub(crate) schedule: Option<Schedule>,
    pub(crate) state: Option<CarState>,
    state_seq: u8,
    last_state_sent: Option<u64>,
    /// When a frame from the ground station was last heard (ground frames are kept only
    /// while one is around).
    ground_heard: Option<u64>,
    pub(crate) mode: Mode,
    stats: Stats,
}

impl<const N: usize> Endpoint<N> {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        own: Address,
        retry: RetryConfig,
        stale_after_us: u32,
        heartbeat_us: u32,
        seed: u32,
        key: Option<Key>,
        guard: ReplayGuard,
        schedule: Option<Schedule>,
    ) -> Self {
        let mut rng = seed ^ 0x9E37_79B9 ^ u32::from(own.to_byte()).rotate_left(16);
        if rng == 0 {
            rng = 1;
        }
        let mut e = Self {
            own,
            deframer: Deframer::new(),
            tx: Deque::new(),
            events: Deque::new(),
            neighbours: NeighbourTable::new(),
            pending: Vec::new(),
            retry,
            stale_after_us: u64::from(stale_after_us),
            heartbeat_us: u64::from(heartbeat_us),
            next_heartbeat: None,
            heartbeat_aligned: false,
            started: None,
            next_seq: 0,
            next_gseq: 0,
            next_handle: 0,
            rng,
            key,
            guard,
            session: None,
            next_nonce: 0,
            hello_nonce: None,
            hello_at: None,
            hellos_unanswered: 0,
            hello_due: None,
            hello_soon: None,
            epoch: 0,
            next_command: 0,
            next_beat: 1,
            auth_pending: None,
            auth_reply: None,
            schedule,
            state: None,
            state_seq: 0,
            last_state_sent: None,
            ground_heard: None,
            mode: Mode::default(),
            stats: Stats::default(),
        };
        e.next_seq = e.random() as u16;
        e.next_gseq = e.random() as u8;
        e
    }

    fn random(&mut self) -> u32 {
        // xorshift32: jitter only, not security.
        let mut x = self.rng;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.rng = x;
        x
    }

    /// Our address.
    pub fn address(&self) -> Address {
        self.own
    }

    /// Counters.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// Nodes heard.
    pub fn neighbours(&self) -> &NeighbourTable<N> {
        &self.neighbours
    }

    /// Staleness limit in use.
    pub fn stale_after_us(&self) -> u64 {
        self.stale_after_us
    }

    /// Command counters accepted in the current session (none without a session).
    pub fn replay_guard(&self) -> ReplayGuard {
        self.session.map_or(ReplayGuard::new(), |s| s.commands)
    }

    /// The car's session with the ground station, once one is open.
    pub fn session(&self) -> Option<Session> {
        self.session
    }

    /// Car: Hello nonces start at `boot << 32` (a counter persisted across restarts).
    pub(crate) fn set_boot(&mut self, boot: u32) {
        self.next_nonce = u64::from(boot) << 32;
    }

    /// Ground station: its session epoch and first command counter.
    pub(crate) fn set_ground_session(&mut self, epoch: u32, first_counter: u32) {
        self.epoch = epoch;
        self.next_command = first_counter;
    }

    /// An authenticated command is still being sent.
    pub(crate) fn auth_outstanding(&self) -> bool {
        self.pending.iter().any(|p| p.auth)
    }

    /// Ground station: the next session, when a counter is used up.
    pub(crate) fn next_epoch(&mut self) {
        self.epoch = self.epoch.wrapping_add(1);
        self.next_beat = 1;
        self.next_command = 1;
        // A heartbeat at once tells the cars of the new epoch (they ask to join it).
        self.next_heartbeat = None;
        self.heartbeat_aligned = false;
    }

    /// Next event for the application.
    pub fn next_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Move queued bytes for the radio UART into `buf`; returns how many.
    pub fn transmit(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in buf.iter_mut() {
            match self.tx.pop_front() {
                Some(b) => {
                    *slot = b;
                    n += 1;
                }
                None => break,
            }
        }
        n
    }

    /// Bytes waiting for the radio UART.
    pub fn tx_pending(&self) -> usize {
        self.tx.len()
    }

    fn queue_bytes(&mut self, bytes: &[u8]) -> bool {
        if self.tx.capacity() - self.tx.len() < bytes.len() {
            self.stats.tx_queue_full += 1;
            return false;
        }
        for &b in bytes {
            // Room was checked above.
            let _ = self.tx.push_back(b);
        }
        true
    }

    fn queue_frame(&mut self, frame: &Frame) -> Result<Encoded, SendError> {
        let enc = encode_frame(frame).map_err(SendError::Encode)?;
        if self.queue_bytes(&enc) {
            Ok(enc)
        } else {
            Err(SendError::TxQueueFull)
        }
    }

    fn emit(&mut self, event: Event) -> bool {
        if self.events.push_back(event).is_err() {
            self.stats.event_overflow += 1;
            false
        } else {
            true
        }
    }

    fn new_handle(&mut self) -> RequestHandle {
        self.next_handle = self.next_handle.wrapping_add(1);
        RequestHandle(self.next_handle)
    }

    // Out of line: a smaller image than its 64-bit shift and remainder at each use.
    #[inline(never)]
    fn timeout(&mut self, attempts: u8) -> u64 {
        let shift = u32::from(attempts.saturating_sub(1)).min(16);
        let t = (u64::from(self.retry.base_us) << shift).min(u64::from(self.retry.max_us));
        let jitter_span = u64::from(self.retry.base_us / 2).max(1);
        t + u64::from(self.random()) % jitter_span
    }

    fn repeat_gap(&mut self) -> u64 {
        let s = u64::from(self.retry.repeat_spacing_us);
        s + u64::from(self.random()) % (s / 2).max(1)
    }

    fn payload(bytes: &[u8]) -> Result<Payload, SendError> {
        Payload::from_slice(bytes).map_err(|_| SendError::PayloadTooLong { len: bytes.len() })
    }

    /// Send an acknowledged request; the answer arrives as [`Event::Reply`] with the returned
    /// handle, or [`Event::Failed`] after [`RetryConfig::max_attempts`]. One request per
    /// destination may be outstanding.
    pub fn request(
        &mut self,
        now: u64,
        dst: Address,
        tag: u8,
        payload: &[u8],
    ) -> Result<RequestHandle, SendError> {
        if dst == Address::Broadcast || dst == self.own {
            return Err(SendError::InvalidDestination);
        }
        let payload = Self::payload(payload)?;
        // Stop-and-wait per destination: the peer keeps one reply per sender in its cache.
        let to_dst = self
            .pending
            .iter()
            .any(|p| p.dst == dst && matches!(p.kind, PendingKind::Acked));
        if to_dst || self.pending.is_full() {
            return Err(SendError::Busy);
        }
        let seq = self.next_seq;
        let frame = Frame::Request {
            src: self.own,
            dst,
            seq,
            tag,
            payload,
        };
        let enc = self.queue_frame(&frame)?;
        self.next_seq = self.next_seq.wrapping_add(1);
        let handle = self.new_handle();
        let due = now + self.timeout(1);
        let p = Pending {
            handle,
            dst,
            seq,
            auth: false,
            counter: 0,
            frame: enc,
            attempts: 1,
            due,
            kind: PendingKind::Acked,
        };
        // Capacity was checked above.
        let _ = self.pending.push(p);
        Ok(handle)
    }

    /// Send a maneuver message [`RetryConfig::repeats`] times (to one node or broadcast);
    /// receivers deliver it once.
    pub fn send_group(
        &mut self,
        now: u64,
        dst: Address,
        group: u8,
        msg: GroupMsg,
    ) -> Result<RequestHandle, SendError> {
        if dst == self.own {
            return Err(SendError::InvalidDestination);
        }
        if self.pending.is_full() {
            return Err(SendError::Busy);
        }
        let frame = Frame::Group {
            src: self.own,
            dst,
            group,
            gseq: self.next_gseq,
            msg,
        };
        let enc = self.queue_frame(&frame)?;
        self.next_gseq = self.next_gseq.wrapping_add(1);
        self.push_repeat(now, dst, enc)
    }

    fn push_repeat(
        &mut self,
        now: u64,
        dst: Address,
        enc: Encoded,
    ) -> Result<RequestHandle, SendError> {
        let handle = self.new_handle();
        let due = now + self.repeat_gap();
        let left = self.retry.repeats.saturating_sub(1);
        let p = Pending {
            handle,
            dst,
            seq: 0,
            auth: false,
            counter: 0,
            frame: enc,
            attempts: 1,
            due,
            kind: PendingKind::Repeat { left },
        };
        self.pending.push(p).map_err(|_| SendError::Busy)?;
        Ok(handle)
    }

    /// Send an authenticated command signed with `counter` (ground station).
    pub(crate) fn command(
        &mut self,
        now: u64,
        dst: Address,
        counter: u32,
        tag: u8,
        payload: &[u8],
    ) -> Result<RequestHandle, SendError> {
        if matches!(dst, Address::Ground) {
            return Err(SendError::InvalidDestination);
        }
        let payload = Self::payload(payload)?;
        if self.pending.iter().any(|p| p.auth) || self.pending.is_full() {
            return Err(SendError::Busy);
        }
        let key = self.key.clone().ok_or(SendError::NoKey)?;
        let mut frame = Frame::AuthCommand {
            dst,
            counter,
            tag,
            payload,
            mac: [0; crate::wire::AUTH_TAG_LEN],
        };
        auth::sign(&key, self.epoch, &mut frame).map_err(SendError::Encode)?;
        let enc = self.queue_frame(&frame)?;
        if dst == Address::Broadcast {
            let h = self.push_repeat(now, dst, enc)?;
            if let Some(p) = self.pending.last_mut() {
                p.auth = true;
                p.counter = counter;
            }
            return Ok(h);
        }
        let handle = self.new_handle();
        let due = now + self.timeout(1);
        let p = Pending {
            handle,
            dst,
            seq: counter as u16,
            auth: true,
            counter,
            frame: enc,
            attempts: 1,
            due,
            kind: PendingKind::Acked,
        };
        let _ = self.pending.push(p);
        Ok(handle)
    }

    /// Answer a delivered request; retransmissions of it are answered from a cache.
    pub fn reply(&mut self, id: IncomingId, tag: u8, payload: &[u8]) -> Result<(), ReplyError> {
        if id.broadcast {
            return Err(ReplyError::Broadcast);
        }
        let payload = Payload::from_slice(payload)
            .map_err(|_| ReplyError::PayloadTooLong { len: payload.len() })?;
        let cached = CachedReply {
            seq: id.seq,
            tag,
            payload,
        };
        match id.counter {
            Some(c) => {
                if self.auth_pending != Some(c) {
                    return Err(ReplyError::NotPending);
                }
                self.auth_pending = None;
                self.auth_reply = Some(cached.clone());
            }
            None => {
                let n = self
                    .neighbours
                    .get_mut(id.from)
                    .filter(|n| n.pending == Some(id.seq))
                    .ok_or(ReplyError::NotPending)?;
                n.pending = None;
                n.reply = Some(cached.clone());
            }
        }
        self.send_reply(id.from, &cached)
    }

    fn send_reply(&mut self, dst: Address, r: &CachedReply) -> Result<(), ReplyError> {
        let frame = Frame::Reply {
            src: self.own,
            dst,
            seq: r.seq,
            tag: r.tag,
            payload: r.payload.clone(),
        };
        self.queue_frame(&frame)
            .map(|_| ())
            .map_err(|_| ReplyError::TxQueueFull)
    }

    /// Feed bytes read from the radio UART at local time `now` (microseconds).
    pub fn push_rx(&mut self, now: u64, bytes: &[u8]) {
        self.started.get_or_insert(now);
        for &b in bytes {
            match self.deframer.push(b) {
                None => {}
                Some(Ok(frame)) => self.handle_frame(now, frame),
                Some(Err(e)) => self.count_error(e),
            }
        }
    }

    fn count_error(&mut self, e: FrameError) {
        let s = &mut self.stats;
        match e {
            FrameError::Oversize => s.rx_oversize += 1,
            FrameError::Cobs => s.rx_cobs += 1,
            FrameError::TooShort { .. } => s.rx_too_short += 1,
            FrameError::ChecksumMismatch { .. } => s.rx_checksum += 1,
            FrameError::UnsupportedVersion { .. } => s.rx_version += 1,
            FrameError::UnknownKind { .. } => s.rx_unknown_kind += 1,
            FrameError::BadLength { .. }
            | FrameError::InvalidAddress { .. }
            | FrameError::InvalidSource
            | FrameError::InvalidDestination
            | FrameError::FieldOutOfRange { .. }
            | FrameError::UnknownGroupMsg { .. } => s.rx_malformed += 1,
        }
    }

    fn for_us(&mut self, dst: Address) -> bool {
        if dst == self.own || dst == Address::Broadcast {
            true
        } else {
            self.stats.not_for_us += 1;
            false
        }
    }

    fn handle_frame(&mut self, now: u64, frame: Frame) {
        let src = frame.src();
        if src == self.own {
            self.stats.rx_own_address += 1;
            return;
        }
        self.stats.rx_frames += 1;
        if src == Address::Ground {
            self.ground_heard = Some(now);
        }
        let stale = self.stale_after_us;
        match self.neighbours.touch(src, now, stale) {
            Some(n) => {
                // A peer silent for longer than a full retry run may have restarted: forget
                // its receive state so its new sequence numbers are not taken for repeats.
                if crate::sat_sub(now, n.last_heard) > DEDUP_RESET_US {
                    n.window = None;
                    n.pending = None;
                    n.reply = None;
                    n.last_gseq = None;
                }
                n.last_heard = now;
            }
            None => self.stats.neighbour_table_full += 1,
        }
        match frame {
            Frame::State {
                src: id,
                seq,
                state,
            } => {
                if let Some(n) = self.neighbours.get_mut(src) {
                    if let Some(last) = n.last_state_seq {
                        n.states_missed += u32::from(seq.wrapping_sub(last).saturating_sub(1));
                    }
                    n.last_state_seq = Some(seq);
                    n.states_heard += 1;
                    n.state = Some((state, now));
                }
                if let Some(s) = self.schedule.as_mut() {
                    s.heard_state(now, id, seq, stale);
                }
                self.emit(Event::State {
                    from: id,
                    seq,
                    state,
                });
            }
            Frame::Heartbeat { beat, .. } => {
                if let Some(n) = self.neighbours.get_mut(src) {
                    n.heartbeat = Some(beat);
                }
                self.emit(Event::Heartbeat { from: src, beat });
            }
            Frame::Request {
                dst,
                seq,
                tag,
                payload,
                ..
            } => {
                if dst != self.own {
                    self.stats.not_for_us += 1;
                    return;
                }
                self.handle_request(src, seq, tag, payload);
            }
            Frame::Reply {
                dst,
                seq,
                tag,
                payload,
                ..
            } => {
                if dst != self.own {
                    self.stats.not_for_us += 1;
                    return;
                }
                match self.pending.iter().position(|p| {
                    matches!(p.kind, PendingKind::Acked) && p.dst == src && p.seq == seq
                }) {
                    Some(i) => {
                        let Some(p) = take(&mut self.pending, i) else {
                            return;
                        };
                        self.emit(Event::Reply {
                            handle: p.handle,
                            from: src,
                            tag,
                            payload,
                        });
                    }
                    None => self.stats.unexpected_replies += 1,
                }
            }
            Frame::Group {
                dst,
                group,
                gseq,
                msg,
                ..
            } => {
                if !self.for_us(dst) {
                    return;
                }
                let Some(n) = self.neighbours.get_mut(src) else {
                    return;
                };
                if n.last_gseq == Some(gseq) {
                    self.stats.group_duplicates += 1;
                    return;
                }
                let ev = Event::Group {
                    from: src,
                    group,
                    msg,
                    broadcast: dst == Address::Broadcast,
                };
                if self.emit(ev) {
                    if let Some(n) = self.neighbours.get_mut(src) {
                        n.last_gseq = Some(gseq);
                    }
                }
            }
            frame @ Frame::AuthCommand { .. } => self.handle_auth(now, frame),
            frame @ Frame::GroundBeat { .. } => self.handle_beat(now, frame),
            frame @ Frame::Hello { .. } => self.handle_hello(now, frame),
            frame @ Frame::SessionOpen { .. } => self.handle_open(frame),
        }
    }

    fn handle_request(&mut self, src: Address, seq: u16, tag: u8, payload: Payload) {
        let Some(n) = self.neighbours.get_mut(src) else {
            return;
        };
        let verdict = match n.window {
            Some(w) => w.check(seq),
            None => SeqCheck::Fresh,
        };
        match verdict {
            SeqCheck::Fresh => {
                let ev = Event::Request(Incoming {
                    id: IncomingId {
                        from: src,
                        seq,
                        counter: None,
                        broadcast: false,
                    },
                    tag,
                    payload,
                });
                if self.emit(ev) {
                    if let Some(n) = self.neighbours.get_mut(src) {
                        match n.window.as_mut() {
                            Some(w) => w.mark(seq),
                            None => n.window = Some(SeqWindow::starting_at(seq)),
                        }
                        n.pending = Some(seq);
                    }
                }
            }
            SeqCheck::Duplicate => {
                self.stats.duplicates += 1;
                let cached = n.reply.clone().filter(|r| r.seq == seq);
                let waiting = n.pending == Some(seq);
                if let Some(r) = cached {
                    self.stats.replies_resent += 1;
                    let _ = self.send_reply(src, &r);
                } else if waiting {
                    self.stats.duplicates_pending += 1;
                }
            }
            SeqCheck::TooOld => self.stats.too_old += 1,
        }
    }

    /// Advance timers to `now`: retransmissions, state broadcast, heartbeat, staleness.
    pub fn poll(&mut self, now: u64) {
        self.started.get_or_insert(now);
        let mut i = 0;
        while i < self.pending.len() {
            if self.pending[i].due > now {
                i += 1;
                continue;
            }
            let attempts = self.pending[i].attempts;
            let kind = self.pending[i].kind.clone();
            let resend = match kind {
                PendingKind::Acked => attempts < self.retry.max_attempts,
                PendingKind::Repeat { left } => left > 0,
            };
            if resend {
                let frame = self.pending[i].frame.clone();
                if self.queue_bytes(&frame) && matches!(kind, PendingKind::Acked) {
                    self.stats.retries += 1;
                }
                let due = match kind {
                    PendingKind::Acked => now + self.timeout(attempts + 1),
                    PendingKind::Repeat { .. } => now + self.repeat_gap(),
                };
                if let Some(p) = self.pending.get_mut(i) {
                    p.attempts = attempts.saturating_add(1);
                    p.due = due;
                    if let PendingKind::Repeat { left } = &mut p.kind {
                        *left -= 1;
                    }
                }
                i += 1;
            } else {
                let Some(p) = take(&mut self.pending, i) else {
                    break;
                };
                match kind {
                    PendingKind::Acked => {
                        self.stats.failures += 1;
                        self.emit(Event::Failed {
                            handle: p.handle,
                            dst: p.dst,
                        });
                    }
                    PendingKind::Repeat { .. } => {
                        self.emit(Event::RepeatsDone { handle: p.handle });
                    }
                }
            }
        }
        self.poll_state(now);
        self.poll_heartbeat(now);
        if self.session.is_none() && self.key.is_some() && matches!(self.own, Address::Car(_)) {
            let first = now + u64::from(self.random()) % HELLO_FIRST_JITTER_US;
            if now >= *self.hello_due.get_or_insert(first) {
                self.hello_due = Some(now + HELLO_RETRY_US);
                self.hello(now, HELLO_GAP_US);
            }
        }
        if self.hello_soon.is_some_and(|t| now >= t) {
            self.hello_soon = None;
            self.hello(now, HELLO_GAP_US);
        }
    }

    /// When the next state broadcast is due to be written (its slot's start less the send
    /// lead), if this node broadcasts its state on a schedule.
    pub fn next_state_due(&mut self, now: u64) -> Option<u64> {
        self.state?;
        Some(self.schedule.as_mut()?.next_due(now))
    }

    /// Earliest time at which [`Endpoint::poll`] has work to do.
    pub fn poll_at(&mut self, now: u64) -> u64 {
        let mut t = self.next_heartbeat.unwrap_or(now);
        for p in &self.pending {
            t = t.min(p.due);
        }
        if self.state.is_some() {
            if let Some(s) = self.schedule.as_mut() {
                t = t.min(s.next_due(now));
            }
        }
        if self.session.is_none() && self.key.is_some() && matches!(self.own, Address::Car(_)) {
            t = t.min(self.hello_due.unwrap_or(now));
        }
        if let Some(soon) = self.hello_soon {
            t = t.min(soon);
        }
        t
    }
}

/// Removes item `i` and puts the last one in its place, as `swap_remove` does, `None` when
/// `i` is out of range. heapless's `swap_remove` moves the last item with `ptr::copy`,
/// which may overlap and so links `memmove` (740 bytes) into the firmware; this one swaps it
/// in, which never overlaps.
fn take<T, const N: usize>(v: &mut Vec<T, N>, i: usize) -> Option<T> {
    if i >= v.len() {
        return None;
    }
    let mut item = v.pop()?;
    if let Some(slot) = v.get_mut(i) {
        core::mem::swap(slot, &mut item);
    }
    Some(item)
}

#[cfg(test)]
mod take_tests {
    use super::*;

    #[test]
    fn take_is_swap_remove() {
        let items: Vec<u32, 4> = Vec::from_slice(&[10, 11, 12, 13]).unwrap();
        for i in 0..5 {
            let (mut a, mut b) = (items.clone(), items.clone());
            let expected = (i < b.len()).then(|| b.swap_remove(i));
            assert_eq!(take(&mut a, i), expected, "{i}");
            assert_eq!(a, b, "{i}");
        }
    }
}
