//! Cycle-level harness for the SoC: loads a program, steps the clock, paces bytes into the
//! UARTs at the line rate and collects everything the SoC emits, stamped with the cycle it
//! appeared in. Runs are deterministic: the same program and inputs give the same trace.

use crate::golden::Retire;
pub use crate::model::CoreVariant;
pub use crate::model::SimError;
use crate::model::{Model, RawEvent, Record};
pub use soc_model::{CameraError, CameraFrame, CameraTiming, VGA_H_BLANK};

/// Core clock of the SoC in Hz (128 clocks per bit at 115200 baud; divisor 8).
pub const CLOCK_HZ: u32 = 14_745_600;
/// Rate of the CLINT's mtime: it counts core clocks.
pub const TIMEBASE_HZ: u32 = CLOCK_HZ;
/// UART line rate the harness paces received bytes at.
pub const BAUD: u32 = 115_200;
/// Clocks per 8N1 character at [`BAUD`].
pub const CHAR_CYCLES: u64 = (CLOCK_HZ / BAUD) as u64 * 10;
/// Base address of RAM, where execution starts.
pub const RAM_BASE: u32 = 0x8000_0000;
/// RAM size in bytes.
pub const RAM_SIZE: u32 = 1 << 20;
/// Size of the frame-grabber window in bytes (`vision::frame::WINDOW_LEN`).
pub const FRAME_WINDOW_LEN: usize = 0x13_0000;

/// Memory map of the SoC.
pub mod map {
    /// Simulation control: +0 exit (SiFive test finisher values), +4 console byte.
    pub const SIM_CTRL: u32 = 0x0010_0000;
    pub const CLINT: u32 = 0x0200_0000;
    pub const PLIC: u32 = 0x0c00_0000;
    pub const UART0: u32 = 0x1000_0000;
    pub const UART1: u32 = 0x1000_1000;
    pub const RAM: u32 = super::RAM_BASE;
    /// Frame-grabber window (`super::FRAME_WINDOW_LEN` bytes; layout in `vision::frame`).
    pub const FRAME_WINDOW: u32 = 0x8100_0000;
    /// Vision unit (`vision::run_window` layout), fed by the camera port.
    pub const VISION: u32 = 0x8113_0000;
}

/// PLIC source numbers.
pub mod irq {
    pub const UART0: u32 = 10;
    pub const UART1: u32 = 11;
    /// The vision unit's end of frame.
    pub const VISION: u32 = 12;
}

/// The SoC's two UARTs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Uart {
    /// UART0, the LBC link.
    Lbc,
    /// UART1, the radio.
    Radio,
}

/// How a run ended, as written to the simulation-control exit register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// Finisher value 0x5555.
    Pass,
    /// Finisher value `code << 16 | 0x3333`.
    Fail(u16),
    /// Finisher value 0x7777.
    Reset,
    /// Any other value written to the exit register.
    Other(u32),
}

impl Exit {
    /// Decodes a value written to the exit register.
    pub fn decode(v: u32) -> Self {
        match v & 0xffff {
            0x5555 => Self::Pass,
            0x3333 => Self::Fail((v >> 16) as u16),
            0x7777 => Self::Reset,
            _ => Self::Other(v),
        }
    }
}

/// Something the SoC emitted in one clock cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// A byte finished transmitting (its stop bit ended) on a UART.
    Tx { uart: Uart, byte: u8 },
    /// A byte written to the console register.
    Console(u8),
    /// The program wrote the exit register.
    Exit(Exit),
}

/// A byte queued for a UART receiver: what [`Soc::send_at`] was asked (the cycle the call was
/// made in, the earliest cycle asked for) and the cycle it was scheduled for. Replaying the
/// calls at the same cycles into another model of the SoC gives it the same input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RxSend {
    /// [`Soc::cycle`] when `send_at` was called.
    pub called_at: u64,
    /// The UART.
    pub uart: Uart,
    /// The `at` argument.
    pub at: u64,
    /// The cycle the byte is presented to the receiver in.
    pub scheduled: u64,
    /// The byte.
    pub byte: u8,
}

