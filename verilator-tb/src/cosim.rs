//! The SoC, an emulated lower board (`lbc-emu`'s sans-IO [`Lbc`]) on its LBC UART and an
//! optional byte peer on its radio UART, on one timeline. The SoC clock is the master: every
//! byte a SoC UART finishes sending reaches its peer at that cycle's time, and every byte a
//! peer sends arrives at the SoC's receiver at the time the peer says it left, paced one
//! character time apart (115200 baud, 8N1) like a real line. The parties advance in slices
//! shorter than a character time, so none sees another late by more than a fraction of a byte.

use crate::golden::Retire;
use crate::lockstep::{Checker, Mismatch};
use crate::soc::{Event, Soc, Stamped, Uart, CHAR_CYCLES, CLOCK_HZ};
use lbc_emu::Lbc;
use std::collections::VecDeque;

/// Longest run of SoC cycles between two exchanges with the peers.
pub const SLICE_CYCLES: u64 = CHAR_CYCLES / 2;

/// Converts a SoC cycle count to microseconds.
pub fn cycles_to_us(cycles: u64) -> u64 {
    cycles * 1_000_000 / u64::from(CLOCK_HZ)
}

/// Converts microseconds to the first SoC cycle at or after that time.
pub fn us_to_cycles(us: u64) -> u64 {
    (us * u64::from(CLOCK_HZ)).div_ceil(1_000_000)
}

/// The far end of a SoC UART: a sans-IO byte sink and source on the simulated timeline.
pub trait SerialPeer {
    /// A byte the SoC finished sending (its stop bit ended) at `t_us`.
    fn receive(&mut self, t_us: u64, byte: u8);
    /// Advances the peer to `now_us` and appends the bytes it sends, each with the time it
    /// leaves (times may lie in the past; the SoC's line then takes them as soon as it can).
    fn advance(&mut self, now_us: u64, out: &mut Vec<(u64, u8)>);
}

impl SerialPeer for Lbc {
    fn receive(&mut self, t_us: u64, byte: u8) {
        self.push_rx(t_us, &[byte]);
    }

    fn advance(&mut self, now_us: u64, out: &mut Vec<(u64, u8)>) {
        self.step_until(now_us);
        while let Some(tx) = self.pop_tx(now_us) {
            out.push(tx);
        }
    }
}

/// A plain byte sink and source: records what the SoC sends, sends what is queued once its
/// time has come.
#[derive(Debug, Default, Clone)]
pub struct BytePeer {
    /// Every byte received from the SoC with its time in microseconds.
    pub received: Vec<(u64, u8)>,
    /// Bytes to send, each no earlier than its time in microseconds.
    pub to_send: VecDeque<(u64, u8)>,
}

impl BytePeer {
    /// Queues `bytes` to leave no earlier than `t_us`.
    pub fn send_at(&mut self, t_us: u64, bytes: &[u8]) {
        self.to_send.extend(bytes.iter().map(|&b| (t_us, b)));
    }
}

impl SerialPeer for BytePeer {
    fn receive(&mut self, t_us: u64, byte: u8) {
        self.received.push((t_us, byte));
    }

    fn advance(&mut self, now_us: u64, out: &mut Vec<(u64, u8)>) {
        while let Some(&(t, b)) = self.to_send.front() {
            if t > now_us {
                break;
            }
            self.to_send.pop_front();
            out.push((t, b));
        }
    }
}

/// A SoC wired to an emulated LBC and, optionally, a radio peer.
pub struct LbcCosim {
    /// The SoC (released from reset by [`LbcCosim::new`]).
    pub soc: Soc,
    /// The emulated lower board.
    pub lbc: Lbc,
    /// The peer on the radio UART; without one, the radio's output is dropped.
    pub radio: Option<Box<dyn SerialPeer>>,
    checker: Option<Checker>,
    mismatch: Option<Mismatch>,
    scratch: Vec<(u64, u8)>,
    keep_records: bool,
    records: Vec<(u64, Retire)>,
}

impl core::fmt::Debug for LbcCosim {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LbcCosim")
            .field("soc", &self.soc)
            .field("lbc_now_us", &self.lbc.now_us())
            .field("radio", &self.radio.is_some())
            .finish()
    }
}

