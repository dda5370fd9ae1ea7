//! Interrupt-driven serial port on a 16550: RX and TX rings (single-producer single-consumer,
//! [`crate::ring`]) shared between the interrupt handler and the program.
//!
//! The RX interrupt moves bytes from the device FIFO into the RX ring. When the ring is full
//! the handler stops taking bytes and masks the RX interrupt instead of dropping them; the
//! program unmasks it once it has drained some space. The device FIFO then holds the rest
//! (under QEMU the character backend waits; on hardware the FIFO overruns, which the overrun
//! counter records). TX is interrupt driven too: the program fills the TX ring and unmasks
//! the THR-empty interrupt; the handler refills the 16-byte FIFO and masks it again once the
//! ring is empty.
//!
//! Sizing: at 115200 baud 8N1 a byte takes 86.8 us, so 50 ms of work without draining lets
//! 576 bytes arrive; [`RX_RING_SIZE`] leaves room for 7 such periods.
//!
//! Frame ends: a port can be told which byte ends a frame on its line ([`FrameStamping`]).
//! The handler then notes when each such byte arrived on the line, in timer ticks, worked
//! back from the moment it runs: the interrupt at the FIFO's trigger level comes as the last
//! byte arrives, the receive timeout four character times after it, and bytes in one batch
//! arrived back to back. [`Port::read_frame`] hands out a frame with that time, and
//! [`Port::frame_end_pending`] tells the program that a whole frame waits, so it can sleep
//! through the interrupts in between.

use crate::cpu;
use crate::mmio::RegisterBus;
use crate::ring::{Consumer, Producer, Ring};
use crate::uart::{Config, ConfigError, Ier, IrqId, Ns16550, FIFO_DEPTH};
use core::cell::{RefCell, UnsafeCell};
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use critical_section::Mutex;

/// Bytes each port's RX ring holds.
pub const RX_RING_SIZE: usize = 4096;
/// Bytes each port's TX ring holds. Half the RX ring: the
/// program writes short messages, and 2 KiB still drains faster than the line (115200 baud
/// moves 576 bytes in a 50 ms compute window).
pub const TX_RING_SIZE: usize = 2048;
/// Free RX ring space at which a held receiver is resumed.
pub const RX_RESUME_SPACE: usize = 4 * FIFO_DEPTH;
/// Bound on interrupt service rounds per interrupt, so a misbehaving device cannot hang it.
const MAX_SERVICE_ROUNDS: usize = 8;
/// Frame ends remembered per port until the program reads them; the ends of frames beyond
/// that are not stamped ([`Port::read_frame`] then says so).
pub const FRAME_END_SLOTS: usize = 32;
/// Frame ends stamped in one service round (a FIFO's worth of bytes); more are not stamped.
const ENDS_PER_ROUND: usize = 4;
/// Character times of silence after which a 16550 raises its receive timeout.
const RX_TIMEOUT_CHARS: u32 = 4;

/// How a port's handler stamps the ends of frames.
#[derive(Debug, Clone, Copy)]
pub struct FrameStamping {
    /// The byte that ends a frame on this line (0x00 for COBS, 0xFF for the LBC protocol).
    pub delimiter: u8,
    /// Reads the low 32 bits of the free-running timer.
    pub now: fn() -> u32,
    /// Timer ticks one character (start, 8 data bits, stop) takes on the line.
    pub char_ticks: u32,
}

/// A frame end seen by the handler: the delimiter's position in the port's byte count and
/// the timer tick at which it arrived.
#[derive(Debug, Clone, Copy)]
struct FrameEnd {
    pos: u32,
    tick: u32,
}

/// Errors reported to readers of a [`Port`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SerialError {
    /// The device FIFO overflowed since the last read: bytes were lost on the line.
    Overrun,
}

impl core::fmt::Display for SerialError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Overrun => f.write_str("receiver overrun: bytes were lost"),
        }
    }
}

impl core::error::Error for SerialError {}

impl embedded_io::Error for SerialError {
    fn kind(&self) -> embedded_io::ErrorKind {
        embedded_io::ErrorKind::Other
    }
}

