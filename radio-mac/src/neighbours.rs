//! Table of nodes heard recently: last-heard time, latest state, and the per-peer receive
//! state that makes requests execute exactly once (sequence window and reply cache).

use crate::addr::Address;
use crate::wire::{CarState, Heartbeat, Payload};
use heapless::Vec;

/// Neighbour-table capacity of a car.
pub const NEIGHBOURS: usize = 16;
/// Width of the per-peer duplicate window, in sequence numbers.
pub const DEDUP_WINDOW: u16 = 32;

/// Verdict of the duplicate window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SeqCheck {
    /// Not seen before.
    Fresh,
    /// Seen before (retransmission).
    Duplicate,
    /// Older than the window: cannot tell, treated as a duplicate.
    TooOld,
}

/// Sliding window over the last [`DEDUP_WINDOW`] request sequence numbers of one peer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SeqWindow {
    newest: u16,
    /// Bit i set: `newest - i` was seen.
    seen: u32,
}

impl SeqWindow {
    /// A window whose first entry is `seq`.
    pub const fn starting_at(seq: u16) -> Self {
        Self {
            newest: seq,
            seen: 1,
        }
    }

    /// Classify `seq` without marking it.
    pub fn check(&self, seq: u16) -> SeqCheck {
        let ahead = seq.wrapping_sub(self.newest) as i16;
        if ahead > 0 {
            return SeqCheck::Fresh;
        }
        let back = u32::from(ahead.unsigned_abs());
        if back >= u32::from(DEDUP_WINDOW) {
            SeqCheck::TooOld
        } else if self.seen & (1 << back) != 0 {
            SeqCheck::Duplicate
        } else {
            SeqCheck::Fresh
        }
    }

    /// Mark `seq` as seen.
    pub fn mark(&mut self, seq: u16) {
        let ahead = seq.wrapping_sub(self.newest) as i16;
        if ahead > 0 {
            let shift = ahead as u32;
            self.seen = if shift >= 32 { 0 } else { self.seen << shift };
            self.seen |= 1;
            self.newest = seq;
        } else {
            let back = u32::from(ahead.unsigned_abs());
            if back < u32::from(DEDUP_WINDOW) {
                self.seen |= 1 << back;
            }
        }
    }
}

/// The last reply sent to a peer, resent when its request is retransmitted.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CachedReply {
    /// Sequence (or counter low bits) answered.
    pub seq: u16,
    /// Reply tag.
    pub tag: u8,
    /// Reply bytes.
    pub payload: Payload,
}

/// One node heard on the radio.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Neighbour {
    /// Its address.
    pub addr: Address,
    /// Local time it was last heard (any valid frame), microseconds.
    pub last_heard: u64,
    /// Latest state broadcast and when it arrived.
    pub state: Option<(CarState, u64)>,
    /// Latest heartbeat.
    pub heartbeat: Option<Heartbeat>,
    /// State broadcasts received from it.
    pub states_heard: u32,
    /// Gaps in its state sequence (broadcasts missed).
    pub states_missed: u32,
    pub(crate) last_state_seq: Option<u8>,
    pub(crate) window: Option<SeqWindow>,
    pub(crate) pending: Option<u16>,
    pub(crate) reply: Option<CachedReply>,
    pub(crate) last_gseq: Option<u8>,
    /// Ground station: when it last sent this car a session opening.
    pub(crate) session_sent: Option<u64>,
}

impl Neighbour {
    fn new(addr: Address, now: u64) -> Self {
        Self {
            addr,
            last_heard: now,
            state: None,
            heartbeat: None,
            states_heard: 0,
            states_missed: 0,
            last_state_seq: None,
            session_sent: None,
            window: None,
            pending: None,
            reply: None,
            last_gseq: None,
        }
    }

    /// Whether it has been silent for more than `stale_after_us`.
    pub fn is_stale(&self, now: u64, stale_after_us: u64) -> bool {
        crate::sat_sub(now, self.last_heard) > stale_after_us
    }
}

/// Fixed-capacity neighbour table.
///
/// Lookups go through `keys`, the entries' address bytes side by side, which a car scans for
/// every frame it hears (hundreds a second in a full channel); the entries themselves are
/// large.
#[derive(Debug, Clone, Default)]
pub struct NeighbourTable<const N: usize> {
    entries: Vec<Neighbour, N>,
    /// `entries[k].addr.to_byte()` for every k.
    keys: Vec<u8, N>,
}

impl<const N: usize> NeighbourTable<N> {
    /// An empty table.
    pub const fn new() -> Self {
        Self {
            entries: Vec::new(),
            keys: Vec::new(),
        }
    }

    fn index(&self, addr: Address) -> Option<usize> {
        let key = addr.to_byte();
        self.keys.iter().position(|&k| k == key)
    }

    /// All entries, fresh or stale.
    pub fn iter(&self) -> impl Iterator<Item = &Neighbour> {
        self.entries.iter()
    }