/// An event and the cycle it appeared in (cycles since reset was released).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamped<T> {
    pub cycle: u64,
    pub value: T,
}

/// Why a program cannot be loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoadError {
    /// The range `addr..addr + len` does not lie inside RAM.
    OutsideRam { addr: u32, len: u32 },
    /// The address is not word aligned.
    Unaligned { addr: u32 },
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutsideRam { addr, len } => {
                write!(f, "{len} bytes at {addr:#010x} do not fit in RAM")
            }
            Self::Unaligned { addr } => write!(f, "load address {addr:#010x} is not word aligned"),
        }
    }
}

impl std::error::Error for LoadError {}

/// Why an ELF image cannot be loaded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ElfError {
    /// Not a readable ELF file.
    Parse(String),
    /// Not a 32-bit little-endian RISC-V image.
    WrongMachine { architecture: String },
    /// The entry point is not where the core starts.
    Entry { entry: u64 },
    /// A loadable segment lies outside RAM.
    Segment(LoadError),
}

impl core::fmt::Display for ElfError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Parse(why) => write!(f, "not a readable ELF file: {why}"),
            Self::WrongMachine { architecture } => {
                write!(f, "not an RV32 image (architecture {architecture})")
            }
            Self::Entry { entry } => {
                write!(
                    f,
                    "entry point {entry:#x} is not the reset address {RAM_BASE:#x}"
                )
            }
            Self::Segment(e) => write!(f, "segment: {e}"),
        }
    }
}

impl std::error::Error for ElfError {}

/// Why a frame-window write is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// `offset..offset + len` does not lie inside the window of [`FRAME_WINDOW_LEN`] bytes.
    OutsideWindow { offset: usize, len: usize },
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::OutsideWindow { offset, len } => write!(
                f,
                "{len} bytes at window offset {offset:#x} do not fit in {FRAME_WINDOW_LEN:#x} bytes"
            ),
        }
    }
}

impl std::error::Error for FrameError {}

/// The SoC (a simulator child process) with its stimulus schedule.
///
/// # Panics
///
/// The methods panic if the simulator process dies or garbles its replies: that is a broken
/// build or machine, not something a test can recover from. [`Soc::try_new`] reports a
/// simulator that cannot start.
#[derive(Debug)]
pub struct Soc {
    model: Model,
    cycle: u64,
    retired: u64,
    sleep_cycles: u64,
    /// First cycle each UART's receive line is free again.
    rx_free: [u64; 2],
    ext_irq: bool,
    rx_log: Vec<RxSend>,
    /// First cycle the camera's stream is free again.
    cam_free: u64,
}

impl Default for Soc {
    fn default() -> Self {
        Self::new()
    }
}

fn sim<T>(r: Result<T, SimError>) -> T {
    match r {
        Ok(v) => v,
        Err(e) => panic!("the SoC simulator failed: {e}"),
    }
}

impl Soc {
    /// A SoC held in reset with zeroed RAM and frame window.
    ///
    /// # Panics
    ///
    /// If the simulator cannot be started (see [`Soc::try_new`]).
    pub fn new() -> Self {
        sim(Self::try_new())
    }

    /// A SoC held in reset with zeroed RAM and frame window, or why the simulator process
    /// cannot be started.
    pub fn try_new() -> Result<Self, SimError> {
        Self::try_with_core(CoreVariant::Dsp)
    }

    /// A SoC held in reset whose core is `core`.
    ///
    /// # Panics
    ///
    /// If the simulator cannot be started.
    pub fn with_core(core: CoreVariant) -> Self {
        sim(Self::try_with_core(core))
    }

    /// A SoC held in reset whose core is `core`, or why the simulator cannot be started.
    pub fn try_with_core(core: CoreVariant) -> Result<Self, SimError> {
        Ok(Self {
            model: Model::spawn(core)?,
            cycle: 0,
            retired: 0,
            sleep_cycles: 0,
            rx_free: [0; 2],
            ext_irq: false,
            rx_log: Vec::new(),
            cam_free: 0,
        })
    }

