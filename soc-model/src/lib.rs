//! Cycle-accurate instruction-set model of the softcore SoC (`verilator-tb/rtl/`): the RV32IMAC +
//! Zicsr core with its exact cycle costs (two-cycle CSR writes to register-file CSRs, AMOs and
//! trap entry, the 34-cycle divider, the counter-carry cycles), 1 MiB of RAM, the frame-grabber
//! window, the vision unit, two 16550 UARTs, the CLINT, the PLIC and the simulation-control
//! device, in one process, deterministic, without the RTL.
//!
//! The model agrees with the RTL cycle for cycle: every instruction retires in the same cycle,
//! every UART byte and console byte appears in the same cycle, and the statistics (cycles,
//! sleep cycles, retired instructions) are the same. `docs/soc-model.md` lists what is
//! modelled, the cycle table and the measured speed.
//!
//! Speed comes from three things: instructions are decoded once per RAM halfword where they
//! start (compressed ones expanded then; the decoded form is dropped when a word it overlaps is
//! written); devices are not ticked but compute their state from
//! cycle numbers, so the core runs straight until the next cycle at which something can change
//! (a byte finishing, a timer match, a counter carry, `until`); and a core waiting in WFI jumps
//! straight to that cycle, with the counter carries in between accounted arithmetically.
//!
//! [`hart`] is the plain reference model (architectural state only) the RTL's lockstep checker
//! uses; [`isa`] has instruction encoders for tests; [`rvc`] expands compressed instructions.
#![forbid(unsafe_code)]

mod dev;
mod elf;
mod exec;
mod fast;
pub mod hart;
pub mod isa;
pub mod rvc;
#[cfg(test)]
mod tests;
mod vision_unit;

pub use elf::LoadError;
pub use hart::Retire;
pub use vision_unit::{CameraTiming, CAPACITY as VISION_CAPACITY, VGA_H_BLANK};

use dev::{Clint, Plic, Uart};
use vision_unit::VisionUnit;

/// Core clock in Hz (115200 baud is divisor 8: 128 clocks per bit).
pub const CLOCK_HZ: u64 = 14_745_600;
/// Clocks per 115200-8N1 character at divisor 8 (16 x 8 x 10).
pub const CHAR_CYCLES: u64 = 1280;
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
    /// CLINT: msip +0, mtimecmp +0x4000, mtime +0xbff8.
    pub const CLINT: u32 = 0x0200_0000;
    /// PLIC: priorities, pending 0x1000, enable 0x2000, threshold 0x20_0000, claim 0x20_0004.
    pub const PLIC: u32 = 0x0c00_0000;
    /// UART0, the LBC link (PLIC source 10).
    pub const UART0: u32 = 0x1000_0000;
    /// UART1, the radio (PLIC source 11).
    pub const UART1: u32 = 0x1000_1000;
    /// RAM.
    pub const RAM: u32 = super::RAM_BASE;
    /// Frame-grabber window (`super::FRAME_WINDOW_LEN` bytes, data port only).
    pub const FRAME_WINDOW: u32 = 0x8100_0000;
    /// Vision unit: registers, class table and run buffers (`vision::run_window` layout) in a
    /// 64 KiB region (PLIC source 12).
    pub const VISION: u32 = 0x8113_0000;
}

/// PLIC sources of the SoC's devices.
pub mod irq {
    /// UART0 (LBC link).
    pub const UART0: u32 = 10;
    /// UART1 (radio).
    pub const UART1: u32 = 11;
    /// The vision unit's end of frame.
    pub const VISION: u32 = 12;
}

/// The SoC's two UARTs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Port {
    /// UART0 at 0x1000_0000, the LBC link.
    Lbc,
    /// UART1 at 0x1000_1000, the radio.
    Radio,
}

impl Port {
    fn index(self) -> usize {
        match self {
            Self::Lbc => 0,
            Self::Radio => 1,
        }
    }
}

/// Something the SoC emitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// A byte finished transmitting (its stop bit ended) on a UART.
    Tx {
        /// Which UART.
        port: Port,
        /// The byte.
        byte: u8,
    },
    /// A byte written to the console register.
    Console(u8),
}

/// An output and the cycle it appeared in (the RTL's event cycle: cycles since reset).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamped {
    /// Cycle stamp, numbered as `verilator-tb`'s `Soc::run` events.
    pub cycle: u64,
    /// What was emitted.
    pub output: Output,
}