impl LbcCosim {
    /// Connects a loaded SoC to `lbc` and releases the SoC from reset.
    pub fn new(mut soc: Soc, lbc: Lbc) -> Self {
        soc.release();
        Self {
            soc,
            lbc,
            radio: None,
            checker: None,
            mismatch: None,
            scratch: Vec::new(),
            keep_records: false,
            records: Vec::new(),
        }
    }

    /// Checks every instruction the SoC retires against the golden model (`checker` must hold
    /// the same image as the SoC). A run stops at the first mismatch; see
    /// [`LbcCosim::mismatch`].
    pub fn with_checker(mut self, checker: Checker) -> Self {
        self.checker = Some(checker);
        self
    }

    /// Keeps every retirement record with its cycle stamp (see [`LbcCosim::records`]).
    pub fn with_records(mut self) -> Self {
        self.keep_records = true;
        self
    }

    /// The records kept so far (with [`LbcCosim::with_records`]).
    pub fn records(&self) -> &[(u64, Retire)] {
        &self.records
    }

    /// The first disagreement between the RTL and the golden model, if checking found one.
    pub fn mismatch(&self) -> Option<&Mismatch> {
        self.mismatch.as_ref()
    }

    /// Instructions checked against the golden model so far (0 without a checker).
    pub fn checked(&self) -> u64 {
        self.checker.as_ref().map_or(0, Checker::checked)
    }

    /// Attaches `peer` to the radio UART (UART1).
    pub fn with_radio(mut self, peer: Box<dyn SerialPeer>) -> Self {
        self.radio = Some(peer);
        self
    }

    /// Simulated time in microseconds.
    pub fn now_us(&self) -> u64 {
        cycles_to_us(self.soc.cycle())
    }

    /// Runs for `cycles` SoC cycles or until the program exits (or, with a checker, the RTL
    /// and the model disagree); returns the SoC's events (the bytes it sent on both UARTs
    /// included).
    pub fn run(&mut self, cycles: u64) -> Vec<Stamped<Event>> {
        let end = self.soc.cycle() + cycles;
        let mut out = Vec::new();
        while self.soc.cycle() < end && self.mismatch.is_none() {
            let slice_end = (self.soc.cycle() + SLICE_CYCLES).min(end);
            let rvfi = self.checker.is_some() || self.keep_records;
            let (records, events) = self.soc.batch(slice_end - self.soc.cycle(), rvfi, false);
            if self.keep_records {
                self.records
                    .extend(records.iter().map(|r| (r.cycle, r.retire)));
            }
            if let Some(checker) = self.checker.as_mut() {
                for rec in &records {
                    if let Err(m) = checker.check(rec) {
                        self.mismatch = Some(m);
                        break;
                    }
                }
            }
            let mut exited = false;
            for e in &events {
                match e.value {
                    Event::Tx {
                        uart: Uart::Lbc,
                        byte,
                    } => self.lbc.receive(cycles_to_us(e.cycle), byte),
                    Event::Tx {
                        uart: Uart::Radio,
                        byte,
                    } => {
                        if let Some(r) = self.radio.as_mut() {
                            r.receive(cycles_to_us(e.cycle), byte);
                        }
                    }
                    Event::Exit(_) => exited = true,
                    Event::Console(_) => {}
                }
            }
            out.extend(events);
            let now_us = cycles_to_us(self.soc.cycle());
            self.scratch.clear();
            self.lbc.advance(now_us, &mut self.scratch);
            for &(t_us, byte) in &self.scratch {
                self.soc.send_at(Uart::Lbc, us_to_cycles(t_us), &[byte]);
            }
            if let Some(r) = self.radio.as_mut() {
                self.scratch.clear();
                r.advance(now_us, &mut self.scratch);
                for &(t_us, byte) in &self.scratch {
                    self.soc.send_at(Uart::Radio, us_to_cycles(t_us), &[byte]);
                }
            }
            if exited {
                break;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_conversions_agree() {
        assert_eq!(cycles_to_us(u64::from(CLOCK_HZ)), 1_000_000);
        assert_eq!(us_to_cycles(1_000_000), u64::from(CLOCK_HZ));
        for us in [0, 1, 87, 1_000, 123_456_789] {
            let c = us_to_cycles(us);
            assert_eq!(cycles_to_us(c), us, "{us} us");
        }
    }
}