    /// Process id of the simulator child (it never outlives this handle).
    pub fn simulator_pid(&self) -> u32 {
        self.model.pid()
    }

    /// Copies `words` into RAM at `addr` (the core stays in reset until [`Soc::release`]).
    pub fn load_words(&mut self, addr: u32, words: &[u32]) -> Result<(), LoadError> {
        if !addr.is_multiple_of(4) {
            return Err(LoadError::Unaligned { addr });
        }
        let len = u32::try_from(words.len() * 4).unwrap_or(u32::MAX);
        let off = addr.wrapping_sub(RAM_BASE);
        if addr < RAM_BASE || u64::from(off) + u64::from(len) > u64::from(RAM_SIZE) {
            return Err(LoadError::OutsideRam { addr, len });
        }
        sim(self.model.load(off / 4, words));
        Ok(())
    }

    /// Copies `bytes` into RAM at `addr` (little endian; the last word is zero padded).
    pub fn load_bytes(&mut self, addr: u32, bytes: &[u8]) -> Result<(), LoadError> {
        let words: Vec<u32> = bytes
            .chunks(4)
            .map(|c| {
                let mut w = [0u8; 4];
                w[..c.len()].copy_from_slice(c);
                u32::from_le_bytes(w)
            })
            .collect();
        self.load_words(addr, &words)
    }

    /// Loads the file bytes of the PT_LOAD segments of an RV32 ELF image into a fresh SoC (RAM
    /// starts zeroed, which covers the segments' zero-filled tails). The entry point must be
    /// [`RAM_BASE`].
    pub fn load_elf(&mut self, elf: &[u8]) -> Result<(), ElfError> {
        for (addr, words) in elf_segments(elf)? {
            self.load_words(addr, &words).map_err(ElfError::Segment)?;
        }
        Ok(())
    }

    /// Writes `bytes` into the frame-grabber window (at [`map::FRAME_WINDOW`] + `offset`)
    /// between two clock cycles: loads from the next cycle on see them. The core may be
    /// running; the window's reader/writer protocol (docs/camera.md) orders the writes.
    pub fn write_frame_window(&mut self, offset: usize, bytes: &[u8]) -> Result<(), FrameError> {
        if offset
            .checked_add(bytes.len())
            .is_none_or(|end| end > FRAME_WINDOW_LEN)
        {
            return Err(FrameError::OutsideWindow {
                offset,
                len: bytes.len(),
            });
        }
        sim(self.model.write_frame(offset as u32, bytes));
        Ok(())
    }

    /// Streams a frame of RGB332 codes (`width` per row) into the vision unit's camera port:
    /// one pixel a cycle from the first cycle at or after `max(at, cycle())` in which the
    /// previous frame's stream has ended, `timing.h_blank` cycles between rows (the row's end
    /// in the first of them), the frame's end right after the last row's. The same call on
    /// `soc_model::Soc` gives the same cycles.
    pub fn camera_frame_at(
        &mut self,
        at: u64,
        codes: &[u8],
        width: u16,
        height: u16,
        timing: CameraTiming,
    ) -> Result<CameraFrame, CameraError> {
        let ok = (1..=4096).contains(&width)
            && (1..=4096).contains(&height)
            && codes.len() == usize::from(width) * usize::from(height);
        if !ok {
            return Err(CameraError::BadFrame {
                width,
                height,
                len: codes.len(),
            });
        }
        if timing.h_blank == 0 {
            return Err(CameraError::BadTiming);
        }
        let first = at.max(self.cycle).max(self.cam_free);
        let eof = first + timing.eof_offset(width, height);
        self.cam_free = eof + 1;
        sim(self
            .model
            .camera(first, width, height, timing.h_blank, codes));
        Ok(CameraFrame { first, eof })
    }

    /// Releases reset: the core starts at [`RAM_BASE`]; cycle 0 is the first clock after.
    pub fn release(&mut self) {
        sim(self.model.release());
        self.cycle = 0;
    }

    /// Cycles run since reset was released.
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Instructions retired since the SoC was created (traps included).
    pub fn retired(&self) -> u64 {
        self.retired
    }