impl embedded_hal_nb::serial::Error for SerialError {
    fn kind(&self) -> embedded_hal_nb::serial::ErrorKind {
        match self {
            Self::Overrun => embedded_hal_nb::serial::ErrorKind::Overrun,
        }
    }
}

/// Why a port cannot be opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum OpenError {
    /// The port's state was already handed out.
    AlreadyOpen,
    /// The line settings cannot be applied.
    Config(ConfigError),
}

impl From<ConfigError> for OpenError {
    fn from(e: ConfigError) -> Self {
        Self::Config(e)
    }
}

/// Counters kept by the interrupt handler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    /// Bytes moved into the RX ring.
    pub rx_bytes: u32,
    /// Bytes written to the device from the TX ring.
    pub tx_bytes: u32,
    /// Device FIFO overruns seen in LSR (bytes lost on the line).
    pub overruns: u32,
    /// Parity, framing or break conditions seen in LSR.
    pub line_errors: u32,
    /// Times the RX ring was full and the receiver was held.
    pub rx_ring_full: u32,
}

#[derive(Debug, Default)]
struct Counters {
    rx_bytes: AtomicU32,
    tx_bytes: AtomicU32,
    overruns: AtomicU32,
    line_errors: AtomicU32,
    rx_ring_full: AtomicU32,
}

fn bump(counter: &AtomicU32, by: u32) {
    counter.fetch_add(by, Ordering::Relaxed);
}

/// What the interrupt handler owns: the device and the ring ends it serves.
struct IsrHalf<B: 'static> {
    uart: Ns16550<B>,
    ier: Ier,
    rx: Producer<u8, RX_RING_SIZE>,
    tx: Consumer<u8, TX_RING_SIZE>,
    ends: Producer<FrameEnd, FRAME_END_SLOTS>,
    stamping: Option<FrameStamping>,
    /// Bytes moved into the RX ring so far (wrapping): the position of the next one.
    rx_pos: u32,
}

/// The static state of one interrupt-driven port. Place it in a `static`, then
/// [`PortState::open`] it once and call [`PortState::on_interrupt`] from its interrupt.
pub struct PortState<B: 'static> {
    rx: UnsafeCell<Ring<u8, RX_RING_SIZE>>,
    tx: UnsafeCell<Ring<u8, TX_RING_SIZE>>,
    ends: UnsafeCell<Ring<FrameEnd, FRAME_END_SLOTS>>,
    /// One past the position of the last frame delimiter received (0: none yet).
    end_mark: AtomicU32,
    taken: AtomicBool,
    isr: Mutex<RefCell<Option<IsrHalf<B>>>>,
    rx_held: AtomicBool,
    overrun_pending: AtomicBool,
    counters: Counters,
}

// SAFETY: the rings in the `UnsafeCell`s (bytes and frame ends) are only reached through the
// producer/consumer halves that `open` creates exactly once (guarded by `taken`); the SPSC
// halves are designed to be used from two contexts at once. Everything else is atomics or behind a
// critical-section mutex.
unsafe impl<B: Send> Sync for PortState<B> {}

impl<B> core::fmt::Debug for PortState<B> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("PortState")
            .field("taken", &self.taken.load(Ordering::Relaxed))
            .field("rx_held", &self.rx_held.load(Ordering::Relaxed))
            .field("counters", &self.counters)
            .finish_non_exhaustive()
    }
}

impl<B: RegisterBus + Send + 'static> Default for PortState<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<B: RegisterBus + Send + 'static> PortState<B> {
    /// An unopened port.
    pub const fn new() -> Self {
        Self {
            rx: UnsafeCell::new(Ring::new(0)),
            tx: UnsafeCell::new(Ring::new(0)),
            ends: UnsafeCell::new(Ring::new(FrameEnd { pos: 0, tick: 0 })),
            end_mark: AtomicU32::new(0),
            taken: AtomicBool::new(false),
            isr: Mutex::new(RefCell::new(None)),
            rx_held: AtomicBool::new(false),
            overrun_pending: AtomicBool::new(false),
            counters: Counters {
                rx_bytes: AtomicU32::new(0),
                tx_bytes: AtomicU32::new(0),
                overruns: AtomicU32::new(0),
                line_errors: AtomicU32::new(0),
                rx_ring_full: AtomicU32::new(0),
            },
        }
    }

