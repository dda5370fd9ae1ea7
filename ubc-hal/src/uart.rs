//! NS16550A register-level driver: register layouts by name, line setup (8N1, FIFOs on,
//! divisor from the input clock) and the interrupt service step that moves bytes between
//! the device FIFOs and the rings of a [`crate::serial`] port.

use crate::mmio::RegisterBus;
use bitfield::bitfield;

/// Register offsets (byte-spaced registers, as on qemu virt's UART0 and `pci-serial`).
pub mod reg {
    /// Receive buffer (read, DLAB=0).
    pub const RBR: usize = 0;
    /// Transmit holding register (write, DLAB=0).
    pub const THR: usize = 0;
    /// Divisor latch, low byte (DLAB=1).
    pub const DLL: usize = 0;
    /// Interrupt enable (DLAB=0).
    pub const IER: usize = 1;
    /// Divisor latch, high byte (DLAB=1).
    pub const DLM: usize = 1;
    /// Interrupt identification (read).
    pub const IIR: usize = 2;
    /// FIFO control (write).
    pub const FCR: usize = 2;
    /// Line control.
    pub const LCR: usize = 3;
    /// Modem control.
    pub const MCR: usize = 4;
    /// Line status.
    pub const LSR: usize = 5;
    /// Modem status.
    pub const MSR: usize = 6;
    /// Scratch.
    pub const SCR: usize = 7;
}

/// Depth of the 16550A transmit and receive FIFOs.
pub const FIFO_DEPTH: usize = 16;

bitfield! {
    /// Interrupt enable register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Ier(pub u8);
    impl Debug;
    /// Received data available (and character timeout).
    pub rx_available, set_rx_available: 0;
    /// Transmit holding register empty.
    pub thr_empty, set_thr_empty: 1;
    /// Receiver line status (overrun, parity, framing, break).
    pub line_status, set_line_status: 2;
    /// Modem status change.
    pub modem_status, set_modem_status: 3;
}

bitfield! {
    /// Interrupt identification register.
    #[derive(Clone, Copy, PartialEq, Eq)]
    pub struct Iir(pub u8);
    impl Debug;
    /// Set when no interrupt is pending (the bit is active low).
    pub no_interrupt, _: 0;
    /// Interrupt source, see [`IrqId`].
    pub u8, id, _: 3, 1;
    /// 0b11 when the FIFOs are enabled.
    pub u8, fifos, _: 7, 6;
}

/// Interrupt sources as reported in [`Iir::id`], highest priority first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IrqId {
    /// Overrun, parity or framing error, or break: cleared by reading LSR.
    LineStatus,
    /// RX FIFO at its trigger level: cleared by draining it below.
    RxAvailable,
    /// Characters wait in the RX FIFO and none arrived for 4 character times.
    RxTimeout,
    /// THR empty: cleared by reading IIR or writing THR.
    ThrEmpty,
    /// Modem status change: cleared by reading MSR.
    ModemStatus,
}

impl Iir {
    /// The pending interrupt source, if any.
    pub fn pending(&self) -> Option<IrqId> {
        if self.no_interrupt() {
            return None;
        }
        Some(match self.id() {
            0b011 => IrqId::LineStatus,
            0b010 => IrqId::RxAvailable,
            0b110 => IrqId::RxTimeout,
            0b001 => IrqId::ThrEmpty,
            _ => IrqId::ModemStatus,
        })
    }
}

bitfield! {
    /// FIFO control register (write only).
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Fcr(pub u8);
    impl Debug;
    /// Enable both FIFOs.
    pub enable, set_enable: 0;
    /// Clear the receive FIFO (self-clearing).
    pub clear_rx, set_clear_rx: 1;
    /// Clear the transmit FIFO (self-clearing).
    pub clear_tx, set_clear_tx: 2;
    /// DMA mode select.
    pub dma_mode, set_dma_mode: 3;
    /// RX trigger level: 0 = 1 byte, 1 = 4, 2 = 8, 3 = 14.
    pub u8, rx_trigger, set_rx_trigger: 7, 6;
}

