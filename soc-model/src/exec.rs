//! The core (`rtl/rv_core.v`) at instruction granularity with the RTL's exact cycle costs, the
//! memory map (`rtl/soc.v`), and the run loop.
//!
//! Timeline of one instruction whose EXEC cycle is `c` (`core_at`):
//! - the interrupt lines are sampled in `c`; an enabled pending interrupt (with `mstatus.MIE`)
//!   is taken instead of the instruction, unless it is a WFI: two cycles, no record;
//! - most instructions complete in `c` (record stamped `c + 1`); a CSR instruction that writes
//!   a register-file CSR retires in `c` and writes the CSR in `c + 1`; an AMO reads in `c` and
//!   writes and retires in `c + 1`; DIV/REM complete in `c + 33`; an exception writes mtval in
//!   `c` and mepc in `c + 1` (record stamped `c + 2`); a WFI with nothing enabled pending
//!   stalls;
//! - after the last cycle, one counter-carry (CNT) cycle per pending carry, then the next EXEC.
//!
//! The cycle counter's six low bits wrap every 64 cycles and the instruction counter's every 64
//! retirements; each wrap raises a carry into the register-file word, taken as a CNT cycle at
//! the next instruction boundary (with a second one when the low word overflows). Wraps are
//! found by comparing cycle and retirement counts with the next wrap point, so nothing is
//! counted per instruction beyond those two numbers.

use crate::dev::Access;
use crate::hart::Retire;
use crate::{
    line, map, pend, AmoEx2, Halt, Output, Retired, Soc, Stamped, StuckReason, FRAME_WORDS,
    RAM_BASE, RAM_SIZE,
};

const WFI: u32 = 0x1050_0073;

/// Memory fields of a retirement record.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Mem {
    pub addr: u32,
    pub rmask: u8,
    pub wmask: u8,
    pub rdata: u32,
    pub wdata: u32,
}

fn lane_mask(addr: u32, size: u32) -> u8 {
    let base: u8 = match size {
        0 => 0b0001,
        1 => 0b0011,
        _ => 0b1111,
    };
    base << (addr & 3)
}

fn misaligned(addr: u32, size: u32) -> bool {
    match size {
        1 => addr & 1 != 0,
        2 => addr & 3 != 0,
        _ => false,
    }
}

/// Whether the RAM word at aligned address `word` holds any of the 32 bits fetched at `next`.
pub(crate) fn fetched_word(word: u32, next: u32) -> bool {
    word == next & !3 || word == next.wrapping_add(2) & !3
}

/// The 32 bits at halfword offset `off` of RAM.
pub(crate) fn fetch_ram(ram: &[u32], off: u32) -> u32 {
    let i = (off >> 2) as usize & (crate::RAM_WORDS - 1);
    if off & 2 == 0 {
        ram[i]
    } else {
        ram[i] >> 16 | ram[(i + 1) & (crate::RAM_WORDS - 1)] << 16
    }
}

/// Drops the decoded instructions (by halfword) that overlap RAM word `i`.
pub(crate) fn forget_word(ops: &mut [u64], i: usize) {
    let n = ops.len();
    for h in [2 * i, 2 * i + 1, (2 * i + n - 1) % n] {
        if let Some(op) = ops.get_mut(h) {
            *op = 0;
        }
    }
}

/// DIV/DIVU/REM/REMU (`f3` 4..=7) as the RTL's divider computes them (the ISA's results).
pub(crate) fn divide(f3: u32, a: u32, b: u32) -> u32 {
    crate::hart::divide(f3, a, b)
}

/// The implemented CSR addresses (legality decodes all 12 bits).
fn csr_exists(addr: u32) -> bool {
    matches!(
        addr,
        0x300
            | 0x301
            | 0x304
            | 0x305
            | 0x310
            | 0x340
            | 0x341
            | 0x342
            | 0x343
            | 0x344
            | 0xb00
            | 0xc00
            | 0xb80
            | 0xc80
            | 0xb02
            | 0xc02
            | 0xb82
            | 0xc82
            | 0xf11
            | 0xf12
            | 0xf13
            | 0xf14
            | 0xf15
    )
}

/// Line bits to their mip/mie positions.
fn line_bits(l: u8) -> u32 {
    u32::from(l & line::MSI) << 3
        | u32::from((l & line::MTI) >> 1) << 7
        | u32::from((l & line::MEI) >> 2) << 11
}

/// Where a data address goes (`rtl/soc.v`'s decode).
enum Target {
    Ram(usize),
    Frame(usize),
    Sim(u32),
    Clint(u32),
    Plic(u32),
    Uart(usize, bool),
    Vision(u32),
    None,
}

