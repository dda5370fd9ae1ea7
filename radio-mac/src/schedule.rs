//! Transmit schedule for the periodic state broadcast, above the radio's own CSMA.
//!
//! Time is cut into 30 Hz frames of [`FRAME_US`] (the overhead tracking period) and each frame
//! into [`SLOTS`] slots of [`SLOT_US`]. A car sends its state at the start of its slot
//! (default `(id - 1) % SLOTS`). A 16-byte state frame occupies about 1.7 ms of air, which
//! leaves a guard of about 0.35 ms per slot.
//!
//! The frame boundaries come from one of two time bases:
//! * [`TimeBase::External`]: the application calls [`Schedule::external_tick`] on a shared
//!   event, e.g. the arrival of each overhead tracking frame (all cars hear it at once).
//! * [`TimeBase::FollowLowest`]: each car aligns to the state broadcasts of the lowest car ID
//!   it hears, subtracting the known pipeline latency of a state frame; the lowest car
//!   free-runs. This needs no extra bytes on air.
//!
//! The phase is where frames start on the sender's UART, so a sender must start writing at
//! its slot's start, not merely decide to then: a program that needs some time between
//! [`Schedule::next_due`] and its UART write reports each write ([`Schedule::written`]) and
//! the schedule learns that delay and makes the broadcast due that much earlier (the send
//! lead). Otherwise every follower would sit the delay behind its reference, and the lowest
//! car, hearing everybody late, would keep yielding to them.

use crate::addr::CarId;

/// Frame period: one overhead tracking period (30 Hz), in microseconds.
pub const FRAME_US: u32 = 33_333;
/// Slots per frame.
pub const SLOTS: u8 = 16;
/// Slot length in microseconds.
pub const SLOT_US: u32 = FRAME_US / SLOTS as u32;
/// Default pipeline latency of a state frame, from the start of the UART write on the sender
/// to its delimiter leaving the receiver's radio UART, for a Wi.232-like module at 115200 bps:
/// 16 bytes in (1.39 ms) + inter-byte gap timeout (0.26 ms) + air (20 bytes, 1.74 ms)
/// + 16 bytes out (1.39 ms).
pub const DEFAULT_STATE_LATENCY_US: u32 = 4_774;

/// A phase error above this, once locked, is an outlier (a late frame), in microseconds.
pub const OUTLIER_US: u64 = 200;
/// Consecutive outliers after which the phase jumps to the new estimate.
pub const OUTLIERS_TO_JUMP: u8 = 4;

/// A state frame heard this much later than its slot's phase (on the schedule this car
/// follows), from the slot three before this car's, makes this car leave out its next
/// broadcast while every slot is taken, in microseconds: the channel is running behind, and the
/// slot left free lets it catch up (see [`Schedule::heard_state`]).
pub const LATE_YIELD_US: u64 = 400;

/// Consecutive disagreeing frames after which a car with nobody to follow adopts their phase.
pub const ROOT_YIELD: u8 = 8;

/// At full occupancy (every slot taken), one frame in this many is a *ground frame*: the cars
/// in the first [`GROUND_SLOTS`] slots stay silent in it and the ground station sends its
/// heartbeat there (it has no free slot otherwise, and a heartbeat sent between state frames
/// collides with them). A frame is known by the state sequence number of the car in slot 0,
/// which grows by one every frame: a ground frame is one whose number is
/// `GROUND_FRAME_EVERY - 1` modulo `GROUND_FRAME_EVERY`.
pub const GROUND_FRAME_EVERY: u8 = 32;
/// Slots kept silent in a ground frame: the ground station's heartbeat (22 bytes) takes
/// longer on air than one slot.
pub const GROUND_SLOTS: u8 = 2;

/// Whether the frame with number `seq` (see [`GROUND_FRAME_EVERY`]) is a ground frame.
pub fn is_ground_frame(seq: u8) -> bool {
    seq % GROUND_FRAME_EVERY == GROUND_FRAME_EVERY - 1
}

/// Largest send lead learned from [`Schedule::written`], in microseconds (a write later than
/// this after its slot's start is a late frame, not a delay to make up for).
pub const MAX_SEND_LEAD_US: u32 = 1_000;
/// Weight of a new delay in the send lead: 1 / 2^`LEAD_SHIFT`.
const LEAD_SHIFT: u32 = 2;

