//! RV32IMAC + Zcb + Zicsr instruction encoders, so tests and tools can build programs without an
//! assembler. Register operands are `u8` numbers 0..=31; immediates are taken modulo their
//! field width (callers keep them in range).

/// ABI register numbers used by the test programs.
pub mod reg {
    pub const ZERO: u8 = 0;
    pub const RA: u8 = 1;
    pub const SP: u8 = 2;
    pub const T0: u8 = 5;
    pub const T1: u8 = 6;
    pub const T2: u8 = 7;
    pub const S0: u8 = 8;
    pub const S1: u8 = 9;
    pub const A0: u8 = 10;
    pub const A1: u8 = 11;
    pub const A2: u8 = 12;
    pub const A3: u8 = 13;
    pub const A4: u8 = 14;
    pub const A5: u8 = 15;
}

/// CSR numbers implemented by the core.
pub mod csr {
    pub const MSTATUS: u16 = 0x300;
    pub const MISA: u16 = 0x301;
    pub const MIE: u16 = 0x304;
    pub const MTVEC: u16 = 0x305;
    pub const MSTATUSH: u16 = 0x310;
    pub const MSCRATCH: u16 = 0x340;
    pub const MEPC: u16 = 0x341;
    pub const MCAUSE: u16 = 0x342;
    pub const MTVAL: u16 = 0x343;
    pub const MIP: u16 = 0x344;
    pub const MCYCLE: u16 = 0xb00;
    pub const MINSTRET: u16 = 0xb02;
    pub const MCYCLEH: u16 = 0xb80;
    pub const MINSTRETH: u16 = 0xb82;
    pub const CYCLE: u16 = 0xc00;
    pub const INSTRET: u16 = 0xc02;
    pub const CYCLEH: u16 = 0xc80;
    pub const INSTRETH: u16 = 0xc82;
    pub const MVENDORID: u16 = 0xf11;
    pub const MHARTID: u16 = 0xf14;
}

fn r(op: u32, f3: u32, f7: u32, rd: u8, rs1: u8, rs2: u8) -> u32 {
    (f7 << 25)
        | (u32::from(rs2 & 31) << 20)
        | (u32::from(rs1 & 31) << 15)
        | (f3 << 12)
        | (u32::from(rd & 31) << 7)
        | op
}

fn i(op: u32, f3: u32, rd: u8, rs1: u8, imm: i32) -> u32 {
    ((imm as u32 & 0xfff) << 20)
        | (u32::from(rs1 & 31) << 15)
        | (f3 << 12)
        | (u32::from(rd & 31) << 7)
        | op
}

fn s(op: u32, f3: u32, rs1: u8, rs2: u8, imm: i32) -> u32 {
    let imm = imm as u32;
    (((imm >> 5) & 0x7f) << 25)
        | (u32::from(rs2 & 31) << 20)
        | (u32::from(rs1 & 31) << 15)
        | (f3 << 12)
        | ((imm & 0x1f) << 7)
        | op
}

fn b(f3: u32, rs1: u8, rs2: u8, off: i32) -> u32 {
    let o = off as u32;
    (((o >> 12) & 1) << 31)
        | (((o >> 5) & 0x3f) << 25)
        | (u32::from(rs2 & 31) << 20)
        | (u32::from(rs1 & 31) << 15)
        | (f3 << 12)
        | (((o >> 1) & 0xf) << 8)
        | (((o >> 11) & 1) << 7)
        | 0b110_0011
}

pub fn lui(rd: u8, imm20: u32) -> u32 {
    ((imm20 & 0xf_ffff) << 12) | (u32::from(rd & 31) << 7) | 0b011_0111
}
pub fn auipc(rd: u8, imm20: u32) -> u32 {
    ((imm20 & 0xf_ffff) << 12) | (u32::from(rd & 31) << 7) | 0b001_0111
}
pub fn jal(rd: u8, off: i32) -> u32 {
    let o = off as u32;
    (((o >> 20) & 1) << 31)
        | (((o >> 1) & 0x3ff) << 21)
        | (((o >> 11) & 1) << 20)
        | (((o >> 12) & 0xff) << 12)
        | (u32::from(rd & 31) << 7)
        | 0b110_1111
}
pub fn jalr(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(0b110_0111, 0, rd, rs1, imm)
}
pub fn beq(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(0, rs1, rs2, off)
}
pub fn bne(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(1, rs1, rs2, off)
}
pub fn blt(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(4, rs1, rs2, off)
}
pub fn bge(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(5, rs1, rs2, off)
}
pub fn bltu(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(6, rs1, rs2, off)
}
pub fn bgeu(rs1: u8, rs2: u8, off: i32) -> u32 {
    b(7, rs1, rs2, off)
}

