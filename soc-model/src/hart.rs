//! Golden RV32IMAC + Zcb + Zicsr machine-mode instruction-set model: the reference the RTL core is
//! checked against, one retired instruction at a time. It follows the privileged spec's
//! choices the core makes (documented in docs/soft-core.md): direct or vectored mtvec (a
//! vectored table is 64-byte aligned), mtval is zero for EBREAK,
//! misaligned accesses trap, all mip bits are read-only wires, mcycle follows the clock (the
//! checker supplies its value), and interrupts are taken between instructions.

/// One retired instruction, in the shape of the RVFI port.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Retire {
    pub order: u64,
    pub insn: u32,
    pub trap: bool,
    pub intr: bool,
    pub pc_rdata: u32,
    pub pc_wdata: u32,
    pub rd_addr: u8,
    pub rd_wdata: u32,
    pub mem_addr: u32,
    pub mem_rmask: u8,
    pub mem_wmask: u8,
    pub mem_rdata: u32,
    pub mem_wdata: u32,
}

/// Word-wide memory as the model sees it: aligned addresses, byte-lane write masks.
pub trait Bus {
    /// The word at aligned address `addr`.
    fn load(&mut self, addr: u32) -> u32;
    /// Writes the lanes of `data` selected by `mask` at aligned address `addr`.
    fn store(&mut self, addr: u32, mask: u8, data: u32);
}

/// Interrupt line bits as carried by `Hart::irq_lines` (mip bit positions 3, 7, 11).
pub mod line {
    pub const SOFTWARE: u8 = 1;
    pub const TIMER: u8 = 2;
    pub const EXTERNAL: u8 = 4;
}

/// Trap causes.
pub mod cause {
    pub const MISALIGNED_FETCH: u32 = 0;
    pub const ILLEGAL_INSTRUCTION: u32 = 2;
    pub const BREAKPOINT: u32 = 3;
    pub const MISALIGNED_LOAD: u32 = 4;
    pub const MISALIGNED_STORE: u32 = 6;
    pub const ECALL_M: u32 = 11;
    pub const INTERRUPT: u32 = 1 << 31;
    pub const M_SOFTWARE: u32 = INTERRUPT | 3;
    pub const M_TIMER: u32 = INTERRUPT | 7;
    pub const M_EXTERNAL: u32 = INTERRUPT | 11;
}

/// `misa` of the core: RV32 with A, C, I, M.
pub const MISA: u32 = 0x4000_1105;
/// Writable bits of `mie`: MSIE, MTIE, MEIE.
const MIE_MASK: u32 = 0x888;

/// Architectural state of the single hart.
#[derive(Debug, Clone)]
pub struct Hart {
    pub pc: u32,
    pub x: [u32; 32],
    pub mstatus_mie: bool,
    pub mstatus_mpie: bool,
    pub mie: u32,
    pub mtvec: u32,
    pub mscratch: u32,
    pub mepc: u32,
    pub mcause: u32,
    pub mtval: u32,
    pub mcycle: u64,
    pub minstret: u64,
    pub reservation: Option<u32>,
    /// Interrupt input lines ([`line`] bits) as the next instruction sees them.
    pub irq_lines: u8,
    order: u64,
    pending_csr: Option<(u16, u32)>,
}

enum Outcome {
    Next,
    Jump(u32),
    Trap(u32, u32),
}

impl Hart {
    /// The hart after reset, starting at `reset_pc`.
    pub fn new(reset_pc: u32) -> Self {
        Self {
            pc: reset_pc,
            x: [0; 32],
            mstatus_mie: false,
            mstatus_mpie: false,
            mie: 0,
            mtvec: 0,
            mscratch: 0,
            mepc: 0,
            mcause: 0,
            mtval: 0,
            mcycle: 0,
            minstret: 0,
            reservation: None,
            irq_lines: 0,
            order: 0,
            pending_csr: None,
        }
    }

    /// The mip register value for the current interrupt lines.
    pub fn mip(&self) -> u32 {
        let l = u32::from(self.irq_lines);
        ((l & 1) << 3) | (((l >> 1) & 1) << 7) | (((l >> 2) & 1) << 11)
    }

    /// mstatus as read by a CSR instruction (MPP is hard-wired to machine mode).
    pub fn mstatus(&self) -> u32 {
        (3 << 11) | (u32::from(self.mstatus_mpie) << 7) | (u32::from(self.mstatus_mie) << 3)
    }