/// Where the frame boundaries come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TimeBase {
    /// Application ticks, e.g. overhead tracking frames.
    External {
        /// Offset from a tick to the start of slot 0, in microseconds.
        offset_us: u32,
    },
    /// Align to the lowest car ID heard.
    FollowLowest {
        /// Pipeline latency of a state frame (see [`DEFAULT_STATE_LATENCY_US`]).
        latency_us: u32,
    },
}

/// How often and when the state is broadcast.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StateTiming {
    /// Slotted: once per frame, at the car's slot.
    Slotted {
        /// Slot number, 0..SLOTS.
        slot: u8,
        /// Frame time base.
        time_base: TimeBase,
    },
    /// Unscheduled: every `period_us` from the first state the application sets (CSMA only).
    Periodic {
        /// Period in microseconds.
        period_us: u32,
    },
}

impl StateTiming {
    /// Slotted at the default slot of `id`, following the lowest ID heard.
    pub fn slotted(id: CarId) -> Self {
        StateTiming::Slotted {
            slot: default_slot(id),
            time_base: TimeBase::FollowLowest {
                latency_us: DEFAULT_STATE_LATENCY_US,
            },
        }
    }
}

/// Default slot of a car: `(id - 1) % SLOTS`.
pub fn default_slot(id: CarId) -> u8 {
    (id.get() - 1) % SLOTS
}

/// Signed distance from `b` to `a` modulo the frame, in `(-FRAME_US/2, FRAME_US/2]`.
// Out of line: a smaller image than its 64-bit remainder at each use.
#[inline(never)]
fn phase_diff(a: u64, b: u64) -> i64 {
    let f = i64::from(FRAME_US);
    let d = (a as i64).wrapping_sub(b as i64).rem_euclid(f);
    if d > f / 2 {
        d - f
    } else {
        d
    }
}

/// Slot timer state.
#[derive(Debug, Clone)]
pub struct Schedule {
    timing: StateTiming,
    /// `None` for a listener (the ground station), which follows every car.
    own: Option<CarId>,
    /// A time (local clock) at which some frame's slot 0 started.
    epoch: u64,
    /// Car currently followed, with the time it was last heard.
    reference: Option<(CarId, u64)>,
    locked: bool,
    outliers: u8,
    dissent: u8,
    next_tx: Option<u64>,
    last_tx: Option<u64>,
    /// Slot start of the last broadcast sent (its write should have started then).
    last_target: Option<u64>,
    /// The reference's last state sequence number and the start of the frame it was sent in.
    ref_frame: Option<(u8, u64)>,
    /// How much earlier than its slot's start a broadcast is due, in 1/16 microseconds.
    lead_x16: u32,
    /// The start of an own slot left free because the channel ran behind before it.
    yield_slot: Option<u64>,
}

impl Schedule {
    /// A schedule for car `own`.
    pub fn new(own: CarId, timing: StateTiming) -> Self {
        Self::with_owner(Some(own), timing)
    }

    /// A schedule that only learns the cars' frame phase (ground station), following the
    /// lowest car ID heard; it sends nothing by itself.
    pub fn listener(latency_us: u32) -> Self {
        Self::with_owner(
            None,
            StateTiming::Slotted {
                slot: SLOTS - 1,
                time_base: TimeBase::FollowLowest { latency_us },
            },
        )
    }

    fn with_owner(own: Option<CarId>, timing: StateTiming) -> Self {
        Self {
            timing,
            own,
            epoch: 0,
            reference: None,
            locked: false,
            outliers: 0,
            dissent: 0,
            next_tx: None,
            last_tx: None,
            last_target: None,
            ref_frame: None,
            lead_x16: 0,
            yield_slot: None,
        }
    }

    /// The timing in use.
    pub fn timing(&self) -> StateTiming {
        self.timing
    }

    /// Whether the frame boundaries come from a tick or a lower car (false: free-running).
    pub fn is_locked(&self) -> bool {
        self.locked
    }

    /// Car followed for [`TimeBase::FollowLowest`].
    pub fn reference(&self) -> Option<CarId> {
        self.reference.map(|(id, _)| id)
    }

    fn adjust(&mut self, estimate: u64) {
        let e = phase_diff(estimate, self.epoch);
        if !self.locked {
            self.epoch = estimate;
            self.locked = true;
            self.outliers = 0;
        } else if e.unsigned_abs() > OUTLIER_US {
            // A late reference frame (deferred by CSMA) must not drag everybody along;
            // only a persistent shift is followed.
            self.outliers += 1;
            if self.outliers < OUTLIERS_TO_JUMP {
                return;
            }
            self.epoch = estimate;
            self.outliers = 0;
        } else {
            self.outliers = 0;
            self.epoch = (self.epoch as i64 + e / 2) as u64;
        }
        self.next_tx = None;
    }