fn target(addr: u32) -> Target {
    if addr >> 20 == 0x800 {
        Target::Ram(((addr >> 2) & 0x3_ffff) as usize)
    } else if addr >> 24 == 0x81 && ((addr >> 2) & 0x3f_ffff) < FRAME_WORDS as u32 {
        Target::Frame(((addr >> 2) & 0x3f_ffff) as usize)
    } else if addr >> 4 == map::SIM_CTRL >> 4 {
        Target::Sim((addr >> 2) & 3)
    } else if addr >> 16 == map::CLINT >> 16 {
        Target::Clint(addr & 0xfffc)
    } else if addr >> 22 == map::PLIC >> 22 {
        Target::Plic(addr & 0x3f_fffc)
    } else if addr >> 3 == map::UART0 >> 3 {
        Target::Uart(0, addr & 4 != 0)
    } else if addr >> 3 == map::UART1 >> 3 {
        Target::Uart(1, addr & 4 != 0)
    } else if addr >> 16 == map::VISION >> 16 {
        Target::Vision(addr & 0xfffc)
    } else {
        Target::None
    }
}

fn merge(old: u32, wstrb: u8, data: u32) -> u32 {
    let mut w = old;
    for lane in 0..4 {
        if wstrb & (1 << lane) != 0 {
            let m = 0xffu32 << (8 * lane);
            w = (w & !m) | (data & m);
        }
    }
    w
}

impl Soc {
    // ------------------------------------------------------------------ devices and time

    /// Brings the devices to cycle `t` (emitting what they finish before it) and works out the
    /// interrupt lines in `t` and the first later cycle they may change in.
    pub(crate) fn sync(&mut self, t: u64) {
        let out = &mut self.out;
        for (i, u) in self.uart.iter_mut().enumerate() {
            let port = if i == 0 {
                crate::Port::Lbc
            } else {
                crate::Port::Radio
            };
            u.advance_to(t, &mut |cycle, byte| {
                out.push(Stamped {
                    cycle,
                    output: Output::Tx { port, byte },
                });
            });
        }
        if let Some((e, v)) = self.tb_next {
            if e <= t {
                self.tb = v;
                self.tb_next = None;
            }
        }
        self.dev_t = t;
        let src = self.irq_sources(t);
        let mei = self.plic.eip(src) || self.tb;
        self.lines =
            u8::from(self.clint.msip) | u8::from(self.clint.mtip(t)) << 1 | u8::from(mei) << 2;
        let mut next = self.uart[0]
            .next_change()
            .min(self.uart[1].next_change())
            .min(self.clint.next_change(t));
        if let Some((e, _)) = self.tb_next {
            next = next.min(e);
        }
        if let Some(v) = self.vision.as_ref() {
            next = next.min(v.next_change());
        }
        self.next_dev = next;
    }

    /// The PLIC's source levels in cycle `t` (bit n = source n), with the devices brought to
    /// `t`.
    fn irq_sources(&mut self, t: u64) -> u16 {
        let vision = self.vision.as_mut().is_some_and(|v| {
            v.advance_to(t);
            v.irq()
        });
        u16::from(self.uart[0].irq()) << 10
            | u16::from(self.uart[1].irq()) << 11
            | u16::from(vision) << crate::irq::VISION
    }

    /// Interrupt lines that are high or that something other than the core could still raise
    /// (the timer always can; a UART can while its receiver or a draining transmitter may
    /// interrupt and the PLIC passes it on).
    fn possible_lines(&self) -> u8 {
        let mut p = line::MTI | (self.lines & line::MEI);
        if self.clint.msip {
            p |= line::MSI;
        }
        let uart_can = |i: usize, src: u8| self.plic.can_signal(src) && self.uart[i].irq_possible();
        let vision_can = self.plic.can_signal(crate::irq::VISION as u8)
            && self.vision.as_ref().is_some_and(|v| v.irq_possible());
        if self.mie & line::MEI != 0
            && (self.tb
                || self.tb_next.is_some()
                || uart_can(0, 10)
                || uart_can(1, 11)
                || vision_can)
        {
            p |= line::MEI;
        }
        p
    }

    fn stuck(&mut self, reason: StuckReason) {
        if self.halt.is_none() {
            self.halt = Some(Halt::Stuck {
                pc: self.pc,
                reason,
            });
        }
    }

    /// Reads the word at aligned address `addr` in cycle `c`, with the read side effects of
    /// the lanes in `rmask` when `re`.
    fn load_word(&mut self, c: u64, addr: u32, rmask: u8, re: bool) -> u32 {
        match target(addr) {
            Target::Ram(i) => self.ram[i],
            Target::Frame(i) => self.frame[i],
            Target::Sim(_) | Target::None => 0,
            Target::Clint(off) => self.clint.read(c, off),
            Target::Plic(off) => {
                self.sync(c);
                let src = self.irq_sources(c);
                let v = self.plic.read(off, re, src);
                self.next_dev = c + 1;
                v
            }
            Target::Uart(u, hi) => {
                self.sync(c);
                let v = self.uart[u].rdata(hi);
                if re {
                    let acc = Access {
                        addr_hi: hi,
                        re,
                        rmask,
                        ..Access::default()
                    };
                    self.uart_access(u, acc);
                    self.next_dev = c + 1;
                }
                v
            }
            Target::Vision(off) => self.vision.as_mut().map_or(0, |v| v.read(c, off)),
        }
    }

