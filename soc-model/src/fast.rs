//! Decoded instructions and the core's straight-line executor.
//!
//! Every RAM halfword (an instruction may start at any) has a slot in `Soc::ops` holding the
//! decoded form of the instruction starting there, a `u64`: its length in bytes (2 or 4) in
//! the high word, and in the low word the (expanded, if compressed) instruction laid out like
//! a 32-bit one where it can be: kind (bits 0-5), rd (6-10), rs1 (11-15), rs2 (16-20)
//! and the 12-bit I-type immediate in bits 20-31 as in the instruction. Stores and branches
//! keep rs2 in the rd field (their immediate needs bits 20-31; a branch's is its offset
//! halved), JAL its offset halved in bits 12-31, LUI and AUIPC the upper immediate as in the
//! instruction. Writes to x0 are decoded away (a no-op, a jump without link, or the general
//! path for a load or a division). Zero means "not decoded yet", so the table starts as zeroed
//! memory and costs nothing until used; a store into a word clears the slots of the
//! instructions that overlap it.
//!
//! The executor runs decoded instructions that take a fixed number of cycles and touch only
//! registers and RAM, up to a deadline (the next cycle at which a device may change, a counter
//! wraps, or the run ends). Anything else (CSRs, system instructions, atomics, device or
//! misaligned accesses, illegal compressed encodings, jumps to themselves) goes to the general
//! path in `exec.rs`, which also covers every instruction the executor runs.

mod shared;

use crate::exec::{divide, fetch_ram, fetched_word};
use crate::hart::Retire;
use crate::{Retired, Soc, RAM_BASE, RAM_HALVES, RAM_SIZE, RAM_WORDS};

pub(crate) mod k {
    pub const SLOW: u32 = 1;
    pub const LUI: u32 = 2;
    pub const AUIPC: u32 = 3;
    pub const ADDI: u32 = 4;
    pub const SLTI: u32 = 5;
    pub const SLTIU: u32 = 6;
    pub const XORI: u32 = 7;
    pub const ORI: u32 = 8;
    pub const ANDI: u32 = 9;
    pub const SLLI: u32 = 10;
    pub const SRLI: u32 = 11;
    pub const SRAI: u32 = 12;
    pub const ADD: u32 = 13;
    pub const SUB: u32 = 14;
    pub const SLL: u32 = 15;
    pub const SLT: u32 = 16;
    pub const SLTU: u32 = 17;
    pub const XOR: u32 = 18;
    pub const SRL: u32 = 19;
    pub const SRA: u32 = 20;
    pub const OR: u32 = 21;
    pub const AND: u32 = 22;
    pub const MUL: u32 = 23;
    pub const MULH: u32 = 24;
    pub const MULHSU: u32 = 25;
    pub const MULHU: u32 = 26;
    pub const DIV: u32 = 27;
    pub const DIVU: u32 = 28;
    pub const REM: u32 = 29;
    pub const REMU: u32 = 30;
    pub const JAL: u32 = 31;
    pub const J: u32 = 32;
    pub const JALR: u32 = 33;
    pub const JR: u32 = 34;
    pub const BEQ: u32 = 35;
    pub const BNE: u32 = 36;
    pub const BLT: u32 = 37;
    pub const BGE: u32 = 38;
    pub const BLTU: u32 = 39;
    pub const BGEU: u32 = 40;
    pub const LB: u32 = 41;
    pub const LH: u32 = 42;
    pub const LW: u32 = 43;
    pub const LBU: u32 = 44;
    pub const LHU: u32 = 45;
    pub const SB: u32 = 46;
    pub const SH: u32 = 47;
    pub const SW: u32 = 48;
    pub const NOP: u32 = 49;
}

const SLOW: u32 = k::SLOW;

/// Decodes the instruction whose 32 bits fetched at `pc` are `fetched` (the slot's `u64`).
pub(crate) fn decode_at(fetched: u32, pc: u32) -> u64 {
    if crate::rvc::is_compressed(fetched) {
        let op = crate::rvc::expand(fetched as u16).map_or(SLOW, |x| decode(x, pc));
        2 << 32 | u64::from(op)
    } else {
        4 << 32 | u64::from(decode(fetched, pc))
    }
}