    /// A shared tick (tracking frame) arrived at `now`.
    pub fn external_tick(&mut self, now: u64) {
        if let StateTiming::Slotted {
            time_base: TimeBase::External { offset_us },
            ..
        } = self.timing
        {
            self.adjust(now + u64::from(offset_us));
        }
    }

    /// A state broadcast from `src` with sequence number `seq` finished arriving at `now`.
    ///
    /// On a schedule that follows the lowest car, the frame of the slot three before this
    /// car's (the last to arrive before this car writes: a state frame reaches the other cars
    /// [`DEFAULT_STATE_LATENCY_US`], 2.3 slots, after its slot's start) arriving more than
    /// [`LATE_YIELD_US`] late means the channel is running behind: a broadcast written late,
    /// or one the radio deferred, pushes every later one back, and on a full channel (16 cars)
    /// the delay would not drain. This car's next slot is then marked ([`Schedule::yields`]);
    /// the endpoint leaves the broadcast out when every slot is taken, so the channel is free
    /// for one slot and catches up.
    pub fn heard_state(&mut self, now: u64, src: CarId, seq: u8, stale_after_us: u64) {
        self.note_late(now, src);
        self.follow(now, src, stale_after_us);
        if self.reference.map(|(r, _)| r) == Some(src) {
            let back =
                u64::from(self.latency_us()) + u64::from(default_slot(src)) * u64::from(SLOT_US);
            self.ref_frame = Some((seq, crate::sat_sub(now, back)));
        }
    }

    fn note_late(&mut self, now: u64, src: CarId) {
        let StateTiming::Slotted {
            slot,
            time_base: TimeBase::FollowLowest { latency_us },
        } = self.timing
        else {
            return;
        };
        if self.own.is_none() || !self.locked {
            return;
        }
        // Only the last frame to arrive before this car writes: from the slot as many slots
        // back as the pipeline is long, plus one.
        let back = latency_us / SLOT_US + 1;
        if (u32::from(slot % SLOTS) + u32::from(SLOTS) - u32::from(default_slot(src)))
            % u32::from(SLOTS)
            != back
        {
            return;
        }
        let mine = match self.next_tx {
            Some(t) if t > now => t,
            _ => self.next_slot_start(now),
        };
        // When that frame should have arrived (for this car's next slot's frame period).
        let expected = crate::sat_sub(mine + u64::from(latency_us), u64::from(back * SLOT_US));
        if now > expected + LATE_YIELD_US && mine > now + self.send_lead_us() {
            self.yield_slot = Some(mine);
        }
    }

    /// Whether the broadcast for the slot starting at `slot_start` is left out because the
    /// channel ran behind just before it (see [`Schedule::heard_state`]).
    pub fn yields(&self, slot_start: u64) -> bool {
        // The phase may have moved a little since (the frame that was late adjusts it).
        self.yield_slot
            .is_some_and(|y| y.abs_diff(slot_start) < u64::from(SLOT_US) / 2)
    }

    /// The slot start the broadcast due now aims at, once [`Schedule::next_due`] has set it.
    pub fn target(&self) -> Option<u64> {
        self.next_tx
    }

    fn latency_us(&self) -> u32 {
        match self.timing {
            StateTiming::Slotted {
                time_base: TimeBase::FollowLowest { latency_us },
                ..
            } => latency_us,
            _ => 0,
        }
    }

    /// The number of the frame whose slot 0 starts at `start` (see [`GROUND_FRAME_EVERY`]),
    /// from the reference's sequence numbers; `None` without a reference.
    pub fn frame_number(&self, start: u64) -> Option<u8> {
        let (seq, at) = self.ref_frame?;
        self.reference?;
        let f = i64::from(FRAME_US);
        let d = start as i64 - at as i64;
        let k = (d + d.signum() * f / 2) / f;
        Some(seq.wrapping_add(k as u8))
    }