    fn uart_access(&mut self, u: usize, acc: Access) {
        let out = &mut self.out;
        let port = if u == 0 {
            crate::Port::Lbc
        } else {
            crate::Port::Radio
        };
        if let Some(uart) = self.uart.get_mut(u) {
            uart.step(Some(acc), &mut |cycle, byte| {
                out.push(Stamped {
                    cycle,
                    output: Output::Tx { port, byte },
                });
            });
        }
    }

    /// Writes the lanes `wstrb` of `wdata` at aligned address `addr` in cycle `c`; `next` is
    /// the address of the instruction after the writing one, whose 32 bits were fetched at the
    /// same clock edge (a store into them is not seen by it).
    fn store_word(&mut self, c: u64, next: u32, addr: u32, wstrb: u8, wdata: u32) {
        match target(addr) {
            Target::Ram(i) => {
                let fetched = fetched_word(addr, next).then(|| self.fetch(next));
                self.ram[i] = merge(self.ram[i], wstrb, wdata);
                self.forget(i);
                if fetched.is_some() {
                    self.stale = fetched;
                }
            }
            Target::Frame(i) => self.frame[i] = merge(self.frame[i], wstrb, wdata),
            Target::Sim(reg) => {
                if reg == 0 {
                    self.halt = Some(Halt::Exit { value: wdata });
                    self.exit_at = c + 1;
                } else if reg == 1 && wstrb & 1 != 0 {
                    self.out.push(Stamped {
                        cycle: c + 1,
                        output: Output::Console(wdata as u8),
                    });
                }
            }
            Target::Clint(off) => {
                self.clint.write(c, off, wstrb, wdata);
                self.next_dev = self.next_dev.min(c + 1);
            }
            Target::Plic(off) => {
                self.plic.write(off, wdata);
                self.next_dev = self.next_dev.min(c + 1);
            }
            Target::Uart(u, hi) => {
                self.sync(c);
                let acc = Access {
                    addr_hi: hi,
                    wstrb,
                    wdata,
                    ..Access::default()
                };
                self.uart_access(u, acc);
                self.next_dev = c + 1;
            }
            Target::Vision(off) => {
                if let Some(v) = self.vision.as_mut() {
                    v.write(c, off, wstrb, wdata);
                    // the interrupt line may change from the next cycle
                    self.next_dev = self.next_dev.min(c + 1);
                }
            }
            Target::None => {}
        }
    }

    /// The 32 bits the fetch stage reads at the halfword address `pc` (zero outside RAM, which
    /// is illegal): two halfword banks, the upper half from the next word when `pc` is in the
    /// middle of one (wrapping at the end of RAM as the bank address does).
    pub(crate) fn fetch(&self, pc: u32) -> u32 {
        let off = pc.wrapping_sub(RAM_BASE);
        if off < RAM_SIZE {
            fetch_ram(&self.ram, off)
        } else {
            0
        }
    }

    /// Drops the decoded instructions that overlap RAM word `i`: those starting in it and a
    /// 32-bit one starting in the upper half of the word before.
    pub(crate) fn forget(&mut self, i: usize) {
        forget_word(&mut self.ops, i);
        if self.code.as_ref().is_some_and(|c| c.covers_word(i)) {
            // The shared decoding no longer matches this SoC's RAM: decode privately.
            self.code = None;
        }
    }

    // ------------------------------------------------------------------ counters

    /// Raises the carries of counter wraps that happened in the cycles and retirements so far.
    pub(crate) fn settle(&mut self) {
        if self.core_at > self.next_cyc_wrap {
            self.pend |= pend::CYC_LO;
            self.next_cyc_wrap += 64;
        }
        if self.instret >= self.ins_wrap_at {
            self.pend |= pend::INS_LO;
            self.ins_nohi = false;
            self.ins_wrap_at += 64;
        }
    }

    /// One counter-carry cycle for the first pending carry (cycle low, cycle high, instret
    /// low, instret high).
    pub(crate) fn cnt_cycle(&mut self) {
        let c = self.core_at;
        let wrap = c == self.next_cyc_wrap;
        let p = self.pend;
        let cyc_lo = p & pend::CYC_LO != 0;
        if cyc_lo {
            let (v, carry) = self.cnt[0].overflowing_add(64);
            self.cnt[0] = v;
            self.pend &= !pend::CYC_LO;
            if carry {
                self.pend |= pend::CYC_HI;
            }
        } else if p & pend::CYC_HI != 0 {
            self.cnt[2] = self.cnt[2].wrapping_add(1);
            self.pend &= !pend::CYC_HI;
        } else if p & pend::INS_LO != 0 {
            let (v, carry) = self.cnt[1].overflowing_add(64);
            self.cnt[1] = v;
            self.pend &= !pend::INS_LO;
            if carry && !self.ins_nohi {
                self.pend |= pend::INS_HI;
            }
        } else {
            self.cnt[3] = self.cnt[3].wrapping_add(1);
            self.pend &= !pend::INS_HI;
        }
        if wrap {
            // a wrap in the cycle that carries the previous one is lost (it cannot happen:
            // a carry never waits 64 cycles), as in the RTL
            self.next_cyc_wrap += 64;
            if !cyc_lo {
                self.pend |= pend::CYC_LO;
            }
        }
        if self.cnt_wfi {
            self.sleep += 1;
        }
        self.core_at = c + 1;
        // the cycle re-fetches the next instruction
        self.stale = None;
    }

