//! Decoded instructions and the core's straight-line executor.
//!
//! Every RAM word has a slot in `Soc::ops` holding its decoded form, packed in a `u64`:
//! kind (bits 0-7), rd (8-15, x0 replaced by a sink register), rs1 (16-23), rs2 (24-31) and a
//! 32-bit operand (the immediate, or an absolute target or value worked out from the word's
//! address: AUIPC and LUI become a constant, JAL and branches carry their target). Zero means
//! "not decoded yet", so the table starts as zeroed memory and costs nothing until used; a
//! store into a word clears its slot.
//!
//! The executor runs decoded instructions that take a fixed number of cycles and touch only
//! registers and RAM, up to a deadline (the next cycle at which a device may change, a counter
//! wraps, or the run ends). Anything else (CSRs, system instructions, atomics, device or
//! misaligned accesses, jumps to misaligned targets or to themselves) goes to the general
//! path in `exec.rs`, which also covers every instruction the executor runs.

use crate::exec::divide;
use crate::hart::Retire;
use crate::{Retired, Soc, RAM_BASE, RAM_SIZE, RAM_WORDS, X_SINK};

pub(crate) mod k {
    pub const SLOW: u8 = 1;
    pub const LI: u8 = 2;
    pub const ADDI: u8 = 3;
    pub const SLTI: u8 = 4;
    pub const SLTIU: u8 = 5;
    pub const XORI: u8 = 6;
    pub const ORI: u8 = 7;
    pub const ANDI: u8 = 8;
    pub const SLLI: u8 = 9;
    pub const SRLI: u8 = 10;
    pub const SRAI: u8 = 11;
    pub const ADD: u8 = 12;
    pub const SUB: u8 = 13;
    pub const SLL: u8 = 14;
    pub const SLT: u8 = 15;
    pub const SLTU: u8 = 16;
    pub const XOR: u8 = 17;
    pub const SRL: u8 = 18;
    pub const SRA: u8 = 19;
    pub const OR: u8 = 20;
    pub const AND: u8 = 21;
    pub const MUL: u8 = 22;
    pub const MULH: u8 = 23;
    pub const MULHSU: u8 = 24;
    pub const MULHU: u8 = 25;
    pub const DIV: u8 = 26;
    pub const DIVU: u8 = 27;
    pub const REM: u8 = 28;
    pub const REMU: u8 = 29;
    pub const JAL: u8 = 30;
    pub const JALR: u8 = 31;
    pub const BEQ: u8 = 32;
    pub const BNE: u8 = 33;
    pub const BLT: u8 = 34;
    pub const BGE: u8 = 35;
    pub const BLTU: u8 = 36;
    pub const BGEU: u8 = 37;
    pub const LB: u8 = 38;
    pub const LH: u8 = 39;
    pub const LW: u8 = 40;
    pub const LBU: u8 = 41;
    pub const LHU: u8 = 42;
    pub const SB: u8 = 43;
    pub const SH: u8 = 44;
    pub const SW: u8 = 45;
    pub const NOP: u8 = 46;
}

fn pack(kind: u8, rd: u32, rs1: u32, rs2: u32, imm: u32) -> u64 {
    let rd = if rd == 0 { X_SINK as u32 } else { rd };
    u64::from(kind)
        | u64::from(rd) << 8
        | u64::from(rs1) << 16
        | u64::from(rs2) << 24
        | u64::from(imm) << 32
}