/// Decodes the 32-bit instruction `insn` found at `pc`.
pub(crate) fn decode(insn: u32, pc: u32) -> u32 {
    let opcode = insn & 0x7f;
    let rd = (insn >> 7) & 31;
    let f3 = (insn >> 12) & 7;
    let rs1 = (insn >> 15) & 31;
    let rs2 = (insn >> 20) & 31;
    let f7 = insn >> 25;
    let hi12 = insn & 0xfff0_0000;
    // kind, rd, rs1, rs2 and the I-type immediate where the instruction has it
    let i_type = |kind: u32| kind | rd << 6 | rs1 << 11 | hi12;
    match opcode {
        0b011_0111 if rd == 0 => k::NOP,
        0b001_0111 if rd == 0 => k::NOP,
        0b011_0111 => k::LUI | rd << 6 | (insn & 0xffff_f000),
        0b001_0111 => k::AUIPC | rd << 6 | (insn & 0xffff_f000),
        0b110_1111 => {
            let imm_j = ((((insn as i32) >> 31) << 20) as u32)
                | (insn & 0x000f_f000)
                | (((insn >> 20) & 1) << 11)
                | (((insn >> 21) & 0x3ff) << 1);
            let t = pc.wrapping_add(imm_j);
            if t == pc {
                return SLOW;
            }
            let kind = if rd == 0 { k::J } else { k::JAL };
            kind | rd << 6 | (imm_j >> 1) << 12
        }
        0b110_0111 if f3 == 0 => i_type(if rd == 0 { k::JR } else { k::JALR }),
        0b110_0011 if f3 != 2 && f3 != 3 => {
            let imm_b = ((((insn as i32) >> 31) << 12) as u32)
                | (((insn >> 7) & 1) << 11)
                | (((insn >> 25) & 0x3f) << 5)
                | (((insn >> 8) & 0xf) << 1);
            let t = pc.wrapping_add(imm_b);
            if t == pc {
                return SLOW;
            }
            let kind = match f3 {
                0 => k::BEQ,
                1 => k::BNE,
                4 => k::BLT,
                5 => k::BGE,
                6 => k::BLTU,
                _ => k::BGEU,
            };
            // rs2 in the rd field: the offset needs bits 20-31
            kind | rs2 << 6 | rs1 << 11 | (imm_b >> 1) << 20
        }
        0b000_0011 => {
            let kind = match f3 {
                _ if rd == 0 => return SLOW,
                0 => k::LB,
                1 => k::LH,
                2 => k::LW,
                4 => k::LBU,
                5 => k::LHU,
                _ => return SLOW,
            };
            i_type(kind)
        }
        0b010_0011 => {
            let kind = match f3 {
                0 => k::SB,
                1 => k::SH,
                2 => k::SW,
                _ => return SLOW,
            };
            let imm_s = (f7 << 5) | rd;
            kind | rs2 << 6 | rs1 << 11 | imm_s << 20
        }
        0b001_0011 => {
            let kind = match f3 {
                0 => k::ADDI,
                1 if f7 == 0 => k::SLLI,
                2 => k::SLTI,
                3 => k::SLTIU,
                4 => k::XORI,
                5 if f7 == 0 => k::SRLI,
                5 if f7 == 0x20 => k::SRAI,
                6 => k::ORI,
                7 => k::ANDI,
                _ => return SLOW,
            };
            if rd == 0 {
                k::NOP
            } else {
                i_type(kind)
            }
        }
        0b011_0011 => {
            let kind = match (f7, f3) {
                (0, 0) => k::ADD,
                (0x20, 0) => k::SUB,
                (0, 1) => k::SLL,
                (0, 2) => k::SLT,
                (0, 3) => k::SLTU,
                (0, 4) => k::XOR,
                (0, 5) => k::SRL,
                (0x20, 5) => k::SRA,
                (0, 6) => k::OR,
                (0, 7) => k::AND,
                (1, 0) => k::MUL,
                (1, 1) => k::MULH,
                (1, 2) => k::MULHSU,
                (1, 3) => k::MULHU,
                (1, 4) => k::DIV,
                (1, 5) => k::DIVU,
                (1, 6) => k::REM,
                (1, 7) => k::REMU,
                _ => return SLOW,
            };
            if rd == 0 {
                // a division still takes its 34 cycles
                if kind >= k::DIV {
                    SLOW
                } else {
                    k::NOP
                }
            } else {
                kind | rd << 6 | rs1 << 11 | rs2 << 16
            }
        }
        0b000_1111 if f3 == 0 => k::NOP,
        _ => SLOW,
    }
}