    fn cyc_lo(&self, c: u64) -> u32 {
        (c.wrapping_sub(self.cyc_base) & 63) as u32
    }

    fn ins_lo(&self) -> u32 {
        (self.instret.wrapping_sub(self.ins_base) & 63) as u32
    }

    // ------------------------------------------------------------------ run loop

    /// Runs every cycle before `until` (see [`Soc::run_until`]).
    pub(crate) fn run<const TRACE: bool>(&mut self, until: u64) {
        if matches!(self.halt, Some(Halt::Exit { .. })) {
            return;
        }
        let mut exit_at = None;
        while self.core_at < until {
            self.settle();
            if self.pend != 0 {
                self.cnt_cycle();
                continue;
            }
            if self.core_at >= self.next_dev {
                self.sync(self.core_at);
            }
            let c = self.core_at;
            if let Some(a) = self.amo_ex2.take() {
                self.amo_finish::<TRACE>(c, a);
            } else {
                let insn = match self.stale {
                    Some(w) => w,
                    None => self.fetch(self.pc),
                };
                if self.mstatus_mie && self.lines & self.mie != 0 && insn != WFI {
                    self.interrupt();
                    continue;
                }
                if self.stale.take().is_some() {
                    self.exec::<TRACE>(insn, until);
                } else {
                    self.fast::<TRACE>(until);
                }
            }
            if matches!(self.halt, Some(Halt::Exit { .. })) {
                exit_at = Some(self.exit_at);
                break;
            }
        }
        let end = exit_at.unwrap_or(until).max(self.now);
        // the devices emit what they finish before `end`; nothing changes before `next_dev`
        if end > self.dev_t && end >= self.next_dev {
            self.sync(end);
        }
        self.now = end;
    }

    // ------------------------------------------------------------------ retirement

    fn record(&mut self, stamp: u64, r: Retire) {
        if let Some(t) = self.trace.as_mut() {
            t.push(Retired {
                cycle: stamp,
                retire: r,
            });
        }
    }

    /// Completes an instruction that retires: `rd` (architectural, 0 for none) gets `val`, the
    /// next instruction is `next`; the instruction took `cycles` from `c`, its record is
    /// stamped `c + stamp`; `inc` counts it in minstret.
    #[allow(clippy::too_many_arguments)]
    fn commit<const TRACE: bool>(
        &mut self,
        c: u64,
        insn: u32,
        rd: u32,
        val: u32,
        next: u32,
        cycles: u64,
        stamp: u64,
        inc: bool,
        mem: Mem,
    ) {
        let pc = self.pc;
        if rd != 0 {
            self.x[rd as usize & 31] = val;
        }
        self.pc = next;
        self.core_at = c + cycles;
        self.retired += 1;
        self.last_stamp = c + stamp;
        if inc {
            self.instret += 1;
        }
        self.cnt_wfi = false;
        if TRACE {
            let r = Retire {
                order: self.retired,
                insn,
                trap: false,
                intr: self.intr_flag,
                pc_rdata: pc,
                pc_wdata: next,
                rd_addr: rd as u8,
                rd_wdata: if rd != 0 { val } else { 0 },
                mem_addr: mem.addr,
                mem_rmask: mem.rmask,
                mem_wmask: mem.wmask,
                mem_rdata: mem.rdata,
                mem_wdata: mem.wdata,
            };
            self.record(c + stamp, r);
        }
        self.intr_flag = false;
    }

    /// The handler address for the cause in mcause.
    fn trap_pc(&self) -> u32 {
        let vec = if self.mcause_int && self.mtvec & 1 != 0 {
            u32::from(self.mcause_code) << 2
        } else {
            0
        };
        (self.mtvec & !0x3f) | ((self.mtvec & 0x3c) | vec)
    }