    /// Cycles the core spent asleep in WFI since the SoC was created.
    pub fn sleep_cycles(&self) -> u64 {
        self.sleep_cycles
    }

    /// Queues bytes for a UART's receiver; they arrive one character time apart, the first
    /// as soon as the line is free.
    pub fn send(&mut self, uart: Uart, bytes: &[u8]) {
        self.send_at(uart, self.cycle, bytes);
    }

    /// Like [`Soc::send`], but the first byte arrives no earlier than cycle `at`.
    pub fn send_at(&mut self, uart: Uart, at: u64, bytes: &[u8]) {
        let i = uart_index(uart);
        for &b in bytes {
            let t = at.max(self.rx_free[i]).max(self.cycle);
            sim(self.model.rx(i as u8, t, b));
            self.rx_free[i] = t + CHAR_CYCLES;
            self.rx_log.push(RxSend {
                called_at: self.cycle,
                uart,
                at,
                scheduled: t,
                byte: b,
            });
        }
    }

    /// Every byte queued for the receivers so far, in the order of the calls.
    pub fn rx_log(&self) -> &[RxSend] {
        &self.rx_log
    }

    /// Drives the test bench's external interrupt line.
    pub fn set_external_irq(&mut self, level: bool) {
        if level != self.ext_irq {
            self.ext_irq = level;
            sim(self.model.irq(level));
        }
    }

    /// Runs one clock cycle; returns the retirement record and events it produced.
    pub fn step(&mut self) -> (Option<Retire>, Vec<Event>) {
        let (records, events) = self.batch(1, true, false);
        (
            records.first().map(|r| r.retire),
            events.into_iter().map(|e| e.value).collect(),
        )
    }

    /// Runs up to `max_cycles` (stopping after an exit, or after the first event when
    /// `stop_on_event`); returns the RVFI records (if `rvfi`) and the stamped events.
    pub(crate) fn batch(
        &mut self,
        max_cycles: u64,
        rvfi: bool,
        stop_on_event: bool,
    ) -> (Vec<Record>, Vec<Stamped<Event>>) {
        let b = sim(self.model.run(max_cycles, rvfi, stop_on_event));
        self.cycle += b.cycles;
        self.retired = b.retired;
        self.sleep_cycles = b.sleep_cycles;
        let events = b
            .events
            .into_iter()
            .map(|(cycle, e)| Stamped {
                cycle,
                value: match e {
                    RawEvent::Uart0Tx(byte) => Event::Tx {
                        uart: Uart::Lbc,
                        byte,
                    },
                    RawEvent::Uart1Tx(byte) => Event::Tx {
                        uart: Uart::Radio,
                        byte,
                    },
                    RawEvent::Console(b) => Event::Console(b),
                    RawEvent::Exit(v) => Event::Exit(Exit::decode(v)),
                },
            })
            .collect();
        (b.records, events)
    }

    /// Like [`Soc::run`], and also returns every retirement record with the cycle it is
    /// stamped with (the cycle after the instruction completed).
    pub fn run_records(&mut self, max_cycles: u64) -> (Vec<(u64, Retire)>, Vec<Stamped<Event>>) {
        const BATCH: u64 = 1 << 16;
        let end = self.cycle + max_cycles;
        let (mut recs, mut out) = (Vec::new(), Vec::new());
        while self.cycle < end {
            let (records, events) = self.batch((end - self.cycle).min(BATCH), true, false);
            let stop = events.iter().any(|e| matches!(e.value, Event::Exit(_)));
            recs.extend(records.into_iter().map(|r| (r.cycle, r.retire)));
            out.extend(events);
            if stop {
                break;
            }
        }
        (recs, out)
    }

    /// Runs until the program exits or `max_cycles` have passed; returns every event with its
    /// cycle, ending with the exit if there was one.
    pub fn run(&mut self, max_cycles: u64) -> Vec<Stamped<Event>> {
        /// Longest batch, so a chatty program's events stay bounded per reply.
        const BATCH: u64 = 1 << 22;
        let end = self.cycle + max_cycles;
        let mut out = Vec::new();
        while self.cycle < end {
            let (_, events) = self.batch((end - self.cycle).min(BATCH), false, false);
            let stop = events.iter().any(|e| matches!(e.value, Event::Exit(_)));
            out.extend(events);
            if stop {
                break;
            }
        }
        out
    }
}