    /// The start of the next ground frame's slot 0 at or after `from`, counting frames by
    /// the reference's sequence numbers (`None` without a reference or a phase).
    pub fn next_ground_frame(&self, from: u64) -> Option<u64> {
        let mut t = self.slot_start(0, from)?;
        for _ in 0..u32::from(GROUND_FRAME_EVERY) {
            if is_ground_frame(self.frame_number(t)?) {
                return Some(t);
            }
            t += u64::from(FRAME_US);
        }
        None
    }

    fn follow(&mut self, now: u64, src: CarId, stale_after_us: u64) {
        let StateTiming::Slotted {
            time_base: TimeBase::FollowLowest { latency_us },
            ..
        } = self.timing
        else {
            return;
        };
        let back = u64::from(latency_us) + u64::from(default_slot(src)) * u64::from(SLOT_US);
        let estimate = crate::sat_sub(now, back);
        if self.own.is_some_and(|own| src >= own) {
            self.root_vote(now, estimate, stale_after_us);
            return;
        }
        let current_ok = match self.reference {
            Some((r, heard)) => crate::sat_sub(now, heard) <= stale_after_us && r < src,
            None => false,
        };
        if current_ok {
            return;
        }
        let switched = self.reference.map(|(r, _)| r) != Some(src);
        self.reference = Some((src, now));
        if switched {
            self.locked = false;
        }
        self.adjust(estimate);
    }

    /// A car with no lower ID to follow (the root) still yields when every frame it hears
    /// disagrees with its phase: then it is the odd one out (e.g. its slot collides with a
    /// car that aligned to another root while this one was unheard).
    fn root_vote(&mut self, now: u64, estimate: u64, stale_after_us: u64) {
        let following = self
            .reference
            .is_some_and(|(_, heard)| crate::sat_sub(now, heard) <= stale_after_us);
        if following {
            return;
        }
        if !self.locked {
            self.epoch = estimate;
            self.locked = true;
            self.next_tx = None;
            return;
        }
        if phase_diff(estimate, self.epoch).unsigned_abs() <= OUTLIER_US {
            self.dissent = 0;
            return;
        }
        self.dissent += 1;
        if self.dissent >= ROOT_YIELD {
            self.dissent = 0;
            self.epoch = estimate;
            self.next_tx = None;
        }
    }

    /// Forget a reference that has not been heard for `stale_after_us` (keep free-running).
    pub fn expire(&mut self, now: u64, stale_after_us: u64) {
        if let Some((_, heard)) = self.reference {
            if crate::sat_sub(now, heard) > stale_after_us {
                self.reference = None;
            }
        }
    }

    /// The slot this schedule sends in (0 for periodic timing).
    pub fn own_slot(&self) -> u8 {
        match self.timing {
            StateTiming::Slotted { slot, .. } => slot % SLOTS,
            StateTiming::Periodic { .. } => 0,
        }
    }

    /// Earliest start of `slot` at or after `from`, once the frame phase is known.
    pub fn slot_start(&self, slot: u8, from: u64) -> Option<u64> {
        if !self.locked || matches!(self.timing, StateTiming::Periodic { .. }) {
            return None;
        }
        Some(self.slot_start_unchecked(slot, from))
    }

    fn next_slot_start(&self, from: u64) -> u64 {
        self.slot_start_unchecked(self.own_slot(), from)
    }

    // Out of line: used from every path that times a slot, and its 64-bit division is a
    // call and some twenty instructions at each place it would be inlined.
    #[inline(never)]
    fn slot_start_unchecked(&self, slot: u8, from: u64) -> u64 {
        let slot = u64::from(slot % SLOTS);
        let f = u64::from(FRAME_US);
        let base = self.epoch + slot * u64::from(SLOT_US);
        let k = if from > base {
            (from - base).div_ceil(f)
        } else {
            0
        };
        let mut t = base + k * f;
        // The epoch may lie ahead of `from` after an adjustment.
        while t >= from + f {
            t -= f;
        }
        t
    }

    /// When the next state broadcast is due (computed lazily from `now`): its slot's start,
    /// less the send lead.
    pub fn next_due(&mut self, now: u64) -> u64 {
        if let Some(t) = self.next_tx {
            return t.saturating_sub(self.send_lead_us());
        }
        let t = match self.timing {
            StateTiming::Periodic { period_us } => match self.last_tx {
                Some(l) => l + u64::from(period_us),
                None => now,
            },
            StateTiming::Slotted { .. } => {
                // At most one broadcast per frame, even when the epoch moved.
                let earliest = match self.last_tx {
                    Some(l) => (l + u64::from(FRAME_US) / 2).max(now),
                    None => now,
                };
                self.next_slot_start(earliest + self.send_lead_us())
            }
        };
        self.next_tx = Some(t);
        t.saturating_sub(self.send_lead_us())
    }