    /// An exception raised by the instruction in EXEC cycle `c`.
    fn exception<const TRACE: bool>(&mut self, c: u64, insn: u32, cause: u8, tval: u32) {
        let pc = self.pc;
        self.mtval = tval;
        self.mcause_int = false;
        self.mcause_code = cause;
        self.mstatus_mpie = self.mstatus_mie;
        self.mstatus_mie = false;
        self.mepc = pc;
        let handler = self.trap_pc();
        self.pc = handler;
        self.core_at = c + 2;
        self.retired += 1;
        self.last_stamp = c + 2;
        self.cnt_wfi = false;
        if TRACE {
            let r = Retire {
                order: self.retired,
                insn,
                trap: true,
                intr: self.intr_flag,
                pc_rdata: pc,
                pc_wdata: handler,
                ..Retire::default()
            };
            self.record(c + 2, r);
        }
        self.intr_flag = false;
    }

    /// Takes the pending enabled interrupt instead of the instruction at `pc`.
    fn interrupt(&mut self) {
        let c = self.core_at;
        let p = self.lines & self.mie;
        let cause = if p & line::MEI != 0 {
            11
        } else if p & line::MSI != 0 {
            3
        } else {
            7
        };
        self.mtval = 0;
        self.mcause_int = true;
        self.mcause_code = cause;
        self.mstatus_mpie = self.mstatus_mie;
        self.mstatus_mie = false;
        self.mepc = self.pc;
        self.pc = self.trap_pc();
        self.core_at = c + 2;
        self.intr_flag = true;
        self.cnt_wfi = false;
        self.stale = None;
    }

    // ------------------------------------------------------------------ execution

    /// Executes the instruction at `pc`, of which `fetched` are the 32 bits read there, in EXEC
    /// cycle `core_at`, with every case the RTL has; `until` bounds a WFI's wait. A compressed
    /// instruction runs as its 32-bit form; its record shows the 16 bits (so does mtval when
    /// it is illegal: it then arrives as those 16 bits, whose low bits are not 11).
    pub(crate) fn exec<const TRACE: bool>(&mut self, fetched: u32, until: u64) {
        let c = self.core_at;
        let pc = self.pc;
        let (insn, raw, len) = if crate::rvc::is_compressed(fetched) {
            let lo = fetched & 0xffff;
            (crate::rvc::expand(lo as u16).unwrap_or(lo), lo, 2)
        } else {
            (fetched, fetched, 4)
        };
        let opcode = insn & 0x7f;
        let rd = (insn >> 7) & 31;
        let f3 = (insn >> 12) & 7;
        let rs1 = ((insn >> 15) & 31) as usize;
        let rs2 = ((insn >> 20) & 31) as usize;
        let f7 = insn >> 25;
        let a = self.x[rs1];
        let b = self.x[rs2];
        let imm_i = (insn as i32 >> 20) as u32;
        let imm_s = (((insn as i32) >> 25) << 5) as u32 | ((insn >> 7) & 0x1f);
        let next = pc.wrapping_add(len);
        let none = Mem::default();
        let illegal = |s: &mut Self| s.exception::<TRACE>(c, raw, 2, raw);
        match opcode {
            0b011_0111 => {
                self.commit::<TRACE>(c, raw, rd, insn & 0xffff_f000, next, 1, 1, true, none)
            }
            0b001_0111 => {
                let v = pc.wrapping_add(insn & 0xffff_f000);
                self.commit::<TRACE>(c, raw, rd, v, next, 1, 1, true, none);
            }
            0b110_1111 => {
                let imm_j = ((((insn as i32) >> 31) << 20) as u32)
                    | (insn & 0x000f_f000)
                    | (((insn >> 20) & 1) << 11)
                    | (((insn >> 21) & 0x3ff) << 1);
                let t = pc.wrapping_add(imm_j);
                self.jump::<TRACE>(c, raw, rd, t, len);
            }
            0b110_0111 if f3 == 0 => {
                let sum = a.wrapping_add(imm_i);
                self.jump::<TRACE>(c, raw, rd, sum & !1, len);
            }
            0b110_0011 if f3 != 2 && f3 != 3 => {
                let taken = match f3 {
                    0 => a == b,
                    1 => a != b,
                    4 => (a as i32) < (b as i32),
                    5 => (a as i32) >= (b as i32),
                    6 => a < b,
                    _ => a >= b,
                };
                if taken {
                    let imm_b = ((((insn as i32) >> 31) << 12) as u32)
                        | (((insn >> 7) & 1) << 11)
                        | (((insn >> 25) & 0x3f) << 5)
                        | (((insn >> 8) & 0xf) << 1);
                    self.jump::<TRACE>(c, raw, 0, pc.wrapping_add(imm_b), len);
                } else {
                    self.commit::<TRACE>(c, raw, 0, 0, next, 1, 1, true, none);
                }
            }
            0b000_0011 if matches!(f3, 0 | 1 | 2 | 4 | 5) => {
                let addr = a.wrapping_add(imm_i);
                if misaligned(addr, f3 & 3) {
                    return self.exception::<TRACE>(c, raw, 4, addr);
                }
                let mask = lane_mask(addr, f3 & 3);
                let word = self.load_word(c, addr & !3, mask, true);
                let v = word >> ((addr & 3) * 8);
                let v = match f3 {
                    0 => v as u8 as i8 as i32 as u32,
                    1 => v as u16 as i16 as i32 as u32,
                    4 => v & 0xff,
                    5 => v & 0xffff,
                    _ => word,
                };
                let mem = Mem {
                    addr: addr & !3,
                    rmask: mask,
                    rdata: word,
                    ..Mem::default()
                };
                self.commit::<TRACE>(c, raw, rd, v, next, 1, 1, true, mem);
            }
            0b010_0011 if f3 <= 2 => {
                let addr = a.wrapping_add(imm_s);
                if misaligned(addr, f3) {
                    return self.exception::<TRACE>(c, raw, 6, addr);
                }
                let data = match f3 {
                    0 => (b & 0xff) * 0x0101_0101,
                    1 => (b & 0xffff) * 0x0001_0001,
                    _ => b,
                };
                let mask = lane_mask(addr, f3);
                self.store_word(c, next, addr & !3, mask, data);
                let mem = Mem {
                    addr: addr & !3,
                    wmask: mask,
                    wdata: data,
                    ..Mem::default()
                };
                self.commit::<TRACE>(c, raw, 0, 0, next, 1, 1, true, mem);
            }
            0b001_0011 => {
                let sh = imm_i & 31;
                let v = match f3 {
                    0 => a.wrapping_add(imm_i),
                    1 if f7 == 0 => a << sh,
                    2 => u32::from((a as i32) < (imm_i as i32)),
                    3 => u32::from(a < imm_i),
                    4 => a ^ imm_i,
                    5 if f7 == 0 => a >> sh,
                    5 if f7 == 0x20 => ((a as i32) >> sh) as u32,
                    6 => a | imm_i,
                    7 => a & imm_i,
                    _ => return illegal(self),
                };
                self.commit::<TRACE>(c, raw, rd, v, next, 1, 1, true, none);
            }
            0b011_0011 if f7 == 1 => {
                let (v, cycles) = match f3 {
                    0 => (a.wrapping_mul(b), 1),
                    1 => (
                        ((i64::from(a as i32) * i64::from(b as i32)) >> 32) as u32,
                        1,
                    ),
                    2 => (((i64::from(a as i32) * i64::from(b)) >> 32) as u32, 1),
                    3 => (((u64::from(a) * u64::from(b)) >> 32) as u32, 1),
                    _ => (divide(f3, a, b), 34),
                };
                self.commit::<TRACE>(c, raw, rd, v, next, cycles, cycles, true, none);
            }
            0b011_0011 => {
                let sh = b & 31;
                let v = match (f7, f3) {
                    (0, 0) => a.wrapping_add(b),
                    (0x20, 0) => a.wrapping_sub(b),
                    (0, 1) => a << sh,
                    (0, 2) => u32::from((a as i32) < (b as i32)),
                    (0, 3) => u32::from(a < b),
                    (0, 4) => a ^ b,
                    (0, 5) => a >> sh,
                    (0x20, 5) => ((a as i32) >> sh) as u32,
                    (0, 6) => a | b,
                    (0, 7) => a & b,
                    _ => return illegal(self),
                };
                self.commit::<TRACE>(c, raw, rd, v, next, 1, 1, true, none);
            }
            0b000_1111 if f3 == 0 => self.commit::<TRACE>(c, raw, 0, 0, next, 1, 1, true, none),
            0b111_0011 => self.system::<TRACE>(c, insn, raw, until),
            0b010_1111 if f3 == 2 => self.atomic::<TRACE>(c, insn, until),
            _ => illegal(self),
        }
    }