bitfield! {
    /// Line control register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Lcr(pub u8);
    impl Debug;
    /// Word length minus 5 (3 = 8 data bits).
    pub u8, word_length, set_word_length: 1, 0;
    /// Two stop bits (1.5 for 5-bit words) when set.
    pub two_stop_bits, set_two_stop_bits: 2;
    /// Parity enable.
    pub parity_enable, set_parity_enable: 3;
    /// Even parity when set.
    pub even_parity, set_even_parity: 4;
    /// Stick parity.
    pub stick_parity, set_stick_parity: 5;
    /// Hold the line in break.
    pub break_control, set_break_control: 6;
    /// Divisor latch access: DLL/DLM replace RBR/THR/IER while set.
    pub dlab, set_dlab: 7;
}

bitfield! {
    /// Modem control register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Mcr(pub u8);
    impl Debug;
    /// Data terminal ready.
    pub dtr, set_dtr: 0;
    /// Request to send.
    pub rts, set_rts: 1;
    /// OUT1 user output.
    pub out1, set_out1: 2;
    /// OUT2: gates the interrupt line on PC-style boards.
    pub out2, set_out2: 3;
    /// Internal loopback.
    pub loopback, set_loopback: 4;
}

bitfield! {
    /// Line status register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Lsr(pub u8);
    impl Debug;
    /// At least one byte waits in RBR / the RX FIFO.
    pub data_ready, _: 0;
    /// A byte was lost because the RX FIFO was full.
    pub overrun, _: 1;
    /// The byte at the head of the FIFO has a parity error.
    pub parity_error, _: 2;
    /// The byte at the head of the FIFO has a framing error.
    pub framing_error, _: 3;
    /// A break condition was received.
    pub break_interrupt, _: 4;
    /// THR (or the TX FIFO) is empty.
    pub thr_empty, _: 5;
    /// THR and the transmit shift register are both empty: the line is idle.
    pub transmitter_empty, _: 6;
    /// At least one error byte is in the RX FIFO.
    pub rx_fifo_error, _: 7;
}

/// Line settings. The line is always 8 data bits, no parity, one stop bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub struct Config {
    /// Frequency of the clock feeding the baud generator, in Hz.
    pub input_clock_hz: u32,
    /// Line rate in bit/s.
    pub baud: u32,
    /// RX FIFO trigger level code (see [`Fcr::rx_trigger`]).
    pub rx_trigger: u8,
}

impl Default for Config {
    /// 115200 baud from the classic 1.8432 MHz crystal, interrupt at 8 bytes in the FIFO.
    fn default() -> Self {
        Self {
            input_clock_hz: 1_843_200,
            baud: 115_200,
            rx_trigger: 2,
        }
    }
}

impl Config {
    /// The default settings with another input clock.
    pub fn with_clock(input_clock_hz: u32) -> Self {
        Self {
            input_clock_hz,
            ..Self::default()
        }
    }
}

/// Largest baud rate error accepted by [`divisor`], in parts per thousand.
pub const MAX_BAUD_ERROR_PERMILLE: u32 = 25;

/// Why a line configuration cannot be applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ConfigError {
    /// The baud rate was zero.
    ZeroBaud,
    /// The divisor does not fit the 16-bit latch (or is zero: the clock is too slow).
    DivisorOutOfRange {
        /// The divisor that would be needed.
        divisor: u32,
    },
    /// The nearest divisor misses the requested rate by more than [`MAX_BAUD_ERROR_PERMILLE`].
    BaudMismatch {
        /// Requested bit/s.
        requested: u32,
        /// Bit/s the nearest divisor gives.
        achieved: u32,
    },
}

