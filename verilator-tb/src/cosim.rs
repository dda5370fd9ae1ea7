//! The SoC and an emulated lower board (`lbc-emu`'s sans-IO [`Lbc`]) on one timeline. The SoC
//! clock is the master: every byte the SoC's LBC UART finishes sending reaches the emulator at
//! that cycle's time, and every byte the emulator sends arrives at the SoC's receiver at the
//! time the emulator says it left its UART. The two advance in slices shorter than a character
//! time, so neither sees the other late by more than a fraction of a byte.

use crate::soc::{Event, Soc, Stamped, Uart, CHAR_CYCLES, CLOCK_HZ};
use lbc_emu::Lbc;

/// Longest run of SoC cycles between two exchanges with the emulator.
pub const SLICE_CYCLES: u64 = CHAR_CYCLES / 2;

/// Converts a SoC cycle count to microseconds.
pub fn cycles_to_us(cycles: u64) -> u64 {
    cycles * 1_000_000 / u64::from(CLOCK_HZ)
}

/// Converts microseconds to the first SoC cycle at or after that time.
pub fn us_to_cycles(us: u64) -> u64 {
    (us * u64::from(CLOCK_HZ)).div_ceil(1_000_000)
}

/// A SoC wired to an emulated LBC.
#[derive(Debug)]
pub struct LbcCosim {
    /// The SoC (released from reset by [`LbcCosim::new`]).
    pub soc: Soc,
    /// The emulated lower board.
    pub lbc: Lbc,
}

impl LbcCosim {
    /// Connects a loaded SoC to `lbc` and releases the SoC from reset.
    pub fn new(mut soc: Soc, lbc: Lbc) -> Self {
        soc.release();
        Self { soc, lbc }
    }

    /// Runs for `cycles` SoC cycles or until the program exits; returns the SoC's events (LBC
    /// traffic included, in both directions as `Tx` from the SoC only).
    pub fn run(&mut self, cycles: u64) -> Vec<Stamped<Event>> {
        let end = self.soc.cycle() + cycles;
        let mut out = Vec::new();
        while self.soc.cycle() < end {
            let slice_end = (self.soc.cycle() + SLICE_CYCLES).min(end);
            let events = self.soc.run(slice_end - self.soc.cycle());
            let mut exited = false;
            for e in &events {
                match e.value {
                    Event::Tx {
                        uart: Uart::Lbc,
                        byte,
                    } => {
                        self.lbc.push_rx(cycles_to_us(e.cycle), &[byte]);
                    }
                    Event::Exit(_) => exited = true,
                    _ => {}
                }
            }
            out.extend(events);
            let now_us = cycles_to_us(self.soc.cycle());
            self.lbc.step_until(now_us);
            while let Some((t_us, byte)) = self.lbc.pop_tx(now_us) {
                self.soc.send_at(Uart::Lbc, us_to_cycles(t_us), &[byte]);
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