    /// The send lead: how long before its slot's start a broadcast is made due (see the
    /// module documentation), in microseconds.
    pub fn send_lead_us(&self) -> u64 {
        u64::from(self.lead_x16 >> 4)
    }

    /// The broadcast sent last started on the UART at `at`: learn the delay from its due
    /// time to the write.
    pub fn written(&mut self, at: u64) {
        let Some(target) = self.last_target.take() else {
            return;
        };
        if !matches!(self.timing, StateTiming::Slotted { .. }) {
            return;
        }
        // The write came `late` after the slot start it aimed at, with the current lead.
        let late = at as i64 - target as i64;
        let delay = (late + self.send_lead_us() as i64).clamp(0, i64::from(MAX_SEND_LEAD_US));
        let lead = i64::from(self.lead_x16);
        let next = lead + ((delay << 4) - lead) / (1 << LEAD_SHIFT);
        self.lead_x16 = next.clamp(0, i64::from(MAX_SEND_LEAD_US) << 4) as u32;
    }

    /// Time of the last broadcast.
    pub fn last_sent(&self) -> Option<u64> {
        self.last_tx
    }

    /// Record that a broadcast was sent at `now`.
    pub fn sent(&mut self, now: u64) {
        self.last_target = self.next_tx;
        self.last_tx = Some(now);
        self.next_tx = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(n: u8) -> CarId {
        CarId::new(n).unwrap()
    }

    #[test]
    fn slots_fit_a_state_frame() {
        // 16 bytes + 4 bytes of radio preamble at 86.8 us per byte.
        const { assert!(20 * 868 / 10 < SLOT_US) };
        assert_eq!(default_slot(id(1)), 0);
        assert_eq!(default_slot(id(17)), 0);
        assert_eq!(default_slot(id(16)), 15);
    }

    #[test]
    fn free_running_slot_times() {
        let mut s = Schedule::new(id(3), StateTiming::slotted(id(3)));
        let t0 = s.next_due(0);
        assert_eq!(t0, 2 * u64::from(SLOT_US));
        s.sent(t0);
        let t1 = s.next_due(t0 + 1);
        assert_eq!(t1, t0 + u64::from(FRAME_US));
    }

    #[test]
    fn follows_lowest_heard() {
        let mut s = Schedule::new(id(3), StateTiming::slotted(id(3)));
        // Car 2's frame (slot 1) arrives at 1_000_000: its slot began latency earlier.
        let rx = 1_000_000u64;
        s.heard_state(rx, id(2), 0, 1_000_000);
        assert_eq!(s.reference(), Some(id(2)));
        let slot1_start = rx - u64::from(DEFAULT_STATE_LATENCY_US);
        let due = s.next_due(rx);
        // Our slot (2) of that frame has passed: the next frame's.
        assert_eq!(due, slot1_start + u64::from(SLOT_US) + u64::from(FRAME_US));
        // A higher ID is ignored, a lower one takes over.
        s.heard_state(rx + 10, id(5), 0, 1_000_000);
        assert_eq!(s.reference(), Some(id(2)));
        s.heard_state(rx + 20, id(1), 0, 1_000_000);
        assert_eq!(s.reference(), Some(id(1)));
    }

    #[test]
    fn root_yields_to_persistent_dissent_only() {
        let mut s = Schedule::new(id(1), StateTiming::slotted(id(1)));
        let f = u64::from(FRAME_US);
        let lat = u64::from(DEFAULT_STATE_LATENCY_US);
        // The first frame heard sets the phase of a car that has nobody to follow.
        let t0 = 10 * f + 4 * u64::from(SLOT_US) + lat + 5_000;
        s.heard_state(t0, id(5), 0, 1_000_000);
        assert!(s.is_locked());
        let epoch = t0 - lat - 4 * u64::from(SLOT_US);
        assert_eq!(s.next_due(t0) % f, epoch % f);
        // A few late frames are ignored.
        for k in 1..u64::from(ROOT_YIELD) {
            s.heard_state(t0 + k * f + 3_000, id(5), 0, 1_000_000);
        }
        // Car 6 (slot 5) agrees and resets the count.
        s.heard_state(t0 + 9 * f + u64::from(SLOT_US), id(6), 0, 1_000_000);
        assert_eq!(s.next_due(t0 + 9 * f) % f, epoch % f);
        // Persistent disagreement moves the root.
        for k in 10..10 + u64::from(ROOT_YIELD) {
            s.heard_state(t0 + k * f + 3_000, id(5), 0, 1_000_000);
        }
        assert_eq!(s.next_due(t0 + 20 * f) % f, (epoch + 3_000) % f);
    }

    #[test]
    fn a_late_frame_just_before_the_slot_leaves_the_slot_free() {
        let f = u64::from(FRAME_US);
        let slot = u64::from(SLOT_US);
        let lat = u64::from(DEFAULT_STATE_LATENCY_US);
        // Car 8 (slot 7) follows car 1, whose frame sets slot 0 of the frame at `epoch`.
        let epoch = 100 * f;
        let mut s = Schedule::new(id(8), StateTiming::slotted(id(8)));
        s.heard_state(epoch + lat, id(1), 0, 1_000_000);
        let mine = epoch + 7 * slot;
        assert_eq!(s.next_due(epoch + lat), mine);
        // Car 5 (slot 4, three before) on time, then 100 us late: nothing changes.
        for late in [0, 100] {
            s.heard_state(epoch + 4 * slot + lat + late, id(5), 0, 1_000_000);
            assert!(!s.yields(mine), "late by {late} us");
        }
        // 500 us late: the channel runs behind, the slot is left free (the target may move
        // by the phase's own small corrections).
        s.heard_state(epoch + 4 * slot + lat + 500, id(5), 0, 1_000_000);
        assert!(s.yields(mine));
        assert!(s.yields(mine + 10));
        // Only that slot: the next frame's is used again.
        assert!(!s.yields(mine + f));

        // A late frame from further back (car 2, slot 1) or from the slot just before (car 7,
        // heard after this car has written) does not count.
        let mut s = Schedule::new(id(8), StateTiming::slotted(id(8)));
        s.heard_state(epoch + lat, id(1), 0, 1_000_000);
        s.heard_state(epoch + slot + lat + 500, id(2), 0, 1_000_000);
        s.heard_state(epoch + 6 * slot + lat + 500, id(7), 0, 1_000_000);
        assert!(!s.yields(mine));
        assert!(!s.yields(mine + f));
    }

    #[test]
    fn a_car_yields_only_on_a_full_channel_and_counts_it() {
        use crate::{CarConfig, CarMac, CarState};
        let f = u64::from(FRAME_US);
        let slot = u64::from(SLOT_US);
        let lat = u64::from(DEFAULT_STATE_LATENCY_US);
        let epoch = 100 * f;
        let frame = |src: u8| {
            let mut buf = [0u8; 64];
            let n = crate::wire::Frame::State {
                src: id(src),
                seq: 0,
                state: CarState::default(),
            }
            .encode(&mut buf)
            .unwrap();
            buf[..n].to_vec()
        };
        // Car 8 hears `others` on time in the frame before, then car 1 and, 500 us late, car 5
        // (three slots before its own); the states it sends and leaves out in its slot.
        let run = |others: &[u8]| {
            let mut mac = CarMac::new(CarConfig::new(id(8)));
            mac.set_state(CarState::default());
            for &c in others {
                mac.push_rx(epoch - f + u64::from(c - 1) * slot + lat, &frame(c));
            }
            mac.push_rx(epoch + lat, &frame(1));
            mac.push_rx(epoch + 4 * slot + lat + 500, &frame(5));
            let due = mac.next_state_due(epoch + 4 * slot + lat + 500).unwrap();
            mac.poll(due);
            let in_slot = (mac.stats().states_sent, mac.stats().states_yielded);
            // The next frame's slot is used again.
            let due = mac.next_state_due(due + 1).unwrap();
            assert!(due > epoch + f);
            mac.poll(due);
            (in_slot, mac.stats().states_sent)
        };
        let all: Vec<u8> = (1..=16).filter(|&c| c != 8).collect();
        assert_eq!(
            run(&all),
            ((0, 1), 1),
            "full channel: the slot is left free"
        );
        // With a free slot the channel catches up by itself: the car sends as usual.
        let all_but_one: Vec<u8> = (1..=15).filter(|&c| c != 8).collect();
        assert_eq!(run(&all_but_one), ((1, 0), 2));
    }

    #[test]
    fn one_broadcast_per_frame_after_a_jump() {
        let timing = StateTiming::Slotted {
            slot: 3,
            time_base: TimeBase::External { offset_us: 0 },
        };
        let mut s = Schedule::new(id(4), timing);
        let t = s.next_due(10_000);
        s.sent(t);
        // Epoch jumps so that the next slot would come right away.
        s.external_tick(t + 100);
        let n = s.next_due(t + 100);
        assert!(n >= t + u64::from(FRAME_US) / 2);
    }

    #[test]
    fn listener_follows_lowest_and_reports_slots() {
        let mut s = Schedule::listener(DEFAULT_STATE_LATENCY_US);
        assert_eq!(s.slot_start(3, 0), None);
        let rx = 500_000u64;
        s.heard_state(rx, id(126), 0, 1_000_000);
        s.heard_state(rx + 10, id(7), 0, 1_000_000);
        assert_eq!(s.reference(), Some(id(7)));
        let slot6 = rx + 10 - u64::from(DEFAULT_STATE_LATENCY_US);
        let next = s.slot_start(7, rx + 10).unwrap();
        assert_eq!(next, slot6 + u64::from(SLOT_US) + u64::from(FRAME_US));
    }

    #[test]
    fn a_learned_send_lead_makes_writes_start_on_the_slot() {
        let mut s = Schedule::new(id(3), StateTiming::slotted(id(3)));
        let slot = 2 * u64::from(SLOT_US);
        let f = u64::from(FRAME_US);
        assert_eq!(s.next_due(0), slot);
        // The program always writes 240 us after it is due.
        let mut writes = Vec::new();
        for k in 0..40 {
            let due = s.next_due(k * f);
            s.sent(due);
            s.written(due + 240);
            writes.push((due + 240) as i64 - (slot + k * f) as i64);
        }
        assert_eq!(writes[0], 240);
        assert!(writes.last().unwrap().abs() <= 1, "{writes:?}");
        assert_eq!(s.send_lead_us(), 239);
        // A write reported without a send is ignored; an absurd delay is bounded.
        s.written(10);
        let due = s.next_due(40 * f);
        s.sent(due);
        s.written(due + 1_000_000);
        assert!(s.send_lead_us() <= u64::from(MAX_SEND_LEAD_US));
    }

    #[test]
    fn frames_are_numbered_by_the_reference_and_ground_frames_found() {
        let mut s = Schedule::new(id(5), StateTiming::slotted(id(5)));
        assert_eq!(s.next_ground_frame(0), None, "no reference yet");
        let f = u64::from(FRAME_US);
        let lat = u64::from(DEFAULT_STATE_LATENCY_US);
        // Car 1 (slot 0) sent sequence number 20 in the frame starting at 10 * f.
        s.heard_state(10 * f + lat, id(1), 20, 1_000_000);
        assert_eq!(s.frame_number(10 * f), Some(20));
        assert_eq!(s.frame_number(13 * f + 5), Some(23));
        assert_eq!(s.frame_number(9 * f - 7), Some(19));
        // Number 31 is the next ground frame: 11 frames on.
        assert_eq!(s.next_ground_frame(10 * f + 1), Some(21 * f));
        assert!(is_ground_frame(31) && is_ground_frame(63) && !is_ground_frame(32));
        // A car that is not the reference does not number frames.
        s.heard_state(10 * f + lat + 3 * u64::from(SLOT_US), id(4), 200, 1_000_000);
        assert_eq!(s.frame_number(10 * f), Some(20));
    }

    #[test]
    fn without_reports_the_lead_stays_zero() {
        let mut s = Schedule::new(id(5), StateTiming::slotted(id(5)));
        for k in 0..5 {
            let due = s.next_due(k * u64::from(FRAME_US));
            assert_eq!(due % u64::from(FRAME_US), 4 * u64::from(SLOT_US));
            s.sent(due);
        }
        assert_eq!(s.send_lead_us(), 0);
    }

    #[test]
    fn periodic_timing() {
        let mut s = Schedule::new(id(4), StateTiming::Periodic { period_us: 1000 });
        assert_eq!(s.next_due(50), 50);
        s.sent(50);
        assert_eq!(s.next_due(60), 1050);
    }

    #[test]
    fn phase_diff_wraps() {
        assert_eq!(phase_diff(10, 0), 10);
        assert_eq!(phase_diff(0, 10), -10);
        assert_eq!(phase_diff(u64::from(FRAME_US) + 5, 0), 5);
    }
}