/// Baud divisor for `baud` from `input_clock_hz` (16x oversampling), rounded to nearest.
pub fn divisor(input_clock_hz: u32, baud: u32) -> Result<u16, ConfigError> {
    if baud == 0 {
        return Err(ConfigError::ZeroBaud);
    }
    let sixteen_baud = u64::from(baud) * 16;
    let clock = u64::from(input_clock_hz);
    let div = (clock + sixteen_baud / 2) / sixteen_baud;
    let div = match u16::try_from(div) {
        Ok(0) | Err(_) => {
            return Err(ConfigError::DivisorOutOfRange {
                divisor: u32::try_from(div).unwrap_or(u32::MAX),
            })
        }
        Ok(d) => d,
    };
    let achieved = clock / (16 * u64::from(div));
    let error = achieved.abs_diff(u64::from(baud)) * 1000;
    if error > u64::from(baud) * u64::from(MAX_BAUD_ERROR_PERMILLE) {
        return Err(ConfigError::BaudMismatch {
            requested: baud,
            achieved: u32::try_from(achieved).unwrap_or(u32::MAX),
        });
    }
    Ok(div)
}

/// An NS16550A-compatible UART.
#[derive(Debug)]
pub struct Ns16550<B> {
    bus: B,
}

impl<B: RegisterBus> Ns16550<B> {
    /// Wraps the registers; call [`Ns16550::init`] before use.
    pub const fn new(bus: B) -> Self {
        Self { bus }
    }

    /// Sets the line to 8N1 at the configured rate, enables and clears the FIFOs, raises
    /// DTR/RTS/OUT2 and leaves every interrupt disabled.
    pub fn init(&self, config: &Config) -> Result<(), ConfigError> {
        let div = divisor(config.input_clock_hz, config.baud)?;
        self.set_ier(Ier(0));
        let mut lcr = Lcr(0);
        lcr.set_dlab(true);
        self.bus.write8(reg::LCR, lcr.0);
        let [lo, hi] = div.to_le_bytes();
        self.bus.write8(reg::DLL, lo);
        self.bus.write8(reg::DLM, hi);
        let mut lcr = Lcr(0);
        lcr.set_word_length(3);
        self.bus.write8(reg::LCR, lcr.0);
        let mut fcr = Fcr(0);
        fcr.set_enable(true);
        fcr.set_clear_rx(true);
        fcr.set_clear_tx(true);
        fcr.set_rx_trigger(config.rx_trigger & 0b11);
        self.bus.write8(reg::FCR, fcr.0);
        let mut mcr = Mcr(0);
        mcr.set_dtr(true);
        mcr.set_rts(true);
        mcr.set_out2(true);
        self.bus.write8(reg::MCR, mcr.0);
        // Clear stale line status, and the holding register of a UART without FIFO (the FIFO
        // reset above emptied the RX FIFO). No loop on `data_ready`: a device that always
        // reports data (absent, or a line that never pauses) must not hang start-up.
        let _ = self.lsr();
        let _ = self.bus.read8(reg::RBR);
        Ok(())
    }

    /// Reads the line status (this clears its error bits).
    pub fn lsr(&self) -> Lsr {
        Lsr(self.bus.read8(reg::LSR))
    }

    /// Reads the interrupt identification.
    pub fn iir(&self) -> Iir {
        Iir(self.bus.read8(reg::IIR))
    }

    /// Reads the interrupt enables.
    pub fn ier(&self) -> Ier {
        Ier(self.bus.read8(reg::IER))
    }

    /// Writes the interrupt enables.
    pub fn set_ier(&self, ier: Ier) {
        self.bus.write8(reg::IER, ier.0)
    }

    /// Reads the modem status (clears the modem status interrupt).
    pub fn msr(&self) -> u8 {
        self.bus.read8(reg::MSR)
    }

    /// Takes one received byte if there is one.
    pub fn try_read(&self) -> Option<u8> {
        self.lsr().data_ready().then(|| self.bus.read8(reg::RBR))
    }

