//! Lockstep checker: runs a program on the RTL SoC and on the golden model side by side and
//! compares every RVFI retirement record with the model's.
//!
//! The model owns a copy of RAM; loads from devices take the value the RTL read (that is the
//! device's answer, not the core's). Values the model cannot know — mcycle reads and the
//! interrupt lines — come from the RVFI record: the lines the instruction saw, and on the first
//! instruction of a handler, the lines at the interrupt entry.

use crate::golden::{Bus, Hart, Retire};
use crate::model::Record;
use crate::soc::{CoreVariant, Event, Exit, Soc, Stamped, RAM_BASE, RAM_SIZE};

/// A disagreement between the RTL and the model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Mismatch {
    /// Records differ.
    Record { rtl: Retire, model: Retire },
    /// The RTL entered an interrupt handler the model had no enabled pending interrupt for.
    SpuriousInterrupt { rtl: Retire },
    /// The model would have taken an interrupt before this instruction; the RTL did not.
    MissedInterrupt { rtl: Retire, cause: u32 },
}

/// What a lockstep run produced.
#[derive(Debug)]
pub struct Run {
    /// The model after the last retired instruction (equal to the RTL's state so far).
    pub hart: Hart,
    /// The exit request, if the program wrote one.
    pub exit: Option<Exit>,
    /// Instructions checked.
    pub retired: u64,
    /// Clock cycles run.
    pub cycles: u64,
    /// Every event of the run.
    pub events: Vec<Stamped<Event>>,
    /// Every record checked with its cycle stamp, when asked for ([`Lockstep::keep_records`]).
    pub records: Vec<(u64, Retire)>,
}

/// The model's memory: a RAM image plus the last device read of the RTL.
#[derive(Debug)]
pub struct ModelBus {
    ram: Vec<u32>,
    device_rdata: u32,
}

impl ModelBus {
    fn new() -> Self {
        Self {
            ram: vec![0; (RAM_SIZE / 4) as usize],
            device_rdata: 0,
        }
    }

    fn ram_index(addr: u32) -> Option<usize> {
        let off = addr.wrapping_sub(RAM_BASE);
        (addr >= RAM_BASE && off < RAM_SIZE).then_some((off / 4) as usize)
    }

    /// Copies a program into the model's RAM.
    fn load(&mut self, addr: u32, words: &[u32]) {
        for (k, w) in words.iter().enumerate() {
            if let Some(i) = Self::ram_index(addr.wrapping_add(4 * k as u32)) {
                self.ram[i] = *w;
            }
        }
    }
}

impl Bus for ModelBus {
    fn load(&mut self, addr: u32) -> u32 {
        match Self::ram_index(addr) {
            Some(i) => self.ram[i],
            None => self.device_rdata,
        }
    }

    fn store(&mut self, addr: u32, mask: u8, data: u32) {
        if let Some(i) = Self::ram_index(addr) {
            let mut w = self.ram[i];
            for lane in 0..4 {
                if mask & (1 << lane) != 0 {
                    let m = 0xffu32 << (8 * lane);
                    w = (w & !m) | (data & m);
                }
            }
            self.ram[i] = w;
        }
    }
}

/// Stimulus applied at given cycles during a lockstep run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stimulus {
    /// Set the test bench external interrupt line.
    ExternalIrq(bool),
}

/// The golden model with its RAM, checking RVFI records one by one. [`Lockstep`] pairs one
/// with a [`Soc`]; [`crate::cosim::LbcCosim::with_checker`] checks a co-simulation.
#[derive(Debug)]
pub struct Checker {
    hart: Hart,
    bus: ModelBus,
    checked: u64,
    /// The core runs MUL* in its divider's loop, so they too finish before an interrupt
    /// that became pending while they ran.
    iterative_mul: bool,
}

impl Default for Checker {
    fn default() -> Self {
        Self::new()
    }
}

/// Drives a SoC and the golden model in lockstep.
#[derive(Debug)]
pub struct Lockstep {
    soc: Soc,
    checker: Checker,
    keep_records: bool,
}

impl Default for Lockstep {
    fn default() -> Self {
        Self::new()
    }
}

fn is_cycle_read(insn: u32) -> Option<bool> {
    if insn & 0x7f != 0b111_0011 || (insn >> 12) & 3 == 0 {
        return None;
    }
    match insn >> 20 {
        0xb00 | 0xc00 => Some(false),
        0xb80 | 0xc80 => Some(true),
        _ => None,
    }
}

impl Checker {
    /// A model at the reset address with zeroed RAM.
    pub fn new() -> Self {
        Self::with_core(CoreVariant::Dsp)
    }

    /// A model at the reset address with zeroed RAM, for an RTL core of variant `core`.
    pub fn with_core(core: CoreVariant) -> Self {
        Self {
            hart: Hart::new(RAM_BASE),
            bus: ModelBus::new(),
            checked: 0,
            iterative_mul: core.iterative_mul(),
        }
    }

    /// Copies words into the model's RAM (what was loaded into the SoC).
    pub fn load(&mut self, addr: u32, words: &[u32]) {
        self.bus.load(addr, words);
    }

    /// Loads an RV32 ELF image (see [`crate::soc::elf_segments`]) into the model's RAM.
    pub fn load_elf(&mut self, elf: &[u8]) -> Result<(), crate::soc::ElfError> {
        for (addr, words) in crate::soc::elf_segments(elf)? {
            self.bus.load(addr, &words);
        }
        Ok(())
    }

    /// The model's hart.
    pub fn hart(&self) -> &Hart {
        &self.hart
    }

    /// Records checked so far.
    pub fn checked(&self) -> u64 {
        self.checked
    }