    /// Initialises the UART, splits the rings between the interrupt handler and the returned
    /// [`Port`], and enables the RX and line-status interrupts in the device. The interrupt
    /// controller and the hart still have to route the device's interrupt here.
    pub fn open(&'static self, uart: Ns16550<B>, config: &Config) -> Result<Port<B>, OpenError> {
        if self.taken.swap(true, Ordering::AcqRel) {
            return Err(OpenError::AlreadyOpen);
        }
        if let Err(e) = uart.init(config) {
            self.taken.store(false, Ordering::Release);
            return Err(e.into());
        }
        // SAFETY: `taken` was false, so this is the only time these `&mut` are created, and
        // nothing else reaches the queues except through the halves made here.
        let (rx_prod, rx_cons) = unsafe { &mut *self.rx.get() }.split();
        // SAFETY: as above.
        let (tx_prod, tx_cons) = unsafe { &mut *self.tx.get() }.split();
        // SAFETY: as above.
        let (ends_prod, ends_cons) = unsafe { &mut *self.ends.get() }.split();
        let mut ier = Ier(0);
        ier.set_rx_available(true);
        ier.set_line_status(true);
        uart.set_ier(ier);
        // Borrows of the interrupt half live only inside critical sections, so this one is
        // never refused; if it were, the port would not work, so say so instead of going on.
        let installed = critical_section::with(|cs| {
            let Ok(mut isr) = self.isr.borrow(cs).try_borrow_mut() else {
                return false;
            };
            *isr = Some(IsrHalf {
                uart,
                ier,
                rx: rx_prod,
                tx: tx_cons,
                ends: ends_prod,
                stamping: None,
                rx_pos: 0,
            });
            true
        });
        if !installed {
            return Err(OpenError::AlreadyOpen);
        }
        Ok(Port {
            state: self,
            rx: rx_cons,
            tx: tx_prod,
            ends: ends_cons,
            delimiter: None,
            read_pos: 0,
        })
    }

    /// Interrupt service: moves received bytes into the RX ring and queued bytes into the TX
    /// FIFO, and records line errors. Call it from the handler of this UART's interrupt.
    pub fn on_interrupt(&self) {
        critical_section::with(|cs| {
            let Ok(mut isr) = self.isr.borrow(cs).try_borrow_mut() else {
                return;
            };
            let Some(h) = isr.as_mut() else {
                return;
            };
            for _ in 0..MAX_SERVICE_ROUNDS {
                let Some(cause) = h.uart.iir().pending() else {
                    break;
                };
                let _ = h.uart.msr();
                self.service_rx(h, cause == IrqId::RxTimeout);
                self.service_tx(h);
            }
        });
    }

    /// Moves the FIFO's bytes into the ring; `timed_out` when the receive timeout (not the
    /// trigger level) raised the interrupt.
    fn service_rx(&self, h: &mut IsrHalf<B>, timed_out: bool) {
        if !h.ier.rx_available() {
            // Held: only record line errors.
            self.record_line_status(h.uart.lsr());
            return;
        }
        let delimiter = h.stamping.map(|s| s.delimiter);
        let mut ends = [0u32; ENDS_PER_ROUND];
        let mut n_ends = 0;
        let mut taken: u32 = 0;
        // The bytes go into the ring a FIFO's worth at a time, in one pass each.
        let mut batch = [0u8; FIFO_DEPTH];
        let mut room = h.rx.room();
        loop {
            let mut n = 0;
            let mut more = false;
            while n < batch.len() {
                let lsr = h.uart.lsr();
                self.record_line_status(lsr);
                if !lsr.data_ready() {
                    break;
                }
                if n >= room {
                    more = true;
                    break;
                }
                let byte = h.uart.read_rbr();
                if let Some(slot) = batch.get_mut(n) {
                    *slot = byte;
                }
                if Some(byte) == delimiter {
                    if let Some(slot) = ends.get_mut(n_ends) {
                        *slot = taken + n as u32;
                        n_ends += 1;
                    }
                }
                n += 1;
            }
            // There is room for them (checked above), so all go in.
            let put = h.rx.enqueue_slice(batch.get(..n).unwrap_or_default());
            taken += put as u32;
            room -= put;
            if more {
                h.ier.set_rx_available(false);
                h.uart.set_ier(h.ier);
                self.rx_held.store(true, Ordering::Release);
                bump(&self.counters.rx_ring_full, 1);
                break;
            }
            if n < batch.len() {
                break;
            }
        }
        if let (Some(s), Some(last)) = (h.stamping, ends.get(..n_ends).and_then(|e| e.last())) {
            // The last byte taken arrived now (trigger level) or one timeout ago.
            let now = (s.now)();
            let newest = if timed_out {
                now.wrapping_sub(RX_TIMEOUT_CHARS.wrapping_mul(s.char_ticks))
            } else {
                now
            };
            for &k in ends.get(..n_ends).unwrap_or_default() {
                let before = taken - 1 - k;
                let _ = h.ends.enqueue(FrameEnd {
                    pos: h.rx_pos.wrapping_add(k),
                    tick: newest.wrapping_sub(before.wrapping_mul(s.char_ticks)),
                });
            }
            self.end_mark.store(
                h.rx_pos.wrapping_add(*last).wrapping_add(1),
                Ordering::Release,
            );
        }
        h.rx_pos = h.rx_pos.wrapping_add(taken);
        bump(&self.counters.rx_bytes, taken);
    }