    /// Writes one byte if THR has room.
    pub fn try_write(&self, byte: u8) -> bool {
        if self.lsr().thr_empty() {
            self.bus.write8(reg::THR, byte);
            true
        } else {
            false
        }
    }

    /// Writes one byte, waiting for THR to empty first.
    pub fn write_blocking(&self, byte: u8) {
        while !self.try_write(byte) {
            core::hint::spin_loop();
        }
    }

    /// Waits until every written byte has left the transmit shift register.
    pub fn wait_idle(&self) {
        while !self.lsr().transmitter_empty() {
            core::hint::spin_loop();
        }
    }

    /// Writes a byte to THR without checking for room (the caller saw THR empty).
    pub(crate) fn write_thr(&self, byte: u8) {
        self.bus.write8(reg::THR, byte)
    }

    /// Reads RBR without checking LSR (the caller saw data ready).
    pub(crate) fn read_rbr(&self) -> u8 {
        self.bus.read8(reg::RBR)
    }
}

/// A behavioural model of a 16550 for host tests: an RX FIFO the test fills, a record of
/// transmitted bytes, IER/LCR/divisor latches and IIR priority resolution.
#[cfg(test)]
pub(crate) mod model {
    use super::*;
    use std::collections::VecDeque;
    use std::sync::Mutex;

    #[derive(Debug, Default)]
    pub(crate) struct State {
        pub(crate) rx: VecDeque<u8>,
        pub(crate) tx: Vec<u8>,
        pub(crate) tx_fifo: usize,
        pub(crate) ier: u8,
        pub(crate) lcr: u8,
        pub(crate) mcr: u8,
        pub(crate) fcr: u8,
        pub(crate) dll: u8,
        pub(crate) dlm: u8,
        pub(crate) overrun: bool,
        pub(crate) thre_irq: bool,
        /// When set, THR never empties (a stalled line).
        pub(crate) tx_stalled: bool,
        /// When set, waiting bytes report the receive timeout instead of the trigger level.
        pub(crate) rx_timeout: bool,
    }

    #[derive(Debug, Default)]
    pub(crate) struct UartModel {
        pub(crate) s: Mutex<State>,
    }

    impl UartModel {
        pub(crate) fn receive(&self, bytes: &[u8]) {
            let mut s = self.s.lock().unwrap();
            for &b in bytes {
                if s.rx.len() == FIFO_DEPTH {
                    s.overrun = true;
                } else {
                    s.rx.push_back(b);
                }
            }
        }
        pub(crate) fn sent(&self) -> Vec<u8> {
            self.s.lock().unwrap().tx.clone()
        }
        /// The line shifts out everything queued in the TX FIFO.
        pub(crate) fn drain_line(&self) {
            let mut s = self.s.lock().unwrap();
            if !s.tx_stalled {
                s.tx_fifo = 0;
                s.thre_irq = true;
            }
        }
        pub(crate) fn irq_line(&self) -> bool {
            Iir(Self::iir(&self.s.lock().unwrap())).pending().is_some()
        }
        fn iir(s: &State) -> u8 {
            let ier = Ier(s.ier);
            if ier.line_status() && s.overrun {
                0b0110
            } else if ier.rx_available() && !s.rx.is_empty() && s.rx_timeout {
                0b1100
            } else if ier.rx_available() && !s.rx.is_empty() {
                0b0100
            } else if ier.thr_empty() && s.thre_irq && s.tx_fifo == 0 {
                0b0010
            } else {
                0b0001
            }
        }
    }