    /// Checks one RTL record against the model; advances the model.
    pub(crate) fn check(&mut self, rec: &Record) -> Result<(), Mismatch> {
        let (rtl, mip, intr_mip) = (&rec.retire, rec.mip, rec.intr_mip);
        if rtl.intr {
            self.hart.irq_lines = intr_mip;
            if self.hart.take_interrupt().is_none() {
                return Err(Mismatch::SpuriousInterrupt { rtl: *rtl });
            }
        }
        self.hart.irq_lines = mip;
        // DIV, DIVU, REM, REMU (and MUL* on the sequential multiplier) run in the divider's
        // loop, which an interrupt does not break into: one that becomes pending meanwhile is
        // taken after the instruction. A compressed record holds its 16 bits: C.MUL (Zcb) is
        // the one compressed form that runs there.
        let insn = soc_model::rvc::as_32bit(rtl.insn);
        let in_loop = if self.iterative_mul {
            insn & 0xfe00_007f == 0x0200_0033
        } else {
            insn & 0xfe00_407f == 0x0200_4033
        };
        if !rtl.intr && rtl.insn != crate::isa::WFI && !in_loop {
            if let Some(cause) = self.hart.pending_interrupt() {
                return Err(Mismatch::MissedInterrupt { rtl: *rtl, cause });
            }
        }
        if let Some(high) = is_cycle_read(rtl.insn) {
            if !rtl.trap && rtl.rd_addr != 0 {
                let v = u64::from(rtl.rd_wdata);
                self.hart.mcycle = if high {
                    (self.hart.mcycle & 0xffff_ffff) | (v << 32)
                } else {
                    (self.hart.mcycle & !0xffff_ffff) | v
                };
            }
        }
        self.bus.device_rdata = rtl.mem_rdata;
        let mut model = self.hart.step(&mut self.bus);
        model.intr = rtl.intr;
        if model != *rtl {
            return Err(Mismatch::Record { rtl: *rtl, model });
        }
        self.checked += 1;
        Ok(())
    }
}

impl Lockstep {
    /// A fresh SoC and model.
    pub fn new() -> Self {
        Self::with_core(CoreVariant::Dsp)
    }

    /// A fresh SoC whose core is `core`, and the model.
    pub fn with_core(core: CoreVariant) -> Self {
        Self {
            soc: Soc::with_core(core),
            checker: Checker::with_core(core),
            keep_records: false,
        }
    }

    /// Loads words at `addr` into both.
    pub fn load(&mut self, addr: u32, words: &[u32]) -> Result<(), crate::soc::LoadError> {
        self.soc.load_words(addr, words)?;
        self.checker.load(addr, words);
        Ok(())
    }

    /// Loads an RV32 ELF image (see [`crate::soc::elf_segments`]) into both.
    pub fn load_elf(&mut self, elf: &[u8]) -> Result<(), crate::soc::ElfError> {
        for (addr, words) in crate::soc::elf_segments(elf)? {
            self.load(addr, &words)
                .map_err(crate::soc::ElfError::Segment)?;
        }
        Ok(())
    }

    /// A word of the model's RAM (equal to the RTL's after a clean run).
    pub fn model_word(&self, addr: u32) -> Option<u32> {
        ModelBus::ram_index(addr).map(|i| self.checker.bus.ram[i])
    }

    /// Makes [`Lockstep::run`] return every record it checked, with its cycle stamp.
    pub fn keep_records(&mut self) {
        self.keep_records = true;
    }

    /// The SoC, for stimulus.
    pub fn soc_mut(&mut self) -> &mut Soc {
        &mut self.soc
    }

    /// Releases reset and runs until the program exits, `max_retire` instructions retired, or
    /// `max_cycles` passed, checking every retirement. Each of `stimuli` is applied before the
    /// clock cycle with its number.
    pub fn run(
        &mut self,
        max_retire: u64,
        max_cycles: u64,
        stimuli: &[(u64, Stimulus)],
    ) -> Result<Run, Mismatch> {
        /// Longest batch of cycles between two looks at the records.
        const BATCH: u64 = 4096;
        self.soc.release();
        let mut events = Vec::new();
        let mut exit = None;
        let mut retired = 0;
        let mut kept = Vec::new();
        let mut stimuli: Vec<(u64, Stimulus)> = stimuli.to_vec();
        stimuli.sort_by_key(|s| s.0);
        let mut next = 0;
        'run: while retired < max_retire && self.soc.cycle() < max_cycles && exit.is_none() {
            while let Some((at, s)) = stimuli.get(next) {
                if *at > self.soc.cycle() {
                    break;
                }
                if *at == self.soc.cycle() {
                    match s {
                        Stimulus::ExternalIrq(level) => self.soc.set_external_irq(*level),
                    }
                }
                next += 1;
            }
            let until_stimulus = stimuli
                .get(next)
                .map_or(u64::MAX, |(at, _)| at - self.soc.cycle());
            let n = BATCH.min(until_stimulus).min(max_cycles - self.soc.cycle());
            let (records, evs) = self.soc.batch(n, true, false);
            for e in evs {
                if let Event::Exit(x) = e.value {
                    exit = Some(x);
                }
                events.push(e);
            }
            for rec in &records {
                if retired >= max_retire {
                    break 'run;
                }
                self.checker.check(rec)?;
                if self.keep_records {
                    kept.push((rec.cycle, rec.retire));
                }
                retired += 1;
            }
        }
        Ok(Run {
            hart: self.checker.hart.clone(),
            exit,
            retired,
            cycles: self.soc.cycle(),
            events,
            records: kept,
        })
    }
}