    fn record_line_status(&self, lsr: crate::uart::Lsr) {
        if lsr.overrun() {
            bump(&self.counters.overruns, 1);
            self.overrun_pending.store(true, Ordering::Release);
        }
        if lsr.parity_error() || lsr.framing_error() || lsr.break_interrupt() {
            bump(&self.counters.line_errors, 1);
        }
    }

    fn service_tx(&self, h: &mut IsrHalf<B>) {
        if !h.ier.thr_empty() || !h.uart.lsr().thr_empty() {
            return;
        }
        let mut sent = 0;
        while sent < FIFO_DEPTH as u32 {
            let Some(byte) = h.tx.dequeue() else {
                break;
            };
            h.uart.write_thr(byte);
            sent += 1;
        }
        bump(&self.counters.tx_bytes, sent);
        if !h.tx.ready() {
            h.ier.set_thr_empty(false);
            h.uart.set_ier(h.ier);
        }
    }

    /// A snapshot of the counters.
    pub fn stats(&self) -> Stats {
        let c = &self.counters;
        Stats {
            rx_bytes: c.rx_bytes.load(Ordering::Relaxed),
            tx_bytes: c.tx_bytes.load(Ordering::Relaxed),
            overruns: c.overruns.load(Ordering::Relaxed),
            line_errors: c.line_errors.load(Ordering::Relaxed),
            rx_ring_full: c.rx_ring_full.load(Ordering::Relaxed),
        }
    }

    fn with_isr<R>(&self, f: impl FnOnce(&mut IsrHalf<B>) -> R) -> Option<R> {
        critical_section::with(|cs| {
            let mut isr = self.isr.borrow(cs).try_borrow_mut().ok()?;
            isr.as_mut().map(f)
        })
    }
}

/// The program's end of an interrupt-driven port: reads from the RX ring, writes to the TX
/// ring. Implements embedded-io and embedded-hal-nb serial traits.
pub struct Port<B: 'static> {
    state: &'static PortState<B>,
    rx: Consumer<u8, RX_RING_SIZE>,
    tx: Producer<u8, TX_RING_SIZE>,
    ends: Consumer<FrameEnd, FRAME_END_SLOTS>,
    delimiter: Option<u8>,
    /// Bytes taken from the RX ring so far (wrapping): the position of the next one.
    read_pos: u32,
}

impl<B> core::fmt::Debug for Port<B> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Port")
            .field("rx_len", &self.rx.len())
            .field("tx_len", &self.tx.len())
            .finish_non_exhaustive()
    }
}