/// The PT_LOAD segments of an RV32 ELF image as word-aligned runs of words (file bytes only;
/// the zero-filled tails are left to zeroed RAM). The entry point must be [`RAM_BASE`].
pub fn elf_segments(elf: &[u8]) -> Result<Vec<(u32, Vec<u32>)>, ElfError> {
    use object::read::elf::{ElfFile32, FileHeader, ProgramHeader};
    use object::{Architecture, Object};
    let file = ElfFile32::<object::LittleEndian>::parse(elf)
        .map_err(|e| ElfError::Parse(e.to_string()))?;
    if file.architecture() != Architecture::Riscv32 {
        return Err(ElfError::WrongMachine {
            architecture: format!("{:?}", file.architecture()),
        });
    }
    if file.entry() != u64::from(RAM_BASE) {
        return Err(ElfError::Entry {
            entry: file.entry(),
        });
    }
    let endian = file.endian();
    let headers = file
        .elf_header()
        .program_headers(endian, elf)
        .map_err(|e| ElfError::Parse(e.to_string()))?;
    let mut out = Vec::new();
    for ph in headers {
        if ph.p_type(endian) != object::elf::PT_LOAD || ph.p_filesz(endian) == 0 {
            continue;
        }
        let addr = ph.p_paddr(endian);
        let data = ph
            .data(endian, elf)
            .map_err(|()| ElfError::Parse("segment data".into()))?;
        let pad = (addr % 4) as usize;
        let mut aligned = vec![0u8; pad];
        aligned.extend_from_slice(data);
        let words = aligned
            .chunks(4)
            .map(|c| {
                let mut w = [0u8; 4];
                w[..c.len()].copy_from_slice(c);
                u32::from_le_bytes(w)
            })
            .collect();
        out.push((addr - pad as u32, words));
    }
    Ok(out)
}

fn uart_index(uart: Uart) -> usize {
    match uart {
        Uart::Lbc => 0,
        Uart::Radio => 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_values_decode() {
        assert_eq!(Exit::decode(0x5555), Exit::Pass);
        assert_eq!(Exit::decode(0x0042_3333), Exit::Fail(0x42));
        assert_eq!(Exit::decode(0x7777), Exit::Reset);
        assert_eq!(Exit::decode(0x1234), Exit::Other(0x1234));
    }

    #[test]
    fn loads_outside_ram_are_refused() {
        let mut soc = Soc::new();
        assert_eq!(
            soc.load_words(RAM_BASE - 4, &[0]),
            Err(LoadError::OutsideRam {
                addr: RAM_BASE - 4,
                len: 4
            })
        );
        assert_eq!(
            soc.load_words(RAM_BASE + RAM_SIZE - 4, &[0, 0]),
            Err(LoadError::OutsideRam {
                addr: RAM_BASE + RAM_SIZE - 4,
                len: 8
            })
        );
        assert_eq!(
            soc.load_words(RAM_BASE + 2, &[0]),
            Err(LoadError::Unaligned { addr: RAM_BASE + 2 })
        );
        assert!(matches!(
            soc.load_elf(b"not an elf"),
            Err(ElfError::Parse(_))
        ));
    }

    #[test]
    fn runs_are_deterministic() {
        // A program that sits in a loop: the run is then a pure function of the input.
        let trace = || {
            let mut soc = Soc::new();
            soc.load_words(RAM_BASE, &[crate::isa::jal(0, 0)]).unwrap();
            soc.release();
            soc.send(Uart::Lbc, b"ab");
            let events = soc.run(3 * CHAR_CYCLES);
            (events, soc.cycle(), soc.retired())
        };
        let a = trace();
        assert_eq!(a, trace());
        assert_eq!(a.1, 3 * CHAR_CYCLES);
    }
}