    impl RegisterBus for UartModel {
        fn read8(&self, offset: usize) -> u8 {
            let mut s = self.s.lock().unwrap();
            let dlab = Lcr(s.lcr).dlab();
            match offset {
                reg::RBR if dlab => s.dll,
                reg::RBR => s.rx.pop_front().unwrap_or(0),
                reg::IER if dlab => s.dlm,
                reg::IER => s.ier,
                reg::IIR => {
                    let v = Self::iir(&s);
                    if v == 0b0010 {
                        s.thre_irq = false;
                    }
                    v | 0xC0
                }
                reg::LCR => s.lcr,
                reg::MCR => s.mcr,
                reg::LSR => {
                    let mut v = 0u8;
                    if !s.rx.is_empty() {
                        v |= 1;
                    }
                    if s.overrun {
                        v |= 2;
                        s.overrun = false;
                    }
                    if s.tx_fifo < FIFO_DEPTH {
                        v |= 0x20;
                    }
                    if s.tx_fifo == 0 {
                        v |= 0x40;
                    }
                    v
                }
                _ => 0,
            }
        }
        fn write8(&self, offset: usize, value: u8) {
            let mut s = self.s.lock().unwrap();
            let dlab = Lcr(s.lcr).dlab();
            match offset {
                reg::THR if dlab => s.dll = value,
                reg::THR => {
                    assert!(
                        s.tx_fifo < FIFO_DEPTH,
                        "THR written while the TX FIFO is full"
                    );
                    s.tx.push(value);
                    s.tx_fifo += 1;
                    s.thre_irq = false;
                    if !s.tx_stalled {
                        // The model's line is fast: the FIFO drains at once.
                        s.tx_fifo = 0;
                        s.thre_irq = true;
                    }
                }
                reg::IER if dlab => s.dlm = value,
                reg::IER => {
                    let was = Ier(s.ier).thr_empty();
                    s.ier = value & 0x0F;
                    if !was && Ier(value).thr_empty() && s.tx_fifo == 0 {
                        s.thre_irq = true;
                    }
                }
                reg::FCR => {
                    s.fcr = value;
                    if Fcr(value).clear_rx() {
                        s.rx.clear();
                    }
                }
                reg::LCR => s.lcr = value,
                reg::MCR => s.mcr = value,
                _ => {}
            }
        }
        fn read32(&self, _offset: usize) -> u32 {
            panic!("16550 registers are bytes")
        }
        fn write32(&self, _offset: usize, _value: u32) {
            panic!("16550 registers are bytes")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::model::UartModel;
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn divisor_for_common_clocks() {
        assert_eq!(divisor(1_843_200, 115_200), Ok(1));
        assert_eq!(divisor(3_686_400, 115_200), Ok(2));
        assert_eq!(divisor(1_843_200, 9_600), Ok(12));
        // 50 MHz soft-core clock: 27.13 rounds to 27, 0.47 % fast.
        assert_eq!(divisor(50_000_000, 115_200), Ok(27));
    }

    #[test]
    fn divisor_errors() {
        assert_eq!(divisor(1_843_200, 0), Err(ConfigError::ZeroBaud));
        assert_eq!(
            divisor(1_000_000, 115_200),
            Err(ConfigError::BaudMismatch {
                requested: 115_200,
                achieved: 62_500
            })
        );
        assert_eq!(
            divisor(100_000, 115_200),
            Err(ConfigError::DivisorOutOfRange { divisor: 0 })
        );
        assert_eq!(
            divisor(u32::MAX, 1),
            Err(ConfigError::DivisorOutOfRange {
                divisor: 268_435_456
            })
        );
        // 2.7 MHz / 16 / 115200 = 1.46 -> 1 gives 168750 baud: far off.
        assert_eq!(
            divisor(2_700_000, 115_200),
            Err(ConfigError::BaudMismatch {
                requested: 115_200,
                achieved: 168_750
            })
        );
    }

    proptest! {
        #[test]
        fn accepted_divisors_are_within_tolerance(clock in 1u32.., baud in 1u32..4_000_000) {
            if let Ok(d) = divisor(clock, baud) {
                let achieved = u64::from(clock) / (16 * u64::from(d));
                let err = achieved.abs_diff(u64::from(baud)) * 1000;
                prop_assert!(err <= u64::from(baud) * u64::from(MAX_BAUD_ERROR_PERMILLE));
            }
        }
    }

    #[test]
    fn register_layouts() {
        let mut lcr = Lcr(0);
        lcr.set_word_length(3);
        assert_eq!(lcr.0, 0x03);
        lcr.set_dlab(true);
        assert_eq!(lcr.0, 0x83);
        let mut fcr = Fcr(0);
        fcr.set_enable(true);
        fcr.set_clear_rx(true);
        fcr.set_clear_tx(true);
        fcr.set_rx_trigger(3);
        assert_eq!(fcr.0, 0xC7);
        let mut ier = Ier(0);
        ier.set_rx_available(true);
        ier.set_thr_empty(true);
        assert_eq!(ier.0, 0x03);
        let lsr = Lsr(0x61);
        assert!(lsr.data_ready() && lsr.thr_empty() && lsr.transmitter_empty());
        assert!(!lsr.overrun());
        assert_eq!(Iir(0xC1).pending(), None);
        assert_eq!(Iir(0xC4).pending(), Some(IrqId::RxAvailable));
        assert_eq!(Iir(0xCC).pending(), Some(IrqId::RxTimeout));
        assert_eq!(Iir(0xC2).pending(), Some(IrqId::ThrEmpty));
        assert_eq!(Iir(0xC6).pending(), Some(IrqId::LineStatus));
        assert_eq!(Iir(0xC0).pending(), Some(IrqId::ModemStatus));
    }

    #[test]
    fn init_programs_8n1_divisor_and_fifos() {
        let m = UartModel::default();
        m.receive(b"stale");
        let uart = Ns16550::new(&m);
        uart.init(&Config::with_clock(3_686_400)).unwrap();
        let s = m.s.lock().unwrap();
        assert_eq!((s.dll, s.dlm), (2, 0));
        assert_eq!(s.lcr, 0x03, "8N1 with DLAB cleared");
        assert_eq!(s.fcr, 0x87, "FIFOs on and cleared, trigger at 8");
        assert_eq!(s.mcr, 0x0B, "DTR, RTS, OUT2");
        assert_eq!(s.ier, 0);
        assert!(s.rx.is_empty());
    }

    /// A bus with nothing behind it: every read gives 0xFF (LSR says data ready forever).
    struct Floating(core::cell::Cell<usize>);

    impl RegisterBus for Floating {
        fn read8(&self, _offset: usize) -> u8 {
            self.0.set(self.0.get() + 1);
            0xFF
        }
        fn write8(&self, _offset: usize, _value: u8) {}
        fn read32(&self, _offset: usize) -> u32 {
            u32::MAX
        }
        fn write32(&self, _offset: usize, _value: u32) {}
    }

    #[test]
    fn init_returns_on_a_device_that_always_has_data() {
        let bus = Floating(core::cell::Cell::new(0));
        let uart = Ns16550::new(&bus);
        assert_eq!(uart.init(&Config::default()), Ok(()));
        assert!(bus.0.get() <= 4, "{} register reads", bus.0.get());
    }

    #[test]
    fn init_rejects_bad_clock_without_touching_the_line() {
        let m = UartModel::default();
        let uart = Ns16550::new(&m);
        assert!(uart.init(&Config::with_clock(1000)).is_err());
        assert_eq!(m.s.lock().unwrap().lcr, 0);
    }

    #[test]
    fn polled_read_write() {
        let m = UartModel::default();
        let uart = Ns16550::new(&m);
        uart.init(&Config::default()).unwrap();
        assert_eq!(uart.try_read(), None);
        m.receive(b"ab");
        assert_eq!(uart.try_read(), Some(b'a'));
        assert_eq!(uart.try_read(), Some(b'b'));
        assert_eq!(uart.try_read(), None);
        uart.write_blocking(b'x');
        assert!(uart.try_write(b'y'));
        assert_eq!(m.sent(), b"xy");
    }
}
