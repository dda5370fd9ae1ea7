//! Test mode: the firmware's behaviour until the real program exists, relied on by the QEMU
//! harness.
//!
//! - Every byte received on the LBC UART is echoed on the LBC UART, and every byte received
//!   on the radio UART on the radio UART: same order, nothing lost, nothing added.
//! - When bytes are waiting, the loop first computes for [`COMPUTE_WINDOW_US`] of CLINT time
//!   without touching the UARTs (a CRC over a buffer; received bytes pile up in the interrupt
//!   driven RX rings meanwhile), then drains both RX rings into the TX rings.
//! - Every [`TICK_PERIOD_US`] of CLINT time it logs `tick N mtime=T`, N counting from 1; the
//!   deadlines are absolute, so ticks do not drift.
//! - [`PANIC_MAGIC`] arriving on either UART makes it panic (after echoing what came first).
//! - With nothing to do it sleeps in WFI until a byte or the next tick.

use crc::{Crc, CRC_32_ISO_HDLC};
use ubc_app::firmware::board::{Board, Clock, Uart};
use ubc_app::magic::SequenceDetector;
use ubc_hal::cpu;

/// Length of one compute window, in microseconds.
pub const COMPUTE_WINDOW_US: u64 = 50_000;
/// Period of the tick log line, in microseconds.
pub const TICK_PERIOD_US: u64 = 1_000_000;
/// Byte sequence that requests a deliberate panic.
pub const PANIC_MAGIC: &[u8; 11] = b"!ubc-panic!";
/// Size of the buffer the compute window checksums.
const WORK_BUFFER: usize = 1024;
/// Longest wait for the echo to leave the UART before a requested panic.
const FLUSH_TIMEOUT_US: u64 = 200_000;
/// Bytes moved per drain step.
const DRAIN_CHUNK: usize = 64;

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Runs the test mode forever.
pub fn run(board: Board) -> ! {
    let clock = board.clock;
    let mut lbc = Echo::new("lbc", board.lbc);
    let mut radio = board.radio.ok().map(|port| Echo::new("radio", port));
    let mut ticker = Ticker::new(&clock);
    let mut work = Workload::new();
    loop {
        let deadline = ticker.next;
        clock.set_wakeup(deadline);
        cpu::idle_unless(|| {
            lbc.waiting() || radio.as_ref().is_some_and(Echo::waiting) || clock.ticks() >= deadline
        });
        ticker.poll(&clock);
        if lbc.waiting() || radio.as_ref().is_some_and(Echo::waiting) {
            let end = clock.ticks() + clock.ticks_from_micros(COMPUTE_WINDOW_US);
            while clock.ticks() < end {
                work.step();
                ticker.poll(&clock);
            }
            lbc.drain(&clock);
            ticker.poll(&clock);
            if let Some(radio) = radio.as_mut() {
                radio.drain(&clock);
            }
        }
    }
}

/// Logs a tick line whenever an absolute one-second deadline has passed.
struct Ticker {
    next: u64,
    period: u64,
    count: u32,
}

impl Ticker {
    fn new(clock: &Clock) -> Self {
        let period = clock.ticks_from_micros(TICK_PERIOD_US);
        Self {
            next: clock.ticks() + period,
            period,
            count: 0,
        }
    }

    fn poll(&mut self, clock: &Clock) {
        let now = clock.ticks();
        if now >= self.next {
            self.count = self.count.wrapping_add(1);
            defmt::info!("tick {=u32} mtime={=u64}", self.count, now);
            self.next += self.period;
        }
    }
}

/// Echoes one UART and watches it for [`PANIC_MAGIC`].
struct Echo {
    name: &'static str,
    port: Uart,
    panic_request: SequenceDetector,
}

impl Echo {
    fn new(name: &'static str, port: Uart) -> Self {
        Self {
            name,
            port,
            panic_request: SequenceDetector::new(PANIC_MAGIC),
        }
    }

    /// Bytes wait in the RX ring and the TX ring has room to echo them.
    fn waiting(&self) -> bool {
        self.port.rx_len() > 0 && self.port.tx_free() > 0
    }

    /// Moves what the RX ring holds into the TX ring, as far as the TX ring has room; never
    /// waits, so a host that stops reading holds back its own input instead of stalling
    /// the loop (the RX ring fills, then the receiver is held).
    fn drain(&mut self, clock: &Clock) {
        let mut buf = [0u8; DRAIN_CHUNK];
        let mut budget = self.port.rx_len().min(self.port.tx_free());
        while budget > 0 {
            let n = self
                .port
                .read_available(&mut buf[..budget.min(DRAIN_CHUNK)]);
            if n == 0 {
                return;
            }
            budget -= n;
            if let Some(last) = self.panic_request.find(&buf[..n]) {
                self.port.write_available(&buf[..=last]);
                self.flush(clock);
                panic!("deliberate panic requested on {} uart", self.name);
            }
            self.port.write_available(&buf[..n]);
        }
    }

    /// Waits until the echo has left the UART, or [`FLUSH_TIMEOUT_US`] passed.
    fn flush(&mut self, clock: &Clock) {
        let deadline = clock.ticks() + clock.ticks_from_micros(FLUSH_TIMEOUT_US);
        clock.set_wakeup(deadline);
        while !self.port.tx_idle() && clock.ticks() < deadline {
            if self.port.tx_len() > 0 {
                // The TX interrupt ends this sleep.
                cpu::idle_unless(|| self.port.tx_len() == 0 || clock.ticks() >= deadline);
            } else {
                // The last FIFO load drains without another interrupt.
                core::hint::spin_loop();
            }
        }
    }
}

/// Stand-in for real work: CRC-32 over a buffer that is rewritten with each result, so no
/// step can be skipped or hoisted.
struct Workload {
    buffer: [u8; WORK_BUFFER],
    digest: u32,
}

impl Workload {
    fn new() -> Self {
        let mut buffer = [0u8; WORK_BUFFER];
        for (i, b) in buffer.iter_mut().enumerate() {
            *b = (i as u8).wrapping_mul(31).wrapping_add(7);
        }
        Self { buffer, digest: 0 }
    }

    fn step(&mut self) {
        self.digest = core::hint::black_box(CRC32.checksum(&self.buffer));
        let at = (self.digest as usize) % (WORK_BUFFER - 4);
        self.buffer[at..at + 4].copy_from_slice(&self.digest.to_le_bytes());
    }
}