/// Why a core stopped making progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StuckReason {
    /// WFI with no interrupt enabled in `mie` that anything could still raise.
    WfiWithoutWakeup,
    /// A jump or branch to itself with no interrupt that can be taken (`mstatus.MIE` clear,
    /// or nothing enabled in `mie` that anything could still raise).
    SpinWithoutInterrupt,
}

/// Why a run stopped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Halt {
    /// The raw word written to the exit register (0x5555 pass, `code << 16 | 0x3333` fail,
    /// 0x7777 reset). The run ends in the cycle after the write, like the RTL's.
    Exit {
        /// The word written.
        value: u32,
    },
    /// The core can provably never make progress. The SoC keeps running (its UARTs still
    /// finish what they hold and time passes), so [`Soc::run_until`] still goes to `until`.
    Stuck {
        /// The instruction it is stuck at.
        pc: u32,
        /// Why.
        reason: StuckReason,
    },
}

/// Run statistics, counted as the RTL harness counts them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Cycles since reset.
    pub cycles: u64,
    /// Cycles the core's sleep output was high: a WFI waiting, and counter-carry cycles taken
    /// while it waits.
    pub sleep_cycles: u64,
    /// Retirement records (instructions retired, and trapping instructions).
    pub retired: u64,
}

/// Why a frame-window write is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// `offset..offset + len` does not lie inside the window of [`FRAME_WINDOW_LEN`] bytes.
    OutsideWindow {
        /// Offset asked for.
        offset: usize,
        /// Bytes asked for.
        len: usize,
    },
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

/// Why a camera frame is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraError {
    /// This SoC has no vision unit ([`Soc::set_vision_unit`]).
    NoVisionUnit,
    /// Width or height is 0 or above 4096, or the pixels are not `width * height` codes.
    BadFrame {
        /// Width asked for.
        width: u16,
        /// Height asked for.
        height: u16,
        /// Codes given.
        len: usize,
    },
    /// `h_blank` is 0.
    BadTiming,
}

impl core::fmt::Display for CameraError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NoVisionUnit => write!(f, "this SoC has no vision unit"),
            Self::BadFrame { width, height, len } => write!(
                f,
                "a {width}x{height} camera frame needs 1..=4096 pixels each way and as many \
                 codes, got {len}"
            ),
            Self::BadTiming => write!(f, "a camera row needs at least one blank cycle"),
        }
    }
}

impl std::error::Error for CameraError {}

/// When a camera frame goes through the vision unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraFrame {
    /// Cycle of its first pixel.
    pub first: u64,
    /// Cycle of its end event; the frame is published at the edge ending `eof + 2` (seen from
    /// `eof + 3`) when the unit processes it.
    pub eof: u64,
}

/// Why words cannot be loaded into RAM.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WordsError {
    /// The address is not word aligned.
    Unaligned {
        /// The address.
        addr: u32,
    },
    /// `addr..addr + 4 * words` does not lie inside RAM.
    OutsideRam {
        /// The address.
        addr: u32,
        /// Number of words.
        words: usize,
    },
}

impl core::fmt::Display for WordsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Unaligned { addr } => write!(f, "address {addr:#010x} is not word aligned"),
            Self::OutsideRam { addr, words } => {
                write!(f, "{words} words at {addr:#010x} do not fit in RAM")
            }
        }
    }
}

impl std::error::Error for WordsError {}

/// A retirement record (shaped like the RTL's RVFI port) and the cycle it is stamped with
/// (the cycle after the instruction completed, as `verilator-tb` stamps RVFI records).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Retired {
    /// Cycle stamp.
    pub cycle: u64,
    /// The record.
    pub retire: Retire,
}

/// Interrupt line bits (as `hart::line`): software, timer, external.
pub(crate) mod line {
    pub const MSI: u8 = 1;
    pub const MTI: u8 = 2;
    pub const MEI: u8 = 4;
}

/// Pending counter carries (the RTL's `cyc_pl`, `cyc_ph`, `ins_pl`, `ins_ph`).
pub(crate) mod pend {
    pub const CYC_LO: u8 = 1;
    pub const CYC_HI: u8 = 2;
    pub const INS_LO: u8 = 4;
    pub const INS_HI: u8 = 8;
}

pub(crate) const RAM_WORDS: usize = (RAM_SIZE / 4) as usize;
pub(crate) const RAM_HALVES: usize = (RAM_SIZE / 2) as usize;
pub(crate) const FRAME_WORDS: usize = FRAME_WINDOW_LEN / 4;