    /// The interrupt the hart would take before its next instruction, if any.
    pub fn pending_interrupt(&self) -> Option<u32> {
        let pend = self.mip() & self.mie;
        if !self.mstatus_mie || pend == 0 {
            return None;
        }
        Some(if pend & (1 << 11) != 0 {
            cause::M_EXTERNAL
        } else if pend & (1 << 3) != 0 {
            cause::M_SOFTWARE
        } else {
            cause::M_TIMER
        })
    }

    /// Enters the handler of the pending interrupt; returns its cause, or `None` (and changes
    /// nothing) when no enabled interrupt is pending.
    pub fn take_interrupt(&mut self) -> Option<u32> {
        let c = self.pending_interrupt()?;
        self.mepc = self.pc;
        self.mcause = c;
        self.mtval = 0;
        self.mstatus_mpie = self.mstatus_mie;
        self.mstatus_mie = false;
        let base = self.mtvec & !3;
        self.pc = if self.mtvec & 1 != 0 {
            base.wrapping_add(4 * (c & 0x7fff_ffff))
        } else {
            base
        };
        Some(c)
    }

    fn csr_read(&self, addr: u16) -> Option<u32> {
        Some(match addr {
            0x300 => self.mstatus(),
            0x301 => MISA,
            0x304 => self.mie,
            0x305 => self.mtvec,
            0x310 => 0,
            0x340 => self.mscratch,
            0x341 => self.mepc,
            0x342 => self.mcause,
            0x343 => self.mtval,
            0x344 => self.mip(),
            0xb00 | 0xc00 => self.mcycle as u32,
            0xb80 | 0xc80 => (self.mcycle >> 32) as u32,
            0xb02 | 0xc02 => self.minstret as u32,
            0xb82 | 0xc82 => (self.minstret >> 32) as u32,
            0xf11..=0xf15 => 0,
            _ => return None,
        })
    }

    fn csr_write(&mut self, addr: u16, v: u32) {
        match addr {
            0x300 => {
                self.mstatus_mie = v & (1 << 3) != 0;
                self.mstatus_mpie = v & (1 << 7) != 0;
            }
            0x304 => self.mie = v & MIE_MASK,
            // mode 1 (vectored) needs a 64-byte aligned table: entry = base | cause << 2
            0x305 => self.mtvec = if v & 1 != 0 { v & !0x3e } else { v & !2 },
            0x340 => self.mscratch = v,
            0x341 => self.mepc = v & !1,
            // WLRL: only the interrupt bit and a 4-bit code are kept
            0x342 => self.mcause = v & 0x8000_000f,
            0x343 => self.mtval = v,
            0xb00 => self.mcycle = (self.mcycle & !0xffff_ffff) | u64::from(v),
            0xb80 => self.mcycle = (self.mcycle & 0xffff_ffff) | (u64::from(v) << 32),
            0xb02 => self.minstret = (self.minstret & !0xffff_ffff) | u64::from(v),
            0xb82 => self.minstret = (self.minstret & 0xffff_ffff) | (u64::from(v) << 32),
            _ => {}
        }
    }

    /// Executes the instruction at `pc` (fetched from `bus`) and returns its retirement record.
    pub fn step<B: Bus>(&mut self, bus: &mut B) -> Retire {
        let pc = self.pc;
        // the 16 bits at pc, and the next 16 unless they start a compressed instruction
        let half = |bus: &mut B, a: u32| (bus.load(a & !3) >> ((a & 2) * 8)) & 0xffff;
        let lo = half(bus, pc);
        let (raw, insn, len) = if crate::rvc::is_compressed(lo) {
            // an illegal one runs as its 16 bits, whose low bits make it illegal
            let x = crate::rvc::expand(lo as u16).unwrap_or(lo);
            (lo, x, 2)
        } else {
            let w = lo | half(bus, pc.wrapping_add(2)) << 16;
            (w, w, 4)
        };
        let mut rec = Retire {
            insn: raw,
            pc_rdata: pc,
            ..Retire::default()
        };
        self.order += 1;
        rec.order = self.order;
        let mut rd_val: Option<u32> = None;
        self.pending_csr = None;
        let outcome = self.execute(insn, len, bus, &mut rec, &mut rd_val);
        match outcome {
            Outcome::Trap(c, tval) => {
                self.mepc = pc;
                self.mcause = c;
                self.mtval = tval;
                self.mstatus_mpie = self.mstatus_mie;
                self.mstatus_mie = false;
                self.pc = self.mtvec & !3;
                rec = Retire {
                    order: rec.order,
                    insn: raw,
                    trap: true,
                    pc_rdata: pc,
                    pc_wdata: self.pc,
                    ..Retire::default()
                };
            }
            Outcome::Next | Outcome::Jump(_) => {
                let next = match outcome {
                    Outcome::Jump(t) => t,
                    _ => pc.wrapping_add(len),
                };
                let rd = ((insn >> 7) & 31) as u8;
                if let (Some(v), true) = (rd_val, rd != 0) {
                    self.x[usize::from(rd)] = v;
                    rec.rd_addr = rd;
                    rec.rd_wdata = v;
                }
                self.pc = next;
                rec.pc_wdata = next;
                // A CSR write to minstret wins over this instruction's own increment.
                self.minstret = self.minstret.wrapping_add(1);
                if let Some((addr, v)) = self.pending_csr.take() {
                    self.csr_write(addr, v);
                }
            }
        }
        rec
    }