const LOAD: u32 = 0b000_0011;
pub fn lb(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(LOAD, 0, rd, rs1, imm)
}
pub fn lh(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(LOAD, 1, rd, rs1, imm)
}
pub fn lw(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(LOAD, 2, rd, rs1, imm)
}
pub fn lbu(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(LOAD, 4, rd, rs1, imm)
}
pub fn lhu(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(LOAD, 5, rd, rs1, imm)
}
const STORE: u32 = 0b010_0011;
pub fn sb(rs2: u8, rs1: u8, imm: i32) -> u32 {
    s(STORE, 0, rs1, rs2, imm)
}
pub fn sh(rs2: u8, rs1: u8, imm: i32) -> u32 {
    s(STORE, 1, rs1, rs2, imm)
}
pub fn sw(rs2: u8, rs1: u8, imm: i32) -> u32 {
    s(STORE, 2, rs1, rs2, imm)
}

const OPIMM: u32 = 0b001_0011;
pub fn addi(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 0, rd, rs1, imm)
}
pub fn slti(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 2, rd, rs1, imm)
}
pub fn sltiu(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 3, rd, rs1, imm)
}
pub fn xori(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 4, rd, rs1, imm)
}
pub fn ori(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 6, rd, rs1, imm)
}
pub fn andi(rd: u8, rs1: u8, imm: i32) -> u32 {
    i(OPIMM, 7, rd, rs1, imm)
}
pub fn slli(rd: u8, rs1: u8, sh: u8) -> u32 {
    i(OPIMM, 1, rd, rs1, i32::from(sh & 31))
}
pub fn srli(rd: u8, rs1: u8, sh: u8) -> u32 {
    i(OPIMM, 5, rd, rs1, i32::from(sh & 31))
}
pub fn srai(rd: u8, rs1: u8, sh: u8) -> u32 {
    i(OPIMM, 5, rd, rs1, 0x400 | i32::from(sh & 31))
}

const OP: u32 = 0b011_0011;
pub fn add(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 0, 0, rd, rs1, rs2)
}
pub fn sub(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 0, 0x20, rd, rs1, rs2)
}
pub fn sll(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 1, 0, rd, rs1, rs2)
}
pub fn slt(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 2, 0, rd, rs1, rs2)
}
pub fn sltu(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 3, 0, rd, rs1, rs2)
}
pub fn xor(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 4, 0, rd, rs1, rs2)
}
pub fn srl(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 5, 0, rd, rs1, rs2)
}
pub fn sra(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 5, 0x20, rd, rs1, rs2)
}
pub fn or(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 6, 0, rd, rs1, rs2)
}
pub fn and(rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, 7, 0, rd, rs1, rs2)
}
/// M extension: `f3` 0 MUL, 1 MULH, 2 MULHSU, 3 MULHU, 4 DIV, 5 DIVU, 6 REM, 7 REMU.
pub fn muldiv(f3: u32, rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(OP, f3 & 7, 1, rd, rs1, rs2)
}
pub fn mul(rd: u8, rs1: u8, rs2: u8) -> u32 {
    muldiv(0, rd, rs1, rs2)
}
pub fn div(rd: u8, rs1: u8, rs2: u8) -> u32 {
    muldiv(4, rd, rs1, rs2)
}

pub fn fence() -> u32 {
    0x0ff0_000f
}
pub const ECALL: u32 = 0x0000_0073;
pub const EBREAK: u32 = 0x0010_0073;
pub const MRET: u32 = 0x3020_0073;
pub const WFI: u32 = 0x1050_0073;
pub const NOP: u32 = 0x0000_0013;

/// Zicsr: `f3` 1 CSRRW, 2 CSRRS, 3 CSRRC, 5 CSRRWI, 6 CSRRSI, 7 CSRRCI; `src` is rs1 or uimm.
pub fn csr_op(f3: u32, rd: u8, csr: u16, src: u8) -> u32 {
    i(0b111_0011, f3 & 7, rd, src, i32::from(csr & 0xfff))
}
pub fn csrrw(rd: u8, csr: u16, rs1: u8) -> u32 {
    csr_op(1, rd, csr, rs1)
}
pub fn csrrs(rd: u8, csr: u16, rs1: u8) -> u32 {
    csr_op(2, rd, csr, rs1)
}
pub fn csrrc(rd: u8, csr: u16, rs1: u8) -> u32 {
    csr_op(3, rd, csr, rs1)
}
pub fn csrr(rd: u8, csr: u16) -> u32 {
    csrrs(rd, csr, 0)
}
pub fn csrrsi(rd: u8, csr: u16, uimm: u8) -> u32 {
    csr_op(6, rd, csr, uimm)
}
pub fn csrrci(rd: u8, csr: u16, uimm: u8) -> u32 {
    csr_op(7, rd, csr, uimm)
}