/// The second cycle of an AMO whose target is not RAM, when its first cycle was the last one
/// of a run (it then runs at the start of the next, after the harness's input).
#[derive(Debug, Clone, Copy)]
pub(crate) struct AmoEx2 {
    pub insn: u32,
    pub pc: u32,
    pub addr: u32,
    pub loaded: u32,
    pub rs2v: u32,
    pub intr: bool,
}

/// Decoded instructions of the executable part of a loaded image, shared by every clone of
/// the SoC that loaded it (many cars running one firmware decode it once and keep one copy
/// in the host's caches). A SoC stops using it once anything stores into that part.
#[derive(Debug)]
pub(crate) struct SharedCode {
    /// First RAM halfword covered.
    pub(crate) first: usize,
    /// One past the last.
    pub(crate) end: usize,
    /// The decoded instruction starting at each RAM halfword (see `fast`), 0 outside
    /// `first..end`.
    pub(crate) ops: Box<[u64]>,
    /// The code's instructions in address order, as a sweep from `first` finds them (each
    /// the next one's predecessor in memory), then a 0 ("not here").
    pub(crate) line: Box<[u64]>,
    /// Per halfword of `first..end`: the index in `line` of the instruction starting there,
    /// or [`SharedCode::OFF_LINE`] where none of the sweep starts.
    pub(crate) at: Box<[u32]>,
}

impl SharedCode {
    /// An index of `at` for a halfword where no instruction of the sweep starts.
    pub(crate) const OFF_LINE: u32 = u32::MAX;

    fn new(first: usize, end: usize, ops: Box<[u64]>) -> Self {
        let mut line = Vec::with_capacity(end.saturating_sub(first) / 2 + 1);
        let mut at = vec![Self::OFF_LINE; end.saturating_sub(first)].into_boxed_slice();
        let mut h = first;
        while h < end {
            let op = ops[h];
            if let Some(slot) = at.get_mut(h - first) {
                *slot = u32::try_from(line.len()).unwrap_or(Self::OFF_LINE);
            }
            line.push(op);
            h += ((op >> 32) as usize / 2).max(1);
        }
        line.push(0);
        SharedCode {
            first,
            end,
            ops,
            line: line.into_boxed_slice(),
            at,
        }
    }

    /// The index in `line` of the instruction at `pc`, or [`SharedCode::OFF_LINE`].
    #[inline(always)]
    pub(crate) fn line_at(&self, pc: u32) -> u32 {
        let h = (pc.wrapping_sub(RAM_BASE) >> 1) as usize;
        self.at
            .get(h.wrapping_sub(self.first))
            .copied()
            .unwrap_or(Self::OFF_LINE)
    }

    /// Whether a store into RAM word `i` changes an instruction this holds (the word's two
    /// halfwords, or a 32-bit instruction starting in the halfword before them).
    pub(crate) fn covers_word(&self, i: usize) -> bool {
        let h = 2 * i;
        h + 1 >= self.first && h < self.end + 1
    }

    /// The decoded instruction at halfword `h`, if `h` lies in the shared code.
    #[inline(always)]
    pub(crate) fn get(&self, h: usize) -> Option<u64> {
        self.ops.get(h).copied().filter(|&op| op != 0)
    }
}

/// The SoC: core, RAM, frame window and devices, with its input schedule. `Clone` copies the
/// whole machine (a snapshot); runs are deterministic.
#[derive(Clone)]
pub struct Soc {
    // ---- core
    /// x0..x31 (x0 is never written); the rest pads the array.
    pub(crate) x: [u32; 64],
    pub(crate) pc: u32,
    pub(crate) mstatus_mie: bool,
    pub(crate) mstatus_mpie: bool,
    /// Enabled interrupt lines ([`line`] bits).
    pub(crate) mie: u8,
    pub(crate) mcause_int: bool,
    pub(crate) mcause_code: u8,
    pub(crate) mscratch: u32,
    pub(crate) mepc: u32,
    pub(crate) mtvec: u32,
    pub(crate) mtval: u32,
    /// Register-file counter words: mcycle low, minstret low, mcycle high, minstret high.
    pub(crate) cnt: [u32; 4],
    /// The core's 6-bit cycle counter in cycle t is `(t - cyc_base) & 63`.
    pub(crate) cyc_base: u64,
    /// The next cycle in which that counter is 63 (it wraps at the end of it).
    pub(crate) next_cyc_wrap: u64,
    /// Increments of the core's 6-bit instruction counter so far.
    pub(crate) instret: u64,
    /// The 6-bit instruction counter is `(instret - ins_base) & 63`.
    pub(crate) ins_base: u64,
    /// The value of `instret` at which that counter wraps next.
    pub(crate) ins_wrap_at: u64,
    /// Pending counter carries ([`pend`] bits).
    pub(crate) pend: u8,
    pub(crate) ins_nohi: bool,
    /// The pending carries were raised while a WFI waited (their cycles count as sleep).
    pub(crate) cnt_wfi: bool,
    pub(crate) res_valid: bool,
    pub(crate) res_addr: u32,
    /// The next record is the first instruction of an interrupt handler.
    pub(crate) intr_flag: bool,
    /// The previous cycle stored to the word of the next instruction after it had been
    /// fetched: that instruction runs as the old word.
    pub(crate) stale: Option<u32>,
    pub(crate) amo_ex2: Option<AmoEx2>,