impl<B: RegisterBus + Send + 'static> Port<B> {
    /// Bytes waiting in the RX ring.
    pub fn rx_len(&self) -> usize {
        self.rx.len()
    }

    /// Bytes waiting in the TX ring (not yet handed to the device).
    pub fn tx_len(&self) -> usize {
        self.tx.len()
    }

    /// Free space in the TX ring.
    pub fn tx_free(&self) -> usize {
        self.tx.capacity() - self.tx.len()
    }

    /// Stamps the ends of frames on this line from now on (see the module documentation).
    pub fn stamp_frames(&mut self, stamping: FrameStamping) {
        self.delimiter = Some(stamping.delimiter);
        self.state.with_isr(|h| h.stamping = Some(stamping));
    }

    /// Whether a frame delimiter arrived that has not been read yet (always false without
    /// [`Port::stamp_frames`]).
    pub fn frame_end_pending(&self) -> bool {
        let mark = self.state.end_mark.load(Ordering::Acquire);
        // The mark is one past the last delimiter: pending while reading has not passed it.
        self.delimiter.is_some() && (mark.wrapping_sub(self.read_pos) as i32) > 0
    }

    /// The timer tick (low 32 bits) at which the oldest frame end not read yet arrived, when
    /// it was stamped.
    pub fn oldest_frame_end(&mut self) -> Option<u32> {
        while let Some(e) = self.ends.peek() {
            if (e.pos.wrapping_sub(self.read_pos) as i32) >= 0 {
                return Some(e.tick);
            }
            // Read past without a stamp lookup (a plain read): drop it.
            self.ends.dequeue();
        }
        None
    }

    fn pop(&mut self) -> Option<u8> {
        let b = self.rx.dequeue()?;
        self.read_pos = self.read_pos.wrapping_add(1);
        Some(b)
    }

    /// Takes one received byte.
    pub fn read_byte(&mut self) -> Option<u8> {
        let byte = self.pop();
        self.resume_rx_if_room();
        byte
    }

    /// Takes up to `buf.len()` received bytes without waiting; returns how many.
    pub fn read_available(&mut self, buf: &mut [u8]) -> usize {
        let mut n = 0;
        for slot in buf.iter_mut() {
            let Some(b) = self.pop() else {
                break;
            };
            *slot = b;
            n += 1;
        }
        self.resume_rx_if_room();
        n
    }

    /// Takes received bytes up to and including the first frame delimiter, at most
    /// `buf.len()`, without waiting. Returns how many, and when the bytes end with a
    /// delimiter whose arrival was stamped, the timer tick (low 32 bits) it arrived at.
    pub fn read_frame(&mut self, buf: &mut [u8]) -> (usize, Option<u32>) {
        let (n, found) = self.rx.dequeue_until(buf, self.delimiter);
        self.read_pos = self.read_pos.wrapping_add(n as u32);
        let end = if found {
            self.end_tick(self.read_pos.wrapping_sub(1))
        } else {
            None
        };
        self.resume_rx_if_room();
        (n, end)
    }

    /// The stamp of the delimiter at `pos`, dropping stamps of delimiters read without one.
    fn end_tick(&mut self, pos: u32) -> Option<u32> {
        while let Some(e) = self.ends.peek() {
            let ahead = e.pos.wrapping_sub(pos) as i32;
            if ahead > 0 {
                return None;
            }
            let tick = e.tick;
            self.ends.dequeue();
            if ahead == 0 {
                return Some(tick);
            }
        }
        None
    }

    /// Queues as much of `bytes` as fits without waiting; returns how many.
    pub fn write_available(&mut self, bytes: &[u8]) -> usize {
        let mut n = 0;
        for &b in bytes {
            if self.tx.enqueue(b).is_err() {
                break;
            }
            n += 1;
        }
        if n > 0 {
            self.start_tx();
        }
        n
    }

    /// Queues all of `bytes`, sleeping while the TX ring is full.
    pub fn write_all_blocking(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let n = self.write_available(bytes);
            bytes = &bytes[n..];
            if !bytes.is_empty() {
                cpu::idle_unless(|| self.tx.ready());
            }
        }
    }

    /// True once the TX ring is empty and the device has shifted out its last bit.
    pub fn tx_idle(&self) -> bool {
        self.tx.is_empty()
            && self
                .state
                .with_isr(|h| h.uart.lsr().transmitter_empty())
                .unwrap_or(true)
    }

    /// Waits (sleeping between interrupts) until everything queued has been sent.
    ///
    /// Call with interrupts enabled: the TX ring drains in the interrupt handler.
    pub fn flush_blocking(&mut self) {
        while !self.tx.is_empty() {
            cpu::idle_unless(|| self.tx.is_empty());
        }
        // The last FIFO load drains at line speed without raising another interrupt.
        while !self.tx_idle() {
            core::hint::spin_loop();
        }
    }

    /// Sends every queued byte by polling the device, without interrupts: for panic and
    /// exit paths, where the interrupt handler no longer runs.
    pub fn flush_polled(&mut self) {
        self.state.with_isr(|h| {
            while let Some(byte) = h.tx.dequeue() {
                h.uart.write_blocking(byte);
            }
            h.uart.wait_idle();
        });
    }

    /// Returns (and clears) whether an overrun was seen since the last call.
    pub fn take_overrun(&mut self) -> bool {
        self.state.overrun_pending.swap(false, Ordering::AcqRel)
    }

    /// The interrupt handler's counters for this port.
    pub fn stats(&self) -> Stats {
        self.state.stats()
    }

    fn start_tx(&mut self) {
        self.state.with_isr(|h| {
            if !h.ier.thr_empty() {
                h.ier.set_thr_empty(true);
                h.uart.set_ier(h.ier);
            }
        });
    }

    fn resume_rx_if_room(&mut self) {
        if !self.state.rx_held.load(Ordering::Acquire) {
            return;
        }
        let space = self.rx.capacity() - self.rx.len();
        if space >= RX_RESUME_SPACE || self.rx.is_empty() {
            self.state.with_isr(|h| {
                h.ier.set_rx_available(true);
                h.uart.set_ier(h.ier);
                self.state.rx_held.store(false, Ordering::Release);
            });
        }
    }
}