/// A extension word operations by funct5 (aq/rl clear).
pub mod amo {
    pub const ADD: u32 = 0b00000;
    pub const SWAP: u32 = 0b00001;
    pub const LR: u32 = 0b00010;
    pub const SC: u32 = 0b00011;
    pub const XOR: u32 = 0b00100;
    pub const OR: u32 = 0b01000;
    pub const AND: u32 = 0b01100;
    pub const MIN: u32 = 0b10000;
    pub const MAX: u32 = 0b10100;
    pub const MINU: u32 = 0b11000;
    pub const MAXU: u32 = 0b11100;
    /// Every funct5 the core implements.
    pub const ALL: [u32; 11] = [ADD, SWAP, LR, SC, XOR, OR, AND, MIN, MAX, MINU, MAXU];
}
pub fn amo_w(funct5: u32, rd: u8, rs1: u8, rs2: u8) -> u32 {
    r(0b010_1111, 2, (funct5 & 31) << 2, rd, rs1, rs2)
}
pub fn lr_w(rd: u8, rs1: u8) -> u32 {
    amo_w(amo::LR, rd, rs1, 0)
}
pub fn sc_w(rd: u8, rs1: u8, rs2: u8) -> u32 {
    amo_w(amo::SC, rd, rs1, rs2)
}

/// Loads a full 32-bit constant into `rd` (LUI + ADDI).
pub fn li(rd: u8, value: u32) -> [u32; 2] {
    let lo = ((value & 0xfff) as i32) << 20 >> 20;
    let hi = value.wrapping_sub(lo as u32) >> 12;
    [lui(rd, hi), addi(rd, rd, lo)]
}

/// RV32C encoders (16-bit instructions). `p`/`q` registers must be x8..=x15 (the 3-bit
/// fields); offsets and immediates must be in range and aligned as the instruction needs.
pub mod c {
    fn rp(r: u8) -> u16 {
        u16::from(r.wrapping_sub(8) & 7)
    }
    fn ci(f3: u16, rd: u8, imm6: i32, op: u16) -> u16 {
        let i = imm6 as u16;
        f3 << 13 | ((i >> 5) & 1) << 12 | u16::from(rd & 31) << 7 | (i & 31) << 2 | op
    }
    fn cr(f4: u16, rd: u8, rs2: u8) -> u16 {
        f4 << 12 | u16::from(rd & 31) << 7 | u16::from(rs2 & 31) << 2 | 2
    }
    fn ca(f2: u16, p: u8, q: u8) -> u16 {
        0b10_0011 << 10 | rp(p) << 7 | f2 << 5 | rp(q) << 2 | 1
    }
    fn cj(f3: u16, off: i32) -> u16 {
        let o = off as u16;
        let b = |n: u16| (o >> n) & 1;
        f3 << 13
            | b(11) << 12
            | b(4) << 11
            | ((o >> 8) & 3) << 9
            | b(10) << 8
            | b(6) << 7
            | b(7) << 6
            | ((o >> 1) & 7) << 3
            | b(5) << 2
            | 1
    }
    fn cb(f3: u16, p: u8, off: i32) -> u16 {
        let o = off as u16;
        let b = |n: u16| (o >> n) & 1;
        f3 << 13
            | b(8) << 12
            | ((o >> 3) & 3) << 10
            | rp(p) << 7
            | ((o >> 6) & 3) << 5
            | ((o >> 1) & 3) << 3
            | b(5) << 2
            | 1
    }
    fn mem(f3: u16, p: u8, q: u8, uimm: u32) -> u16 {
        let u = uimm as u16;
        f3 << 13
            | ((u >> 3) & 7) << 10
            | rp(q) << 7
            | ((u >> 2) & 1) << 6
            | ((u >> 6) & 1) << 5
            | rp(p) << 2
    }