/// Why a burst of the executor ended.
pub(crate) enum Burst {
    /// It reached the deadline.
    Deadline,
    /// The instruction at `pc` needs the general path (not executed).
    Slow,
}

impl Soc {
    /// The first cycle at which the executor must look up from straight-line execution: the
    /// run's end, a possible change of the interrupt lines, a wrap of either counter.
    fn deadline(&self, until: u64) -> u64 {
        until
            .min(self.next_dev)
            .min(self.next_cyc_wrap + 1)
            .min(self.core_at + (self.ins_wrap_at - self.instret))
    }

    /// Whether the run loop must take over: a counter carry pending, a stale fetch, an AMO's
    /// second cycle, an interrupt to take, or the exit.
    fn needs_run_loop(&self) -> bool {
        self.pend != 0
            || self.stale.is_some()
            || self.amo_ex2.is_some()
            || (self.mstatus_mie && self.lines & self.mie != 0)
            || matches!(self.halt, Some(crate::Halt::Exit { .. }))
    }

    /// Runs instructions from `core_at` until `until`, the next cycle at which the devices
    /// may change, or something the run loop handles (see [`Soc::needs_run_loop`]): decoded
    /// instructions in bursts, the others and the counter carries in between.
    pub(crate) fn fast<const TRACE: bool>(&mut self, until: u64) {
        loop {
            let deadline = self.deadline(until);
            let burst = if !TRACE && self.code.is_some() {
                self.burst_shared(deadline)
            } else {
                self.burst::<TRACE>(deadline)
            };
            match burst {
                Burst::Deadline => {
                    if self.core_at >= until
                        || self.core_at >= self.next_dev
                        || self.stale.is_some()
                    {
                        return;
                    }
                    // a counter wrapped: its carry cycles, then on
                    self.settle();
                    while self.pend != 0 && self.core_at < until {
                        self.cnt_cycle();
                    }
                    if self.core_at >= until || self.core_at >= self.next_dev {
                        return;
                    }
                }
                Burst::Slow => {
                    let insn = self.fetch(self.pc);
                    self.exec::<TRACE>(insn, until);
                    if self.needs_run_loop() {
                        return;
                    }
                }
            }
            if self.core_at >= until {
                return;
            }
        }
    }