    // ---- memories
    pub(crate) ram: Vec<u32>,
    /// Decoded instructions by RAM halfword (0: not decoded); see `fast`.
    pub(crate) ops: Vec<u64>,
    /// The loaded image's decoded code, while nothing has stored into it.
    pub(crate) code: Option<std::sync::Arc<SharedCode>>,
    pub(crate) frame: Vec<u32>,

    // ---- devices
    pub(crate) vision: Option<Box<VisionUnit>>,
    pub(crate) clint: Clint,
    pub(crate) plic: Plic,
    pub(crate) uart: [Uart; 2],
    /// The test bench's external interrupt line as the core sees it (registered).
    pub(crate) tb: bool,
    /// A change of it: the cycle it is seen from and the level.
    pub(crate) tb_next: Option<(u64, bool)>,
    /// Interrupt lines ([`line`] bits) in cycle `dev_t` and every cycle until `next_dev`.
    pub(crate) lines: u8,
    pub(crate) dev_t: u64,
    pub(crate) next_dev: u64,
    pub(crate) rx_free: [u64; 2],

    // ---- time and accounting
    /// Cycles run (the harness's view).
    pub(crate) now: u64,
    /// The cycle the core's next step starts in; past `now` when the last instruction of a
    /// run ended after its `until` (the cycles in between touch nothing outside the core).
    pub(crate) core_at: u64,
    pub(crate) halt: Option<Halt>,
    /// The cycle after the exit register was written (the run's last).
    pub(crate) exit_at: u64,
    pub(crate) retired: u64,
    pub(crate) last_stamp: u64,
    pub(crate) sleep: u64,
    pub(crate) out: Vec<Stamped>,
    pub(crate) trace: Option<Vec<Retired>>,
}

impl core::fmt::Debug for Soc {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Soc")
            .field("cycle", &self.now)
            .field("pc", &format_args!("{:#010x}", self.pc))
            .field("halt", &self.halt)
            .field("stats", &self.stats())
            .finish_non_exhaustive()
    }
}

impl Default for Soc {
    fn default() -> Self {
        Self::new()
    }
}

impl Soc {
    /// The SoC just out of reset: RAM and frame window zeroed, the core at [`RAM_BASE`] in
    /// cycle 0.
    pub fn new() -> Self {
        let mut s = Self {
            x: [0; 64],
            pc: RAM_BASE,
            mstatus_mie: false,
            mstatus_mpie: false,
            mie: 0,
            mcause_int: false,
            mcause_code: 0,
            mscratch: 0,
            mepc: 0,
            mtvec: 0,
            mtval: 0,
            cnt: [0; 4],
            cyc_base: 0,
            next_cyc_wrap: 63,
            instret: 0,
            ins_base: 0,
            ins_wrap_at: 64,
            pend: 0,
            ins_nohi: false,
            cnt_wfi: false,
            res_valid: false,
            res_addr: 0,
            intr_flag: false,
            stale: None,
            amo_ex2: None,
            ram: vec![0; RAM_WORDS],
            ops: vec![0; RAM_HALVES],
            code: None,
            frame: vec![0; FRAME_WORDS],
            vision: Some(Box::new(VisionUnit::new())),
            clint: Clint::new(),
            plic: Plic::default(),
            uart: [Uart::new(), Uart::new()],
            tb: false,
            tb_next: None,
            lines: 0,
            dev_t: 0,
            next_dev: 0,
            rx_free: [0; 2],
            now: 0,
            core_at: 0,
            halt: None,
            exit_at: 0,
            retired: 0,
            last_stamp: 0,
            sleep: 0,
            out: Vec::new(),
            trace: None,
        };
        s.sync(0);
        s
    }