    /// C.ADDI4SPN: p = sp + uimm (uimm a nonzero multiple of 4 below 1024).
    pub fn addi4spn(p: u8, uimm: u32) -> u16 {
        let u = uimm as u16;
        ((u >> 4) & 3) << 11
            | ((u >> 6) & 15) << 7
            | ((u >> 2) & 1) << 6
            | ((u >> 3) & 1) << 5
            | rp(p) << 2
    }
    /// C.LW: p = mem[q + uimm] (uimm a multiple of 4 below 128).
    pub fn lw(p: u8, q: u8, uimm: u32) -> u16 {
        mem(0b010, p, q, uimm)
    }
    /// C.SW: mem[q + uimm] = p.
    pub fn sw(p: u8, q: u8, uimm: u32) -> u16 {
        mem(0b110, p, q, uimm)
    }
    fn zcb_mem(f6lo: u16, p: u8, q: u8, b6: u16, uimm: u32) -> u16 {
        let u = uimm as u16;
        0b100 << 13 | f6lo << 10 | rp(q) << 7 | b6 << 6 | ((u >> 1) & 1) << 5 | rp(p) << 2
    }
    /// C.LBU (Zcb): p = mem[q + uimm] as a byte, zero-extended (uimm 0..4).
    pub fn lbu(p: u8, q: u8, uimm: u32) -> u16 {
        zcb_mem(0b000, p, q, (uimm & 1) as u16, uimm)
    }
    /// C.LHU (Zcb): p = halfword at q + uimm, zero-extended (uimm 0 or 2).
    pub fn lhu(p: u8, q: u8, uimm: u32) -> u16 {
        zcb_mem(0b001, p, q, 0, uimm)
    }
    /// C.LH (Zcb): p = halfword at q + uimm, sign-extended (uimm 0 or 2).
    pub fn lh(p: u8, q: u8, uimm: u32) -> u16 {
        zcb_mem(0b001, p, q, 1, uimm)
    }
    /// C.SB (Zcb): the low byte of p to q + uimm (uimm 0..4).
    pub fn sb(p: u8, q: u8, uimm: u32) -> u16 {
        zcb_mem(0b010, p, q, (uimm & 1) as u16, uimm)
    }
    /// C.SH (Zcb): the low halfword of p to q + uimm (uimm 0 or 2).
    pub fn sh(p: u8, q: u8, uimm: u32) -> u16 {
        zcb_mem(0b011, p, q, 0, uimm)
    }
    /// C.ZEXT.B (Zcb): p &= 255.
    pub fn zext_b(p: u8) -> u16 {
        0b10_0111 << 10 | rp(p) << 7 | 0b11_000 << 2 | 1
    }
    /// C.NOT (Zcb): p = !p.
    pub fn not(p: u8) -> u16 {
        0b10_0111 << 10 | rp(p) << 7 | 0b11_101 << 2 | 1
    }
    /// C.MUL (Zcb, with M): p *= q (the low 32 bits).
    pub fn mul(p: u8, q: u8) -> u16 {
        0b10_0111 << 10 | rp(p) << 7 | 0b10 << 5 | rp(q) << 2 | 1
    }
    /// C.NOP.
    pub const NOP: u16 = 0x0001;
    /// C.EBREAK.
    pub const EBREAK: u16 = 0x9002;
    /// C.ADDI: rd += imm6 (-32..32).
    pub fn addi(rd: u8, imm6: i32) -> u16 {
        ci(0b000, rd, imm6, 1)
    }
    /// C.JAL: ra = pc + 2; pc += off (even, -2048..2048).
    pub fn jal(off: i32) -> u16 {
        cj(0b001, off)
    }
    /// C.LI: rd = imm6.
    pub fn li(rd: u8, imm6: i32) -> u16 {
        ci(0b010, rd, imm6, 1)
    }
    /// C.ADDI16SP: sp += imm (a nonzero multiple of 16, -512..512).
    pub fn addi16sp(imm: i32) -> u16 {
        let i = imm as u16;
        let b = |n: u16| (i >> n) & 1;
        0b011 << 13
            | b(9) << 12
            | 2 << 7
            | b(4) << 6
            | b(6) << 5
            | ((i >> 7) & 3) << 3
            | b(5) << 2
            | 1
    }
    /// C.LUI: rd = imm6 << 12 (imm6 nonzero, rd not sp).
    pub fn lui(rd: u8, imm6: i32) -> u16 {
        ci(0b011, rd, imm6, 1)
    }
    /// C.SRLI: p >>= sh (1..32).
    pub fn srli(p: u8, sh: u8) -> u16 {
        0b100 << 13 | rp(p) << 7 | u16::from(sh & 31) << 2 | 1
    }
    /// C.SRAI: p >>= sh, arithmetic.
    pub fn srai(p: u8, sh: u8) -> u16 {
        0b100 << 13 | 1 << 10 | rp(p) << 7 | u16::from(sh & 31) << 2 | 1
    }
    /// C.ANDI: p &= imm6.
    pub fn andi(p: u8, imm6: i32) -> u16 {
        let i = imm6 as u16;
        0b100 << 13 | ((i >> 5) & 1) << 12 | 2 << 10 | rp(p) << 7 | (i & 31) << 2 | 1
    }
    /// C.SUB: p -= q.
    pub fn sub(p: u8, q: u8) -> u16 {
        ca(0, p, q)
    }
    /// C.XOR: p ^= q.
    pub fn xor(p: u8, q: u8) -> u16 {
        ca(1, p, q)
    }
    /// C.OR: p |= q.
    pub fn or(p: u8, q: u8) -> u16 {
        ca(2, p, q)
    }
    /// C.AND: p &= q.
    pub fn and(p: u8, q: u8) -> u16 {
        ca(3, p, q)
    }
    /// C.J: pc += off.
    pub fn j(off: i32) -> u16 {
        cj(0b101, off)
    }
    /// C.BEQZ: branch by off (even, -256..256) when p == 0.
    pub fn beqz(p: u8, off: i32) -> u16 {
        cb(0b110, p, off)
    }
    /// C.BNEZ: branch when p != 0.
    pub fn bnez(p: u8, off: i32) -> u16 {
        cb(0b111, p, off)
    }
    /// C.SLLI: rd <<= sh (1..32).
    pub fn slli(rd: u8, sh: u8) -> u16 {
        u16::from(rd & 31) << 7 | u16::from(sh & 31) << 2 | 2
    }
    /// C.LWSP: rd = mem[sp + uimm] (uimm a multiple of 4 below 256, rd not x0).
    pub fn lwsp(rd: u8, uimm: u32) -> u16 {
        let u = uimm as u16;
        0b010 << 13
            | ((u >> 5) & 1) << 12
            | u16::from(rd & 31) << 7
            | ((u >> 2) & 7) << 4
            | ((u >> 6) & 3) << 2
            | 2
    }
    /// C.SWSP: mem[sp + uimm] = rs2.
    pub fn swsp(rs2: u8, uimm: u32) -> u16 {
        let u = uimm as u16;
        0b110 << 13 | ((u >> 2) & 15) << 9 | ((u >> 6) & 3) << 7 | u16::from(rs2 & 31) << 2 | 2
    }
    /// C.JR: pc = rs1 (not x0).
    pub fn jr(rs1: u8) -> u16 {
        cr(0b1000, rs1, 0)
    }
    /// C.MV: rd = rs2 (rs2 not x0).
    pub fn mv(rd: u8, rs2: u8) -> u16 {
        cr(0b1000, rd, rs2)
    }
    /// C.JALR: ra = pc + 2; pc = rs1 (not x0).
    pub fn jalr(rs1: u8) -> u16 {
        cr(0b1001, rs1, 0)
    }
    /// C.ADD: rd += rs2 (rs2 not x0).
    pub fn add(rd: u8, rs2: u8) -> u16 {
        cr(0b1001, rd, rs2)
    }
}

