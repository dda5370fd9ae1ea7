//! The executor for a SoC that runs its image's shared code, untraced: the same instructions
//! as [`Soc::burst`] with less state in the loop (see `docs/soc-model.md`, "A lean loop for
//! shared code").

use super::{k, Burst};
use crate::exec::{divide, fetched_word};
use crate::{SharedCode, Soc, RAM_BASE, RAM_HALVES, RAM_SIZE, RAM_WORDS};

impl Soc {
    /// [`Soc::burst`] without tracing, for a SoC that runs its image's shared code: every
    /// instruction comes from the shared table (one outside it, or not decoded there, and a
    /// store into it end the burst for the general path), so the loop keeps little state:
    /// the program counter, the cycles left before the deadline and the count of
    /// instructions.
    pub(super) fn burst_shared(&mut self, deadline: u64) -> Burst {
        // Taken out for the burst and put back, not cloned: a clone would count on the `Arc`
        // that every car's SoC shares, from both threads at every burst, and that cache line
        // going back and forth between the cores was more than half of the burst's time.
        let Some(code) = self.code.take() else {
            return self.burst::<false>(deadline);
        };
        let result = self.burst_in(&code, deadline);
        self.code = Some(code);
        result
    }

    /// The burst of [`Soc::burst_shared`] over `code` (taken out of `self.code`).
    #[inline(never)]
    fn burst_in(&mut self, code: &SharedCode, deadline: u64) -> Burst {
        let (first, end) = (code.first, code.end);
        let Ok(table) = <&[u64; RAM_HALVES]>::try_from(&code.ops[..]) else {
            return Burst::Slow;
        };
        let line = &code.line[..];
        let start_at = self.core_at;
        let mut left = deadline.saturating_sub(start_at);
        let mut pc = self.pc;
        let mut n: u64 = 0;
        // cycles beyond one per instruction (divisions)
        let mut extra: u64 = 0;
        let Soc { x, ram, .. } = self;
        let Ok(ram) = <&mut [u32; RAM_WORDS]>::try_from(&mut ram[..]) else {
            return Burst::Slow;
        };
        let x: &mut [u32; 64] = x;
        // Where `pc` is in the code's line: the next instruction in memory is the next one
        // there, an address the host can fetch before this one's length is known.
        let mut i = code.line_at(pc) as usize;
        let result = loop {
            if left == 0 {
                break Burst::Deadline;
            }
            let op64 = match line.get(i) {
                Some(&op) => op,
                None => {
                    let off = pc.wrapping_sub(RAM_BASE);
                    if off >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    table[(off >> 1) as usize & (RAM_HALVES - 1)]
                }
            };
            if op64 == 0 {
                break Burst::Slow;
            }
            let op = op64 as u32;
            let kind = op & 63;
            let rd = ((op >> 6) & 31) as usize;
            let rs1 = ((op >> 11) & 31) as usize;
            let rs2 = ((op >> 16) & 31) as usize;
            let imm = ((op as i32) >> 20) as u32;
            let a = x[rs1];
            let seq = pc.wrapping_add((op64 >> 32) as u32);
            let mut next = seq;
            macro_rules! load {
                ($sm:expr, $v:ident, $w:ident => $ext:expr) => {{
                    let addr = a.wrapping_add(imm);
                    let o = addr.wrapping_sub(RAM_BASE);
                    let sm: u32 = $sm;
                    if addr & sm != 0 || o >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    let $w = ram[(o >> 2) as usize & (RAM_WORDS - 1)];
                    let $v = $w >> ((addr & 3) * 8);
                    x[rd] = $ext;
                }};
            }
            macro_rules! store {
                ($sm:expr, $mask:expr, $v:ident => $data:expr) => {{
                    let addr = a.wrapping_add(imm);
                    let o = addr.wrapping_sub(RAM_BASE);
                    let sm: u32 = $sm;
                    if addr & sm != 0 || o >= RAM_SIZE {
                        break Burst::Slow;
                    }
                    let i = (o >> 2) as usize & (RAM_WORDS - 1);
                    // Into the shared code, or into the instruction fetched next (a stale
                    // fetch): the general path handles it.
                    if (2 * i + 1 >= first && 2 * i < end + 1) || fetched_word(addr & !3, next) {
                        break Burst::Slow;
                    }
                    let $v = x[rd];
                    let data: u32 = $data;
                    let m: u32 = $mask << (8 * (addr & 3));
                    ram[i] = (ram[i] & !m) | (data & m);
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
                k::ADD => x[rd] = a.wrapping_add(x[rs2]),
                k::SUB => x[rd] = a.wrapping_sub(x[rs2]),
                k::SLL => x[rd] = a << (x[rs2] & 31),
                k::SLT => x[rd] = u32::from((a as i32) < (x[rs2] as i32)),
                k::SLTU => x[rd] = u32::from(a < x[rs2]),
                k::XOR => x[rd] = a ^ x[rs2],
                k::SRL => x[rd] = a >> (x[rs2] & 31),
                k::SRA => x[rd] = ((a as i32) >> (x[rs2] & 31)) as u32,
                k::OR => x[rd] = a | x[rs2],
                k::AND => x[rd] = a & x[rs2],
                k::MUL => x[rd] = a.wrapping_mul(x[rs2]),
                k::MULH => {
                    x[rd] = ((i64::from(a as i32) * i64::from(x[rs2] as i32)) >> 32) as u32;
                }
                k::MULHSU => x[rd] = ((i64::from(a as i32) * i64::from(x[rs2])) >> 32) as u32,
                k::MULHU => x[rd] = ((u64::from(a) * u64::from(x[rs2])) >> 32) as u32,
                k::DIV | k::DIVU | k::REM | k::REMU => {
                    // 34 cycles; it may end past the deadline, as on the general path.
                    x[rd] = divide(kind - k::DIV + 4, a, x[rs2]);
                    // (at least 1 left for the decrement below: 0 then ends the burst)
                    left = left.saturating_sub(33).max(1);
                    extra += 33;
                }
                k::JAL => {
                    x[rd] = next;
                    next = pc.wrapping_add((((op as i32) >> 12) << 1) as u32);
                }
                k::J => next = pc.wrapping_add((((op as i32) >> 12) << 1) as u32),
                k::JALR => {
                    let t = a.wrapping_add(imm) & !1;
                    x[rd] = next;
                    next = t;
                }
                k::JR => next = a.wrapping_add(imm) & !1,
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
                k::LB => load!(0, v, _w => v as u8 as i8 as i32 as u32),
                k::LH => load!(1, v, _w => v as u16 as i16 as i32 as u32),
                k::LW => load!(3, _v, w => w),
                k::LBU => load!(0, v, _w => v & 0xff),
                k::LHU => load!(1, v, _w => v & 0xffff),
                k::SB => store!(0, 0xff, v => (v & 0xff) * 0x0101_0101),
                k::SH => store!(1, 0xffff, v => (v & 0xffff) * 0x0001_0001),
                k::SW => store!(3, 0xffff_ffff, v => v),
                k::NOP => {}
                _ => break Burst::Slow,
            }
            i = if next == seq {
                i.wrapping_add(1)
            } else {
                code.line_at(next) as usize
            };
            pc = next;
            left -= 1;
            n += 1;
        };
        let now = start_at + n + extra;
        if n != 0 {
            self.intr_flag = false;
            self.last_stamp = now;
            self.cnt_wfi = false;
        }
        self.core_at = now;
        self.pc = pc;
        self.retired += n;
        self.instret += n;
        result
    }
}