    /// JAL, JALR or a taken branch to `t` (bit 0 already clear, so never misaligned with C);
    /// `rd` 0 for branches; `len` is the instruction's length (the link is `pc + len`).
    fn jump<const TRACE: bool>(&mut self, c: u64, insn: u32, rd: u32, t: u32, len: u32) {
        let pc = self.pc;
        if t == pc && (!self.mstatus_mie || self.mie & self.possible_lines() == 0) {
            self.stuck(StuckReason::SpinWithoutInterrupt);
        }
        self.commit::<TRACE>(
            c,
            insn,
            rd,
            pc.wrapping_add(len),
            t,
            1,
            1,
            true,
            Mem::default(),
        );
    }

    /// SYSTEM instructions; `raw` is the instruction as fetched (C.EBREAK's 16 bits).
    fn system<const TRACE: bool>(&mut self, c: u64, insn: u32, raw: u32, until: u64) {
        let f3 = (insn >> 12) & 7;
        let next = self.pc.wrapping_add(4);
        let none = Mem::default();
        match (f3, insn) {
            (0, 0x0000_0073) => self.exception::<TRACE>(c, insn, 11, 0),
            (0, 0x0010_0073) => self.exception::<TRACE>(c, raw, 3, 0),
            (0, 0x3020_0073) => {
                self.mstatus_mie = self.mstatus_mpie;
                self.mstatus_mpie = true;
                let t = self.mepc;
                self.commit::<TRACE>(c, insn, 0, 0, t, 1, 1, true, none);
            }
            (0, WFI) => {
                if self.lines & self.mie != 0 {
                    self.commit::<TRACE>(c, insn, 0, 0, next, 1, 1, true, none);
                } else {
                    if self.halt.is_none() && self.mie & self.possible_lines() == 0 {
                        self.stuck(StuckReason::WfiWithoutWakeup);
                    }
                    let target = until.min(self.next_dev);
                    self.wfi_wait(target);
                }
            }
            (0 | 4, _) => self.exception::<TRACE>(c, insn, 2, insn),
            _ => self.csr::<TRACE>(c, insn),
        }
    }