/// Decodes the word `insn` found at `pc`.
pub(crate) fn decode(insn: u32, pc: u32) -> u64 {
    let opcode = insn & 0x7f;
    let rd = (insn >> 7) & 31;
    let f3 = (insn >> 12) & 7;
    let rs1 = (insn >> 15) & 31;
    let rs2 = (insn >> 20) & 31;
    let f7 = insn >> 25;
    let imm_i = (insn as i32 >> 20) as u32;
    let imm_s = (((insn as i32) >> 25) << 5) as u32 | ((insn >> 7) & 0x1f);
    let slow = u64::from(k::SLOW);
    match opcode {
        0b011_0111 => pack(k::LI, rd, 0, 0, insn & 0xffff_f000),
        0b001_0111 => pack(k::LI, rd, 0, 0, pc.wrapping_add(insn & 0xffff_f000)),
        0b110_1111 => {
            let imm_j = ((((insn as i32) >> 31) << 20) as u32)
                | (insn & 0x000f_f000)
                | (((insn >> 20) & 1) << 11)
                | (((insn >> 21) & 0x3ff) << 1);
            let t = pc.wrapping_add(imm_j);
            if t & 3 != 0 || t == pc {
                slow
            } else {
                pack(k::JAL, rd, 0, 0, t)
            }
        }
        0b110_0111 if f3 == 0 => pack(k::JALR, rd, rs1, 0, imm_i),
        0b110_0011 if f3 != 2 && f3 != 3 => {
            let imm_b = ((((insn as i32) >> 31) << 12) as u32)
                | (((insn >> 7) & 1) << 11)
                | (((insn >> 25) & 0x3f) << 5)
                | (((insn >> 8) & 0xf) << 1);
            let t = pc.wrapping_add(imm_b);
            if t & 3 != 0 || t == pc {
                return slow;
            }
            let kind = match f3 {
                0 => k::BEQ,
                1 => k::BNE,
                4 => k::BLT,
                5 => k::BGE,
                6 => k::BLTU,
                _ => k::BGEU,
            };
            pack(kind, 0, rs1, rs2, t)
        }
        0b000_0011 => {
            let kind = match f3 {
                0 => k::LB,
                1 => k::LH,
                2 => k::LW,
                4 => k::LBU,
                5 => k::LHU,
                _ => return slow,
            };
            pack(kind, rd, rs1, 0, imm_i)
        }
        0b010_0011 => {
            let kind = match f3 {
                0 => k::SB,
                1 => k::SH,
                2 => k::SW,
                _ => return slow,
            };
            pack(kind, 0, rs1, rs2, imm_s)
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
                _ => return slow,
            };
            let imm = if matches!(kind, k::SLLI | k::SRLI | k::SRAI) {
                imm_i & 31
            } else {
                imm_i
            };
            pack(kind, rd, rs1, 0, imm)
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
                _ => return slow,
            };
            pack(kind, rd, rs1, rs2, 0)
        }
        0b000_1111 if f3 == 0 => pack(k::NOP, 0, 0, 0, 0),
        _ => slow,
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
            match self.burst::<TRACE>(self.deadline(until)) {
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
            stale,
            trace,
            intr_flag,
            retired,
            ..
        } = self;
        let (Ok(ops), Ok(ram)) = (
            <&mut [u64; RAM_WORDS]>::try_from(&mut ops[..]),
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
            let idx = (off >> 2) as usize & (RAM_WORDS - 1);
            let op0 = ops[idx];
            let op = if op0 == 0 {
                let d = decode(ram[idx], pc);
                ops[idx] = d;
                d
            } else {
                op0
            };
            let rd = ((op >> 8) & 63) as usize;
            let rs1 = ((op >> 16) & 63) as usize;
            let rs2 = ((op >> 24) & 63) as usize;
            let imm = (op >> 32) as u32;
            let a = x[rs1];
            let b = x[rs2];
            let mut next = pc.wrapping_add(4);
            let mut cycles = 1;
            let mut mem = crate::exec::Mem::default();
            let insn = if TRACE { ram[idx] } else { 0 };
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
                ($sm:expr, $lanes:expr, $data:expr) => {{
                    let addr = a.wrapping_add(imm);
                    let off = addr.wrapping_sub(RAM_BASE);
                    let sm: u32 = $sm;
                    if addr & sm != 0 || off >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    let data: u32 = $data;
                    let lanes: u8 = $lanes;
                    let i = (off >> 2) as usize & (RAM_WORDS - 1);
                    let old = ram[i];
                    let m = (0..4).fold(0u32, |m, k| {
                        if lanes & (1 << k) != 0 {
                            m | 0xff << (8 * k)
                        } else {
                            m
                        }
                    }) << (8 * (addr & 3));
                    ram[i] = (old & !m) | (data & m);
                    if ops[i] != 0 || i == idx + 1 {
                        ops[i] = 0;
                        if i == idx + 1 {
                            // the next instruction was fetched before this write
                            *stale = Some(old);
                            deadline = 0;
                        }
                    }
                    if TRACE {
                        mem.addr = addr & !3;
                        mem.wmask = lanes << (addr & 3);
                        mem.wdata = data;
                    }
                }};
            }
            match op as u8 {
                k::LI => x[rd] = imm,
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
                    x[rd] = divide(u32::from(op as u8 - k::DIV) + 4, a, b);
                    cycles = 34;
                }
                k::JAL => {
                    x[rd] = next;
                    next = imm;
                }
                k::JALR => {
                    let t = a.wrapping_add(imm) & !1;
                    if t & 2 != 0 {
                        break Burst::Slow;
                    }
                    x[rd] = next;
                    next = t;
                }
                k::BEQ => {
                    if a == b {
                        next = imm;
                    }
                }
                k::BNE => {
                    if a != b {
                        next = imm;
                    }
                }
                k::BLT => {
                    if (a as i32) < (b as i32) {
                        next = imm;
                    }
                }
                k::BGE => {
                    if (a as i32) >= (b as i32) {
                        next = imm;
                    }
                }
                k::BLTU => {
                    if a < b {
                        next = imm;
                    }
                }
                k::BGEU => {
                    if a >= b {
                        next = imm;
                    }
                }
                k::LB => load!(0, 0x1, v, _w => v as u8 as i8 as i32 as u32),
                k::LH => load!(1, 0x3, v, _w => v as u16 as i16 as i32 as u32),
                k::LW => load!(3, 0xf, _v, w => w),
                k::LBU => load!(0, 0x1, v, _w => v & 0xff),
                k::LHU => load!(1, 0x3, v, _w => v & 0xffff),
                k::SB => store!(0, 0x1, (b & 0xff) * 0x0101_0101),
                k::SH => store!(1, 0x3, (b & 0xffff) * 0x0001_0001),
                k::SW => store!(3, 0xf, b),
                k::NOP => {}
                _ => break Burst::Slow,
            }
            if TRACE {
                let writes_rd = !matches!(
                    op as u8,
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
                let rd_addr = if writes_rd {
                    ((insn >> 7) & 31) as u8
                } else {
                    0
                };
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