/// Random RV32C words for random instruction streams (tests of the RTL and the models).
pub mod c_random {
    use super::c;

    /// Two random compressed instructions packed in one word (the first in the low half):
    /// ALU forms and HINTs (writes to x0), loads and stores through x8 and sp (which must hold
    /// word-aligned data addresses with 256 bytes of room), the Zcb forms (byte and halfword
    /// loads and stores through x8, C.ZEXT.B, C.NOT, C.MUL), a C.ADDI16SP pair that leaves sp
    /// as it was, C.EBREAK, and reserved or foreign encodings (illegal). Registers written are
    /// those `free` accepts (or x0); `g` gives random words.
    pub fn pair(g: &mut dyn FnMut() -> u32, free: &dyn Fn(u8) -> bool) -> u32 {
        if g().is_multiple_of(16) {
            let k = ((g() % 31) as i32 - 15) * 16;
            let k = if k == 0 { 16 } else { k };
            return u32::from(c::addi16sp(k)) | u32::from(c::addi16sp(-k)) << 16;
        }
        u32::from(one(g, free)) | u32::from(one(g, free)) << 16
    }

    fn one(g: &mut dyn FnMut() -> u32, free: &dyn Fn(u8) -> bool) -> u16 {
        let reg = |g: &mut dyn FnMut() -> u32, full: bool| loop {
            let r = if full {
                (g() % 32) as u8
            } else {
                8 + (g() % 8) as u8
            };
            if r == 0 || free(r) {
                break r;
            }
        };
        let imm6 = |g: &mut dyn FnMut() -> u32| (g() % 64) as i32 - 32;
        let sh = |g: &mut dyn FnMut() -> u32| 1 + (g() % 31) as u8;
        let any = |g: &mut dyn FnMut() -> u32| (g() % 32) as u8;
        let anyp = |g: &mut dyn FnMut() -> u32| 8 + (g() % 8) as u8;
        match g() % 28 {
            0 => c::addi(reg(g, true), imm6(g)),
            1 => c::li(reg(g, true), imm6(g)),
            2 => {
                let r = loop {
                    let r = reg(g, true);
                    if r != 2 {
                        break r;
                    }
                };
                let i = imm6(g);
                c::lui(r, if i == 0 { 1 } else { i })
            }
            3 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                match g() % 3 {
                    0 => c::srli(r, sh(g)),
                    1 => c::srai(r, sh(g)),
                    _ => c::andi(r, imm6(g)),
                }
            }
            4 | 5 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                let q = anyp(g);
                match g() % 4 {
                    0 => c::sub(r, q),
                    1 => c::xor(r, q),
                    2 => c::or(r, q),
                    _ => c::and(r, q),
                }
            }
            6 => c::slli(reg(g, true), sh(g)),
            7 | 8 => {
                let s = loop {
                    let s = any(g);
                    if s != 0 {
                        break s;
                    }
                };
                if g().is_multiple_of(2) {
                    c::mv(reg(g, true), s)
                } else {
                    c::add(reg(g, true), s)
                }
            }
            9 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                c::addi4spn(r, 4 * (1 + g() % 255))
            }
            10 | 11 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                c::lw(r, 8, 4 * (g() % 32))
            }
            12 | 13 => c::sw(anyp(g), 8, 4 * (g() % 32)),
            14 | 15 => {
                let r = reg(g, true);
                if r == 0 {
                    return c::NOP;
                }
                c::lwsp(r, 4 * (g() % 64))
            }
            16 | 17 => c::swsp(any(g), 4 * (g() % 64)),
            18 => c::NOP,
            19 => c::EBREAK,
            24 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                match g() % 3 {
                    0 => c::lbu(r, 8, g() % 4),
                    1 => c::lhu(r, 8, g() % 2 * 2),
                    _ => c::lh(r, 8, g() % 2 * 2),
                }
            }
            25 => {
                if g().is_multiple_of(2) {
                    c::sb(anyp(g), 8, g() % 4)
                } else {
                    c::sh(anyp(g), 8, g() % 2 * 2)
                }
            }
            26 | 27 => {
                let r = reg(g, false);
                if r == 0 {
                    return c::NOP;
                }
                match g() % 3 {
                    0 => c::zext_b(r),
                    1 => c::not(r),
                    _ => c::mul(r, anyp(g)),
                }
            }
            20 | 21 => {
                // reserved or foreign encodings: illegal
                let junk = g() as u16;
                [
                    0x0000,
                    0x2000 | (junk & 0x1ffc),        // C.FLD
                    0x6000 | (junk & 0x1ffc),        // C.FLW
                    0x9000 | (junk & 0x0ffc),        // reserved (quadrant 0, funct6 1001xx)
                    0x4002 | (junk & 0x107c),        // C.LWSP x0
                    0x8002,                          // C.JR x0
                    0x6101,                          // C.ADDI16SP 0
                    0x1002 | (junk & 0x0ffc),        // C.SLLI by 32+
                    0x9c01 | (junk & 0x039c) | 0x20, // C.SUBW/C.ADDW/reserved
                    0x9c61 | (junk & 0x0380) | (4 + (junk >> 14) * 4), // C.SEXT.B..C.ZEXT.W
                    0xa002 | (junk & 0x1ffc),        // C.FSDSP
                ][(g() % 11) as usize]
            }
            _ => {
                // HINTs: writes to x0
                match g() % 4 {
                    0 => c::li(0, imm6(g)),
                    1 => c::mv(0, 1 + (g() % 31) as u8),
                    2 => c::slli(0, sh(g)),
                    _ => c::addi(0, 1 + (g() % 31) as i32),
                }
            }
        }
    }
}