    /// A WFI stalls from `core_at` (nothing enabled is pending) up to `target`; the lines do
    /// not change before it. Every cycle sleeps; the cycle counter's carries are taken in
    /// between (their CNT cycles sleep too), worked out arithmetically.
    fn wfi_wait(&mut self, target: u64) {
        let c = self.core_at;
        debug_assert!(target > c);
        self.sleep += target - c;
        self.cnt_wfi = true;
        let mut w = self.next_cyc_wrap;
        if w + 3 <= target {
            // whole carries: each wrap's CNT cycle (and the high word's) ends before target
            let n = (target - 3 - w) / 64 + 1;
            let total = u64::from(self.cnt[0]) + 64 * n;
            self.cnt[0] = total as u32;
            self.cnt[2] = self.cnt[2].wrapping_add((total >> 32) as u32);
            w += 64 * n;
        }
        if w < target {
            // the last wrap's carry runs into target: CNT low in w + 1, high in w + 2
            if w + 1 < target {
                let (v, carry) = self.cnt[0].overflowing_add(64);
                self.cnt[0] = v;
                if carry {
                    if w + 2 < target {
                        self.cnt[2] = self.cnt[2].wrapping_add(1);
                    } else {
                        self.pend |= pend::CYC_HI;
                    }
                }
            } else {
                self.pend |= pend::CYC_LO;
            }
            w += 64;
        }
        self.next_cyc_wrap = w;
        self.core_at = target;
    }

    fn csr<const TRACE: bool>(&mut self, c: u64, insn: u32) {
        let f3 = (insn >> 12) & 7;
        let rd = (insn >> 7) & 31;
        let rs1 = (insn >> 15) & 31;
        let addr = insn >> 20;
        let writes = f3 & 3 == 1 || rs1 != 0;
        if !csr_exists(addr) || (writes && addr >> 10 == 3) {
            return self.exception::<TRACE>(c, insn, 2, insn);
        }
        let old = match addr {
            0x300 => 3 << 11 | u32::from(self.mstatus_mpie) << 7 | u32::from(self.mstatus_mie) << 3,
            0x301 => crate::hart::MISA,
            0x304 => line_bits(self.mie),
            0x305 => self.mtvec,
            0x340 => self.mscratch,
            0x341 => self.mepc,
            0x342 => u32::from(self.mcause_int) << 31 | u32::from(self.mcause_code),
            0x343 => self.mtval,
            0x344 => line_bits(self.lines),
            0xb00 | 0xc00 => (self.cnt[0] & !63) | self.cyc_lo(c),
            0xb02 | 0xc02 => (self.cnt[1] & !63) | self.ins_lo(),
            0xb80 | 0xc80 => self.cnt[2],
            0xb82 | 0xc82 => self.cnt[3],
            _ => 0,
        };
        let src = if f3 & 4 != 0 {
            rs1
        } else {
            self.x[rs1 as usize]
        };
        let new = match f3 & 3 {
            1 => src,
            2 => old | src,
            _ => old & !src,
        };
        let next = self.pc.wrapping_add(4);
        let none = Mem::default();
        if !writes {
            return self.commit::<TRACE>(c, insn, rd, old, next, 1, 1, true, none);
        }
        let mut inc = true;
        let cycles = match addr {
            0x300 => {
                self.mstatus_mie = new & (1 << 3) != 0;
                self.mstatus_mpie = new & (1 << 7) != 0;
                1
            }
            0x304 => {
                self.mie = ((new >> 3) & 1) as u8
                    | (((new >> 7) & 1) as u8) << 1
                    | (((new >> 11) & 1) as u8) << 2;
                1
            }
            0x342 => {
                self.mcause_int = new >> 31 != 0;
                self.mcause_code = (new & 0xf) as u8;
                1
            }
            0x305 => {
                self.mtvec = if new & 1 != 0 { new & !0x3e } else { new & !2 };
                2
            }
            0x340 => {
                self.mscratch = new;
                2
            }
            0x341 => {
                self.mepc = new & !1;
                2
            }
            0x343 => {
                self.mtval = new;
                2
            }
            0xb00 => {
                // the 6-bit counter takes the low bits in this cycle (no wrap in it); the
                // word is written in the next
                self.cnt[0] = new;
                let lo = u64::from(new & 63);
                self.cyc_base = (c + 1).wrapping_sub(lo);
                self.next_cyc_wrap = c + 1 + (63 - lo);
                2
            }
            0xb80 => {
                self.cnt[2] = new;
                2
            }
            0xb02 => {
                // replaces this instruction's own increment; if the old value was all ones,
                // that increment still carries into the high word
                inc = false;
                if old == u32::MAX {
                    self.pend |= pend::INS_HI;
                }
                self.cnt[1] = new;
                let lo = u64::from(new & 63);
                self.ins_base = self.instret.wrapping_sub(lo);
                self.ins_wrap_at = self.instret + (64 - lo);
                2
            }
            0xb82 => {
                // this instruction's increment counts, but its carry into the high word is
                // dropped (the write wins)
                inc = false;
                self.instret += 1;
                if self.instret >= self.ins_wrap_at {
                    self.pend |= pend::INS_LO;
                    self.ins_nohi = true;
                    self.ins_wrap_at += 64;
                }
                self.cnt[3] = new;
                2
            }
            _ => 1,
        };
        // the instruction retires in its first cycle
        self.commit::<TRACE>(c, insn, rd, old, next, cycles, 1, inc, none);
    }