    fn execute(
        &mut self,
        insn: u32,
        len: u32,
        bus: &mut impl Bus,
        rec: &mut Retire,
        rd_val: &mut Option<u32>,
    ) -> Outcome {
        let illegal = Outcome::Trap(cause::ILLEGAL_INSTRUCTION, insn);
        if insn & 3 != 3 {
            return illegal;
        }
        let pc = self.pc;
        let opcode = insn & 0x7f;
        let rs1 = ((insn >> 15) & 31) as usize;
        let rs2 = ((insn >> 20) & 31) as usize;
        let f3 = (insn >> 12) & 7;
        let f7 = insn >> 25;
        let a = self.x[rs1];
        let b = self.x[rs2];
        let imm_i = (insn as i32 >> 20) as u32;
        let imm_s = (((insn as i32) >> 25) << 5) as u32 | ((insn >> 7) & 0x1f);
        let imm_b = ((((insn as i32) >> 31) << 12) as u32)
            | (((insn >> 7) & 1) << 11)
            | (((insn >> 25) & 0x3f) << 5)
            | (((insn >> 8) & 0xf) << 1);
        let imm_j = ((((insn as i32) >> 31) << 20) as u32)
            | (insn & 0x000f_f000)
            | (((insn >> 20) & 1) << 11)
            | (((insn >> 21) & 0x3ff) << 1);
        // with C every target is a halfword address: no misaligned-fetch exception
        let jump_to = Outcome::Jump;
        match opcode {
            0b011_0111 => *rd_val = Some(insn & 0xffff_f000),
            0b001_0111 => *rd_val = Some(pc.wrapping_add(insn & 0xffff_f000)),
            0b110_1111 => {
                let o = jump_to(pc.wrapping_add(imm_j));
                if matches!(o, Outcome::Jump(_)) {
                    *rd_val = Some(pc.wrapping_add(len));
                }
                return o;
            }
            0b110_0111 if f3 == 0 => {
                let o = jump_to(a.wrapping_add(imm_i) & !1);
                if matches!(o, Outcome::Jump(_)) {
                    *rd_val = Some(pc.wrapping_add(len));
                }
                return o;
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
                    return jump_to(pc.wrapping_add(imm_b));
                }
            }
            0b000_0011 if matches!(f3, 0 | 1 | 2 | 4 | 5) => {
                let addr = a.wrapping_add(imm_i);
                if misaligned(addr, f3 & 3) {
                    return Outcome::Trap(cause::MISALIGNED_LOAD, addr);
                }
                let word = bus.load(addr & !3);
                let sh = (addr & 3) * 8;
                let v = word >> sh;
                *rd_val = Some(match f3 {
                    0 => v as u8 as i8 as i32 as u32,
                    1 => v as u16 as i16 as i32 as u32,
                    4 => v & 0xff,
                    5 => v & 0xffff,
                    _ => word,
                });
                rec.mem_addr = addr & !3;
                rec.mem_rmask = lane_mask(addr, f3 & 3);
                rec.mem_rdata = word;
            }
            0b010_0011 if f3 <= 2 => {
                let addr = a.wrapping_add(imm_s);
                if misaligned(addr, f3) {
                    return Outcome::Trap(cause::MISALIGNED_STORE, addr);
                }
                let data = match f3 {
                    0 => (b & 0xff) * 0x0101_0101,
                    1 => (b & 0xffff) * 0x0001_0001,
                    _ => b,
                };
                let mask = lane_mask(addr, f3);
                bus.store(addr & !3, mask, data);
                rec.mem_addr = addr & !3;
                rec.mem_wmask = mask;
                rec.mem_wdata = data;
            }
            0b001_0011 => {
                let sh = imm_i & 31;
                *rd_val = Some(match f3 {
                    0 => a.wrapping_add(imm_i),
                    1 if f7 == 0 => a << sh,
                    2 => u32::from((a as i32) < (imm_i as i32)),
                    3 => u32::from(a < imm_i),
                    4 => a ^ imm_i,
                    5 if f7 == 0 => a >> sh,
                    5 if f7 == 0x20 => ((a as i32) >> sh) as u32,
                    6 => a | imm_i,
                    7 => a & imm_i,
                    _ => return illegal,
                });
            }
            0b011_0011 if f7 == 1 => {
                if f3 < 4 {
                    *rd_val = Some(match f3 {
                        0 => a.wrapping_mul(b),
                        1 => ((i64::from(a as i32) * i64::from(b as i32)) >> 32) as u32,
                        2 => ((i64::from(a as i32) * i64::from(b)) >> 32) as u32,
                        _ => ((u64::from(a) * u64::from(b)) >> 32) as u32,
                    });
                } else {
                    *rd_val = Some(divide(f3, a, b));
                }
            }
            0b011_0011 => {
                let sh = b & 31;
                *rd_val = Some(match (f7, f3) {
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
                    _ => return illegal,
                });
            }
            0b000_1111 if f3 == 0 => {}
            0b111_0011 => return self.system(insn, f3, rs1, a, rd_val),
            0b010_1111 if f3 == 2 => return self.atomic(insn, rs2, a, b, bus, rec, rd_val),
            _ => return illegal,
        }
        Outcome::Next
    }

    fn system(
        &mut self,
        insn: u32,
        f3: u32,
        rs1: usize,
        a: u32,
        rd_val: &mut Option<u32>,
    ) -> Outcome {
        let illegal = Outcome::Trap(cause::ILLEGAL_INSTRUCTION, insn);
        match (f3, insn) {
            (0, 0x0000_0073) => Outcome::Trap(cause::ECALL_M, 0),
            (0, 0x0010_0073) => Outcome::Trap(cause::BREAKPOINT, 0),
            (0, 0x3020_0073) => {
                self.mstatus_mie = self.mstatus_mpie;
                self.mstatus_mpie = true;
                Outcome::Jump(self.mepc)
            }
            (0, 0x1050_0073) => Outcome::Next,
            (0 | 4, _) => illegal,
            _ => {
                let addr = (insn >> 20) as u16;
                let Some(old) = self.csr_read(addr) else {
                    return illegal;
                };
                let writes = f3 & 3 == 1 || rs1 != 0;
                if writes && addr >> 10 == 3 {
                    return illegal;
                }
                let src = if f3 & 4 != 0 { rs1 as u32 } else { a };
                let new = match f3 & 3 {
                    1 => src,
                    2 => old | src,
                    _ => old & !src,
                };
                *rd_val = Some(old);
                if writes {
                    self.pending_csr = Some((addr, new));
                }
                Outcome::Next
            }
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn atomic(
        &mut self,
        insn: u32,
        rs2: usize,
        addr: u32,
        b: u32,
        bus: &mut impl Bus,
        rec: &mut Retire,
        rd_val: &mut Option<u32>,
    ) -> Outcome {
        use crate::isa::amo;
        let f5 = insn >> 27;
        if !amo::ALL.contains(&f5) || (f5 == amo::LR && rs2 != 0) {
            return Outcome::Trap(cause::ILLEGAL_INSTRUCTION, insn);
        }
        if addr & 3 != 0 {
            let c = if f5 == amo::LR {
                cause::MISALIGNED_LOAD
            } else {
                cause::MISALIGNED_STORE
            };
            return Outcome::Trap(c, addr);
        }
        rec.mem_addr = addr;
        match f5 {
            amo::LR => {
                let v = bus.load(addr);
                rec.mem_rmask = 0xf;
                rec.mem_rdata = v;
                self.reservation = Some(addr);
                *rd_val = Some(v);
            }
            amo::SC => {
                let ok = self.reservation == Some(addr);
                self.reservation = None;
                if ok {
                    bus.store(addr, 0xf, b);
                    rec.mem_wmask = 0xf;
                    rec.mem_wdata = b;
                } else {
                    rec.mem_addr = 0;
                }
                *rd_val = Some(u32::from(!ok));
            }
            _ => {
                // the core keeps one address register for LR and AMOs, so an AMO ends a
                // reservation (an SC after it fails, as the spec allows)
                self.reservation = None;
                let old = bus.load(addr);
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
                bus.store(addr, 0xf, new);
                rec.mem_rmask = 0xf;
                rec.mem_wmask = 0xf;
                rec.mem_rdata = old;
                rec.mem_wdata = new;
                *rd_val = Some(old);
            }
        }
        Outcome::Next
    }
}

fn misaligned(addr: u32, size: u32) -> bool {
    match size {
        1 => addr & 1 != 0,
        2 => addr & 3 != 0,
        _ => false,
    }
}

fn lane_mask(addr: u32, size: u32) -> u8 {
    let base: u8 = match size {
        0 => 0b0001,
        1 => 0b0011,
        _ => 0b1111,
    };
    base << (addr & 3)
}

/// DIV/DIVU/REM/REMU (`f3` 4..=7) with the spec's division-by-zero and overflow results.
pub fn divide(f3: u32, a: u32, b: u32) -> u32 {
    match f3 {
        4 => {
            if b == 0 {
                u32::MAX
            } else {
                (a as i32).wrapping_div(b as i32) as u32
            }
        }
        5 => a.checked_div(b).unwrap_or(u32::MAX),
        6 => {
            if b == 0 {
                a
            } else {
                (a as i32).wrapping_rem(b as i32) as u32
            }
        }
        _ => a.checked_rem(b).unwrap_or(a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isa;
    use proptest::prelude::*;

    const BASE: u32 = 0x8000_0000;

    /// A small RAM at BASE for the model alone.
    struct Ram(Vec<u32>);

    impl Bus for Ram {
        fn load(&mut self, addr: u32) -> u32 {
            let i = (addr.wrapping_sub(BASE) / 4) as usize;
            self.0.get(i).copied().unwrap_or(0)
        }
        fn store(&mut self, addr: u32, mask: u8, data: u32) {
            let i = (addr.wrapping_sub(BASE) / 4) as usize;
            if let Some(w) = self.0.get_mut(i) {
                for lane in 0..4 {
                    if mask & (1 << lane) != 0 {
                        let m = 0xffu32 << (8 * lane);
                        *w = (*w & !m) | (data & m);
                    }
                }
            }
        }
    }

    fn run(words: &[u32], setup: impl FnOnce(&mut Hart)) -> (Hart, Vec<Retire>) {
        let mut ram = Ram(vec![0; 64]);
        ram.0[..words.len()].copy_from_slice(words);
        let mut h = Hart::new(BASE);
        setup(&mut h);
        let recs = words.iter().map(|_| h.step(&mut ram)).collect();
        (h, recs)
    }

    #[test]
    fn division_corner_cases() {
        assert_eq!(divide(4, 7, 0), u32::MAX);
        assert_eq!(divide(5, 7, 0), u32::MAX);
        assert_eq!(divide(6, 7, 0), 7);
        assert_eq!(divide(7, 7, 0), 7);
        assert_eq!(divide(4, 0x8000_0000, u32::MAX), 0x8000_0000);
        assert_eq!(divide(6, 0x8000_0000, u32::MAX), 0);
        assert_eq!(divide(4, (-7i32) as u32, 2), (-3i32) as u32);
        assert_eq!(divide(6, (-7i32) as u32, 2), (-1i32) as u32);
    }

    #[test]
    fn illegal_instruction_traps_with_the_word() {
        let (h, recs) = run(&[0xffff_ffff], |h| h.mtvec = BASE + 0x40);
        assert!(recs[0].trap);
        assert_eq!(recs[0].pc_wdata, BASE + 0x40);
        assert_eq!(
            (h.mcause, h.mtval, h.mepc),
            (cause::ILLEGAL_INSTRUCTION, 0xffff_ffff, BASE)
        );
        assert_eq!(h.minstret, 0, "a trapping instruction does not retire");
    }

    #[test]
    fn vectored_interrupt_entry() {
        let mut h = Hart::new(BASE);
        h.mtvec = BASE + 0x141;
        h.mstatus_mie = true;
        h.mie = 1 << 7;
        h.irq_lines = line::TIMER;
        assert_eq!(h.take_interrupt(), Some(cause::M_TIMER));
        assert_eq!(h.pc, BASE + 0x140 + 4 * 7);
        assert!(!h.mstatus_mie && h.mstatus_mpie);
        assert_eq!(h.take_interrupt(), None, "MIE is off inside the handler");
    }

    proptest! {
        #[test]
        fn addi_encoding_round_trips(rd in 1u8..32, rs1 in 0u8..32, imm in -2048i32..2048, v: u32) {
            let (h, recs) = run(&[isa::addi(rd, rs1, imm)], |h| if rs1 != 0 { h.x[rs1 as usize] = v });
            let src = if rs1 == 0 { 0 } else { v };
            prop_assert_eq!(h.x[rd as usize], src.wrapping_add(imm as u32));
            prop_assert_eq!(recs[0].rd_addr, rd);
        }

        #[test]
        fn branch_and_jal_offsets_round_trip(half in -2048i32..2048, rd in 1u8..32) {
            // with C a halfword target is aligned: no misaligned-fetch exception
            let off = half * 2;
            let (_, recs) = run(&[isa::beq(0, 0, off)], |_| {});
            prop_assert!(!recs[0].trap);
            prop_assert_eq!(recs[0].pc_wdata, BASE.wrapping_add(off as u32));
            let joff = half * 512;
            let (h, recs) = run(&[isa::jal(rd, joff)], |_| {});
            prop_assert_eq!(recs[0].pc_wdata, BASE.wrapping_add(joff as u32));
            prop_assert_eq!(h.x[rd as usize], BASE + 4);
        }

        #[test]
        fn compressed_instructions_advance_by_two(rd in 1u8..32, imm in -32i32..32, v: u32) {
            // c.addi rd, imm; c.jal +4 (links pc + 2 + 2); a 32-bit addi at a halfword address
            let w0 = u32::from(isa::c::addi(rd, imm)) | u32::from(isa::c::jal(4)) << 16;
            let w1 = u32::from(isa::c::NOP) | (isa::addi(rd, rd, 1) & 0xffff) << 16;
            let w2 = isa::addi(rd, rd, 1) >> 16;
            let mut ram = Ram(vec![0; 64]);
            ram.0[..3].copy_from_slice(&[w0, w1, w2]);
            let mut h = Hart::new(BASE);
            h.x[rd as usize] = v;
            let r0 = h.step(&mut ram);
            prop_assert_eq!((r0.insn, r0.pc_wdata), (w0 & 0xffff, BASE + 2));
            let r1 = h.step(&mut ram);
            prop_assert_eq!(r1.pc_wdata, BASE + 6);
            let r2 = h.step(&mut ram);
            prop_assert_eq!((r2.pc_rdata, r2.pc_wdata), (BASE + 6, BASE + 10));
            prop_assert_eq!(r2.insn, isa::addi(rd, rd, 1));
            if rd == 1 {
                prop_assert_eq!(h.x[1], BASE + 5);
            } else {
                prop_assert_eq!(h.x[rd as usize], v.wrapping_add(imm as u32).wrapping_add(1));
                prop_assert_eq!(h.x[1], BASE + 4);
            }
        }

        #[test]
        fn li_loads_any_constant(rd in 1u8..32, v: u32) {
            let (h, _) = run(&isa::li(rd, v), |_| {});
            prop_assert_eq!(h.x[rd as usize], v);
        }

        #[test]
        fn store_then_load_round_trips(v: u32, byte in 0i32..4) {
            let prog = [
                isa::lui(8, (BASE + 0x80) >> 12),
                isa::addi(8, 8, ((BASE + 0x80) & 0xfff) as i32),
                isa::sb(9, 8, byte),
                isa::lbu(10, 8, byte),
                isa::sw(9, 8, 4),
                isa::lw(11, 8, 4),
            ];
            let (h, _) = run(&prog, |h| h.x[9] = v);
            prop_assert_eq!(h.x[10], v & 0xff);
            prop_assert_eq!(h.x[11], v);
        }
    }
}