impl<B> embedded_io::ErrorType for Port<B> {
    type Error = SerialError;
}

impl<B: RegisterBus + Send + 'static> embedded_io::Read for Port<B> {
    /// Waits for at least one byte, then returns what is buffered; reports an overrun once.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, SerialError> {
        if buf.is_empty() {
            return Ok(0);
        }
        if self.take_overrun() {
            return Err(SerialError::Overrun);
        }
        while self.rx.is_empty() {
            cpu::idle_unless(|| self.rx.ready());
        }
        Ok(self.read_available(buf))
    }
}

impl<B: RegisterBus + Send + 'static> embedded_io::ReadReady for Port<B> {
    fn read_ready(&mut self) -> Result<bool, SerialError> {
        Ok(self.rx.ready())
    }
}

impl<B: RegisterBus + Send + 'static> embedded_io::Write for Port<B> {
    /// Waits for room for at least one byte, then queues what fits.
    fn write(&mut self, buf: &[u8]) -> Result<usize, SerialError> {
        if buf.is_empty() {
            return Ok(0);
        }
        loop {
            let n = self.write_available(buf);
            if n > 0 {
                return Ok(n);
            }
            cpu::idle_unless(|| self.tx.ready());
        }
    }

    fn flush(&mut self) -> Result<(), SerialError> {
        self.flush_blocking();
        Ok(())
    }
}

impl<B: RegisterBus + Send + 'static> embedded_io::WriteReady for Port<B> {
    fn write_ready(&mut self) -> Result<bool, SerialError> {
        Ok(self.tx.ready())
    }
}

impl<B> embedded_hal_nb::serial::ErrorType for Port<B> {
    type Error = SerialError;
}

impl<B: RegisterBus + Send + 'static> embedded_hal_nb::serial::Read<u8> for Port<B> {
    fn read(&mut self) -> nb::Result<u8, SerialError> {
        if self.take_overrun() {
            return Err(nb::Error::Other(SerialError::Overrun));
        }
        self.read_byte().ok_or(nb::Error::WouldBlock)
    }
}

impl<B: RegisterBus + Send + 'static> embedded_hal_nb::serial::Write<u8> for Port<B> {
    fn write(&mut self, word: u8) -> nb::Result<(), SerialError> {
        match self.write_available(&[word]) {
            1 => Ok(()),
            _ => Err(nb::Error::WouldBlock),
        }
    }

    fn flush(&mut self) -> nb::Result<(), SerialError> {
        if self.tx_idle() {
            Ok(())
        } else {
            Err(nb::Error::WouldBlock)
        }
    }
}

#[cfg(test)]
mod tests;