    fn atomic<const TRACE: bool>(&mut self, c: u64, insn: u32, until: u64) {
        use crate::isa::amo;
        let f5 = insn >> 27;
        let rd = (insn >> 7) & 31;
        let rs2 = ((insn >> 20) & 31) as usize;
        if !amo::ALL.contains(&f5) || (f5 == amo::LR && rs2 != 0) {
            return self.exception::<TRACE>(c, insn, 2, insn);
        }
        let addr = self.x[((insn >> 15) & 31) as usize];
        if addr & 3 != 0 {
            let cause = if f5 == amo::LR { 4 } else { 6 };
            return self.exception::<TRACE>(c, insn, cause, addr);
        }
        let next = self.pc.wrapping_add(4);
        let b = self.x[rs2];
        match f5 {
            amo::LR => {
                let v = self.load_word(c, addr, 0xf, true);
                self.res_valid = true;
                self.res_addr = addr;
                let mem = Mem {
                    addr,
                    rmask: 0xf,
                    rdata: v,
                    ..Mem::default()
                };
                self.commit::<TRACE>(c, insn, rd, v, next, 1, 1, true, mem);
            }
            amo::SC => {
                let ok = self.res_valid && self.res_addr == addr;
                self.res_valid = false;
                let mut mem = Mem::default();
                if ok {
                    self.store_word(c, self.pc.wrapping_add(4), addr, 0xf, b);
                    mem = Mem {
                        addr,
                        wmask: 0xf,
                        wdata: b,
                        ..Mem::default()
                    };
                }
                self.commit::<TRACE>(c, insn, rd, u32::from(!ok), next, 1, 1, true, mem);
            }
            _ => {
                let loaded = self.load_word(c, addr, 0xf, true);
                self.res_valid = false;
                self.res_addr = addr;
                let a = AmoEx2 {
                    insn,
                    pc: self.pc,
                    addr,
                    loaded,
                    rs2v: b,
                    intr: self.intr_flag,
                };
                if !matches!(target(addr), Target::Ram(_)) && c + 1 >= until {
                    // the second cycle belongs to the next run (after the harness's input)
                    self.amo_ex2 = Some(a);
                    self.core_at = c + 1;
                } else {
                    self.amo_finish::<TRACE>(c + 1, a);
                }
            }
        }
    }

    /// The second cycle of an AMO, `c`: the new word is stored, rd gets the word read again
    /// (without side effects), and the instruction retires.
    fn amo_finish<const TRACE: bool>(&mut self, c: u64, a: AmoEx2) {
        use crate::isa::amo;
        let f5 = a.insn >> 27;
        let (old, b) = (a.loaded, a.rs2v);
        let new = match f5 {
            amo::SWAP => b,
            amo::ADD => old.wrapping_add(b),
            amo::XOR => old ^ b,
            amo::AND => old & b,
            amo::OR => old | b,
            amo::MIN => (old as i32).min(b as i32) as u32,
            amo::MAX => (old as i32).max(b as i32) as u32,
            amo::MINU => old.min(b),
            _ => old.max(b),
        };
        let again = self.load_word(c, a.addr, 0xf, false);
        self.store_word(c, a.pc.wrapping_add(4), a.addr, 0xf, new);
        let mem = Mem {
            addr: a.addr,
            rmask: 0xf,
            wmask: 0xf,
            rdata: again,
            wdata: new,
        };
        self.intr_flag = a.intr;
        let rd = (a.insn >> 7) & 31;
        self.commit::<TRACE>(c, a.insn, rd, again, a.pc.wrapping_add(4), 1, 1, true, mem);
    }
}