    /// Loads the file bytes of the PT_LOAD segments of an RV32 ELF image (entry point
    /// [`RAM_BASE`]) into RAM; the segments' zero-filled tails are left to RAM as it is (zero
    /// on a fresh SoC). Nothing is written unless every segment fits.
    pub fn load_elf(&mut self, elf: &[u8]) -> Result<(), LoadError> {
        let segs = elf::segments(elf)?;
        for seg in &segs {
            self.write_ram_bytes(seg.off, seg.data);
        }
        // The executable segments, decoded once for this SoC and its clones.
        let code = segs
            .iter()
            .filter(|s| s.exec && !s.data.is_empty())
            .map(|s| (s.off / 2, (s.off + s.data.len()).div_ceil(2)))
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)));
        self.code = code.map(|(first, end)| {
            // A table over all of RAM (zero, "not shared", outside the code; untouched pages
            // cost nothing), so the executor looks an instruction up without arithmetic.
            let mut ops = vec![0u64; RAM_HALVES].into_boxed_slice();
            for (h, op) in ops.iter_mut().enumerate().take(end).skip(first) {
                let off = (h * 2) as u32;
                *op = fast::decode_at(exec::fetch_ram(&self.ram, off), RAM_BASE.wrapping_add(off));
            }
            std::sync::Arc::new(SharedCode::new(first, end, ops))
        });
        Ok(())
    }

    /// Whether this SoC runs its image's code from the decoded copy it shares with its clones
    /// (until something stores into that code).
    pub fn shares_code(&self) -> bool {
        self.code.is_some()
    }

    /// Copies `words` into RAM at `addr`.
    pub fn load_words(&mut self, addr: u32, words: &[u32]) -> Result<(), WordsError> {
        if !addr.is_multiple_of(4) {
            return Err(WordsError::Unaligned { addr });
        }
        let off = u64::from(addr.wrapping_sub(RAM_BASE));
        if addr < RAM_BASE || off + 4 * words.len() as u64 > u64::from(RAM_SIZE) {
            return Err(WordsError::OutsideRam {
                addr,
                words: words.len(),
            });
        }
        let first = (off / 4) as usize;
        for (k, w) in words.iter().enumerate() {
            self.ram[first + k] = *w;
            self.forget(first + k);
        }
        Ok(())
    }

    fn write_ram_bytes(&mut self, off: usize, data: &[u8]) {
        for (k, b) in data.iter().enumerate() {
            let a = off + k;
            let (i, sh) = (a / 4, (a % 4) * 8);
            if let Some(w) = self.ram.get_mut(i) {
                *w = (*w & !(0xff << sh)) | u32::from(*b) << sh;
                self.forget(i);
            }
        }
    }

    /// Cycles run since reset.
    pub fn cycle(&self) -> u64 {
        self.now
    }

    /// Queues bytes for a UART's receiver, exactly as `verilator-tb`'s `Soc::send_at`: each
    /// arrives at `t = max(at, line free, cycle())`, and the line is then busy for one
    /// character time ([`CHAR_CYCLES`]).
    pub fn send_at(&mut self, port: Port, at: u64, bytes: &[u8]) {
        let i = port.index();
        for &b in bytes {
            let t = at.max(self.rx_free[i]).max(self.now);
            self.uart[i].push_rx(t, b);
            self.rx_free[i] = t + CHAR_CYCLES;
            // the byte enters the FIFO at the edge ending cycle t
            self.next_dev = self.next_dev.min(t + 1);
        }
    }

    /// Drives the test bench's external interrupt line (ORed into MEIP through a register):
    /// the core sees the new level from the cycle after [`Soc::cycle`].
    pub fn set_external_irq(&mut self, level: bool) {
        let at = self.now + 1;
        // an earlier change not yet seen happens first
        if let Some((e, v)) = self.tb_next {
            if e <= at {
                self.tb = v;
            }
        }
        self.tb_next = Some((at, level));
        self.next_dev = self.next_dev.min(at);
    }

    /// Runs every cycle before `until` (or until the program writes the exit register) and
    /// appends what the SoC emitted, stamped with its cycle, in cycle order. Returns the halt
    /// if there is one (see [`Halt`]).
    pub fn run_until(&mut self, until: u64, out: &mut Vec<Stamped>) -> Option<Halt> {
        self.run::<false>(until);
        self.flush(out);
        self.halt.clone()
    }

    /// Like [`Soc::run_until`], and also appends the retirement record of every instruction
    /// the core completed (including an instruction that started before `until` and ends
    /// after it).
    pub fn run_until_traced(
        &mut self,
        until: u64,
        out: &mut Vec<Stamped>,
        trace: &mut Vec<Retired>,
    ) -> Option<Halt> {
        self.trace = Some(std::mem::take(trace));
        self.run::<true>(until);
        self.flush(out);
        *trace = self.trace.take().unwrap_or_default();
        self.halt.clone()
    }

    fn flush(&mut self, out: &mut Vec<Stamped>) {
        let rank = |s: &Stamped| match s.output {
            Output::Tx {
                port: Port::Lbc, ..
            } => 0,
            Output::Tx {
                port: Port::Radio, ..
            } => 1,
            Output::Console(_) => 2,
        };
        self.out.sort_by_key(|s| (s.cycle, rank(s)));
        out.append(&mut self.out);
    }

    /// Why the SoC stopped, if it did.
    pub fn halted(&self) -> Option<&Halt> {
        self.halt.as_ref()
    }

    /// Writes `bytes` into the frame-grabber window at `offset`, between two cycles: loads
    /// from cycle [`Soc::cycle`] on see them.
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
        for (k, b) in bytes.iter().enumerate() {
            let a = offset + k;
            let sh = (a % 4) * 8;
            if let Some(w) = self.frame.get_mut(a / 4) {
                *w = (*w & !(0xff << sh)) | u32::from(*b) << sh;
            }
        }
        Ok(())
    }

    /// Gives the SoC a fresh vision unit, or takes it away (its region then reads as zero, as
    /// on a board without the unit).
    pub fn set_vision_unit(&mut self, present: bool) {
        self.vision = present.then(|| Box::new(VisionUnit::new()));
        self.next_dev = self.next_dev.min(self.now);
    }

    /// Whether the SoC has a vision unit.
    pub fn has_vision_unit(&self) -> bool {
        self.vision.is_some()
    }

    /// Streams a frame of RGB332 codes (`width` per row) into the vision unit's camera port,
    /// exactly as `verilator-tb`'s `Soc::camera_frame_at`: the stream starts at the first cycle
    /// at or after `max(at, cycle())` in which the previous frame's stream has ended, one pixel
    /// a cycle, `timing.h_blank` cycles between rows (the row's end in the first), the frame's
    /// end right after the last row's.
    pub fn camera_frame_at(
        &mut self,
        at: u64,
        codes: &[u8],
        width: u16,
        height: u16,
        timing: CameraTiming,
    ) -> Result<CameraFrame, CameraError> {
        let Some(unit) = self.vision.as_mut() else {
            return Err(CameraError::NoVisionUnit);
        };
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
        let (first, eof) = unit.queue(at.max(self.now), codes, width, height, timing);
        // the interrupt line may change when the frame is published
        self.next_dev = self.next_dev.min(eof + 3);
        Ok(CameraFrame { first, eof })
    }

    /// [`Soc::camera_frame_at`] from [`Soc::cycle`] on.
    pub fn camera_frame(
        &mut self,
        codes: &[u8],
        width: u16,
        height: u16,
        timing: CameraTiming,
    ) -> Result<CameraFrame, CameraError> {
        self.camera_frame_at(self.now, codes, width, height, timing)
    }

    /// Statistics up to [`Soc::cycle`].
    pub fn stats(&self) -> Stats {
        Stats {
            cycles: self.now,
            sleep_cycles: self.sleep,
            retired: self.retired - u64::from(self.last_stamp > self.now),
        }
    }

    /// The program counter of the next instruction.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// Integer register `r` (0..=31; others read 0).
    pub fn reg(&self, r: usize) -> u32 {
        if r < 32 {
            self.x[r]
        } else {
            0
        }
    }

    /// The RAM word at `addr` (`None` outside RAM).
    pub fn ram_word(&self, addr: u32) -> Option<u32> {
        let off = addr.wrapping_sub(RAM_BASE);
        (addr >= RAM_BASE && off < RAM_SIZE).then(|| self.ram[(off / 4) as usize])
    }
}