    /// Entry of `addr`.
    pub fn get(&self, addr: Address) -> Option<&Neighbour> {
        self.entries.get(self.index(addr)?)
    }

    /// Number of entries heard within `stale_after_us`.
    pub fn fresh_count(&self, now: u64, stale_after_us: u64) -> usize {
        self.entries
            .iter()
            .filter(|n| !n.is_stale(now, stale_after_us))
            .count()
    }

    /// Entry of `addr`, created if absent; when full, the stalest stale entry is replaced.
    /// `None` when full of fresh entries.
    pub(crate) fn touch(
        &mut self,
        addr: Address,
        now: u64,
        stale_after_us: u64,
    ) -> Option<&mut Neighbour> {
        let idx = match self.index(addr) {
            Some(i) => i,
            None => {
                if self.entries.push(Neighbour::new(addr, now)).is_ok() {
                    // Same capacity as `entries`, so there is room.
                    let _ = self.keys.push(addr.to_byte());
                    self.entries.len() - 1
                } else {
                    let (i, oldest) = self
                        .entries
                        .iter_mut()
                        .enumerate()
                        .min_by_key(|(_, n)| n.last_heard)?;
                    if !oldest.is_stale(now, stale_after_us) {
                        return None;
                    }
                    *oldest = Neighbour::new(addr, now);
                    if let Some(k) = self.keys.get_mut(i) {
                        *k = addr.to_byte();
                    }
                    i
                }
            }
        };
        self.entries.get_mut(idx)
    }

    pub(crate) fn get_mut(&mut self, addr: Address) -> Option<&mut Neighbour> {
        let i = self.index(addr)?;
        self.entries.get_mut(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::addr::CarId;
    use proptest::prelude::*;

    fn car(n: u8) -> Address {
        Address::Car(CarId::new(n).unwrap())
    }

    #[test]
    fn window_basics() {
        let mut w = SeqWindow::starting_at(100);
        assert_eq!(w.check(100), SeqCheck::Duplicate);
        assert_eq!(w.check(101), SeqCheck::Fresh);
        w.mark(103);
        assert_eq!(w.check(101), SeqCheck::Fresh);
        assert_eq!(w.check(100), SeqCheck::Duplicate);
        w.mark(101);
        assert_eq!(w.check(101), SeqCheck::Duplicate);
        assert_eq!(w.check(103 - 32), SeqCheck::TooOld);
        // Wrap-around.
        let mut w = SeqWindow::starting_at(0xFFFF);
        assert_eq!(w.check(0), SeqCheck::Fresh);
        w.mark(0);
        assert_eq!(w.check(0xFFFF), SeqCheck::Duplicate);
    }

    proptest! {
        /// Any sequence of marks: every marked seq within the window is a duplicate.
        #[test]
        fn window_never_forgets_recent(start in any::<u16>(), steps in proptest::collection::vec(0u16..40, 1..50)) {
            let mut w = SeqWindow::starting_at(start);
            let mut marked = std::vec![start];
            let mut s = start;
            for st in steps {
                s = s.wrapping_add(st);
                w.mark(s);
                marked.push(s);
            }
            for m in marked {
                let back = w.newest.wrapping_sub(m);
                if back < DEDUP_WINDOW {
                    prop_assert_eq!(w.check(m), SeqCheck::Duplicate);
                }
            }
        }
    }

    proptest! {
        /// Lookups by address find the entry with that address, whatever was added and
        /// evicted before.
        #[test]
        fn lookups_find_the_entry_of_the_address(ops in proptest::collection::vec((0u8..12, 0u64..400), 1..80)) {
            let mut t = NeighbourTable::<4>::new();
            let mut now = 0;
            for (a, dt) in ops {
                now += dt;
                let addr = if a == 0 { Address::Ground } else { car(a) };
                if let Some(n) = t.touch(addr, now, 100) {
                    prop_assert_eq!(n.addr, addr);
                    n.last_heard = now;
                }
                for b in 0u8..12 {
                    let addr = if b == 0 { Address::Ground } else { car(b) };
                    let want = t.iter().find(|n| n.addr == addr).map(|n| n.addr);
                    prop_assert_eq!(t.get(addr).map(|n| n.addr), want);
                    prop_assert_eq!(t.get_mut(addr).map(|n| n.addr), want);
                }
            }
        }
    }

    #[test]
    fn table_evicts_only_stale() {
        let mut t = NeighbourTable::<2>::new();
        assert!(t.touch(car(1), 0, 100).is_some());
        assert!(t.touch(car(2), 50, 100).is_some());
        assert!(t.touch(car(3), 90, 100).is_none());
        assert!(t.touch(car(3), 150, 100).is_some());
        assert!(t.get(car(1)).is_none());
        assert!(t.get(car(2)).is_some());
        assert_eq!(t.fresh_count(150, 100), 2);
    }
}