    /// Runs decoded instructions from `core_at` while the cycle is before `deadline`.
    #[inline(never)]
    fn burst<const TRACE: bool>(&mut self, mut deadline: u64) -> Burst {
        let mut now = self.core_at;
        let mut pc = self.pc;
        let start = self.instret;
        let mut instret = start;
        let Soc {
            x,
            ops,
            ram,
            code,
            stale,
            trace,
            intr_flag,
            retired,
            ..
        } = self;
        let code = code.as_deref();
        let (Ok(ops), Ok(ram)) = (
            <&mut [u64; RAM_HALVES]>::try_from(&mut ops[..]),
            <&mut [u32; RAM_WORDS]>::try_from(&mut ram[..]),
        ) else {
            return Burst::Slow;
        };
        let result = loop {
            if now >= deadline {
                break Burst::Deadline;
            }
            let off = pc.wrapping_sub(RAM_BASE);
            if off >= RAM_SIZE {
                break Burst::Slow;
            }
            let idx = (off >> 1) as usize & (RAM_HALVES - 1);
            let op64 = match code.map(|c| c.get(idx)) {
                Some(Some(op)) => op,
                // Outside the shared code: the general path (the private table stays empty
                // while the code is shared, so nothing in it can go stale).
                Some(None) => break Burst::Slow,
                None => {
                    let op0 = ops[idx];
                    if op0 == 0 {
                        let d = decode_at(fetch_ram(&ram[..], off), pc);
                        ops[idx] = d;
                        d
                    } else {
                        op0
                    }
                }
            };
            let op = op64 as u32;
            let kind = op & 63;
            let rd = ((op >> 6) & 31) as usize;
            let rs1 = ((op >> 11) & 31) as usize;
            let rs2 = ((op >> 16) & 31) as usize;
            let imm = ((op as i32) >> 20) as u32;
            let a = x[rs1];
            let b = x[rs2];
            let mut next = pc.wrapping_add((op64 >> 32) as u32);
            let mut cycles = 1;
            let mut mem = crate::exec::Mem::default();
            let insn = if TRACE {
                let f = fetch_ram(&ram[..], off);
                if op64 >> 32 == 2 {
                    f & 0xffff
                } else {
                    f
                }
            } else {
                0
            };
            // a load of `lanes` (size mask `sm`), the value from the shifted word `v` and word `w`
            macro_rules! load {
                ($sm:expr, $lanes:expr, $v:ident, $w:ident => $ext:expr) => {{
                    let addr = a.wrapping_add(imm);
                    let off = addr.wrapping_sub(RAM_BASE);
                    let sm: u32 = $sm;
                    if addr & sm != 0 || off >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    let word = ram[(off >> 2) as usize & (RAM_WORDS - 1)];
                    let $w = word;
                    let $v = word >> ((addr & 3) * 8);
                    x[rd] = $ext;
                    if TRACE {
                        let lanes: u8 = $lanes;
                        mem.addr = addr & !3;
                        mem.rmask = lanes << (addr & 3);
                        mem.rdata = word;
                    }
                }};
            }
            // a store of `lanes` (size mask `sm`) with the bus data `data`
            macro_rules! store {
                ($sm:expr, $lanes:expr, $v:ident => $data:expr) => {{
                    let addr = a.wrapping_add(imm);
                    let off = addr.wrapping_sub(RAM_BASE);
                    let sm: u32 = $sm;
                    if addr & sm != 0 || off >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    let i = (off >> 2) as usize & (RAM_WORDS - 1);
                    if code.is_some_and(|c| c.covers_word(i)) {
                        // Into the shared code: the general path stops sharing it.
                        break Burst::Slow;
                    }
                    let $v = x[rd];
                    let data: u32 = $data;
                    let lanes: u8 = $lanes;
                    let old = ram[i];
                    let m = (0..4).fold(0u32, |m, k| {
                        if lanes & (1 << k) != 0 {
                            m | 0xff << (8 * k)
                        } else {
                            m
                        }
                    }) << (8 * (addr & 3));
                    // the next instruction was fetched before this write
                    let hit = fetched_word(addr & !3, next);
                    if hit {
                        *stale = Some(fetch_ram(&ram[..], next.wrapping_sub(RAM_BASE)));
                        deadline = 0;
                    }
                    ram[i] = (old & !m) | (data & m);
                    let h = 2 * i;
                    let hp = h.wrapping_sub(1) & (RAM_HALVES - 1);
                    if ops[h] | ops[h + 1] | ops[hp] != 0 {
                        ops[h] = 0;
                        ops[h + 1] = 0;
                        ops[hp] = 0;
                    }
                    if TRACE {
                        mem.addr = addr & !3;
                        mem.wmask = lanes << (addr & 3);
                        mem.wdata = data;
                    }
                }};
            }
            match kind {
                k::LUI => x[rd] = op & 0xffff_f000,
                k::AUIPC => x[rd] = pc.wrapping_add(op & 0xffff_f000),
                k::ADDI => x[rd] = a.wrapping_add(imm),
                k::SLTI => x[rd] = u32::from((a as i32) < (imm as i32)),
                k::SLTIU => x[rd] = u32::from(a < imm),
                k::XORI => x[rd] = a ^ imm,
                k::ORI => x[rd] = a | imm,
                k::ANDI => x[rd] = a & imm,
                k::SLLI => x[rd] = a << (imm & 31),
                k::SRLI => x[rd] = a >> (imm & 31),
                k::SRAI => x[rd] = ((a as i32) >> (imm & 31)) as u32,
                k::ADD => x[rd] = a.wrapping_add(b),
                k::SUB => x[rd] = a.wrapping_sub(b),
                k::SLL => x[rd] = a << (b & 31),
                k::SLT => x[rd] = u32::from((a as i32) < (b as i32)),
                k::SLTU => x[rd] = u32::from(a < b),
                k::XOR => x[rd] = a ^ b,
                k::SRL => x[rd] = a >> (b & 31),
                k::SRA => x[rd] = ((a as i32) >> (b & 31)) as u32,
                k::OR => x[rd] = a | b,
                k::AND => x[rd] = a & b,
                k::MUL => x[rd] = a.wrapping_mul(b),
                k::MULH => {
                    x[rd] = ((i64::from(a as i32) * i64::from(b as i32)) >> 32) as u32;
                }
                k::MULHSU => x[rd] = ((i64::from(a as i32) * i64::from(b)) >> 32) as u32,
                k::MULHU => x[rd] = ((u64::from(a) * u64::from(b)) >> 32) as u32,
                k::DIV | k::DIVU | k::REM | k::REMU => {
                    x[rd] = divide(kind - k::DIV + 4, a, b);
                    cycles = 34;
                }
                k::JAL => {
                    x[rd] = next;
                    next = pc.wrapping_add((((op as i32) >> 12) << 1) as u32);
                }
                k::J => next = pc.wrapping_add((((op as i32) >> 12) << 1) as u32),
                k::JALR | k::JR => {
                    let t = a.wrapping_add(imm) & !1;
                    if kind == k::JALR {
                        x[rd] = next;
                    }
                    next = t;
                }
                k::BEQ => {
                    if a == x[rd] {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::BNE => {
                    if a != x[rd] {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::BLT => {
                    if (a as i32) < (x[rd] as i32) {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::BGE => {
                    if (a as i32) >= (x[rd] as i32) {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::BLTU => {
                    if a < x[rd] {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::BGEU => {
                    if a >= x[rd] {
                        next = pc.wrapping_add(imm << 1);
                    }
                }
                k::LB => load!(0, 0x1, v, _w => v as u8 as i8 as i32 as u32),
                k::LH => load!(1, 0x3, v, _w => v as u16 as i16 as i32 as u32),
                k::LW => load!(3, 0xf, _v, w => w),
                k::LBU => load!(0, 0x1, v, _w => v & 0xff),
                k::LHU => load!(1, 0x3, v, _w => v & 0xffff),
                k::SB => store!(0, 0x1, v => (v & 0xff) * 0x0101_0101),
                k::SH => store!(1, 0x3, v => (v & 0xffff) * 0x0001_0001),
                k::SW => store!(3, 0xf, v => v),
                k::NOP => {}
                _ => break Burst::Slow,
            }
            if TRACE {
                let writes_rd = !matches!(
                    kind,
                    k::BEQ
                        | k::BNE
                        | k::BLT
                        | k::BGE
                        | k::BLTU
                        | k::BGEU
                        | k::SB
                        | k::SH
                        | k::SW
                        | k::NOP
                );
                let rd_addr = if writes_rd { rd as u8 } else { 0 };
                let r = Retire {
                    order: *retired + (instret - start) + 1,
                    insn,
                    trap: false,
                    intr: *intr_flag,
                    pc_rdata: pc,
                    pc_wdata: next,
                    rd_addr,
                    rd_wdata: if rd_addr != 0 { x[rd] } else { 0 },
                    mem_addr: mem.addr,
                    mem_rmask: mem.rmask,
                    mem_wmask: mem.wmask,
                    mem_rdata: mem.rdata,
                    mem_wdata: mem.wdata,
                };
                *intr_flag = false;
                if let Some(t) = trace.as_mut() {
                    t.push(Retired {
                        cycle: now + cycles,
                        retire: r,
                    });
                }
            }
            pc = next;
            now += cycles;
            instret += 1;
        };
        if instret != start {
            self.intr_flag = false;
            self.last_stamp = now;
            self.cnt_wfi = false;
        }
        self.core_at = now;
        self.pc = pc;
        self.retired += instret - start;
        self.instret = instret;
        result
    }
}
