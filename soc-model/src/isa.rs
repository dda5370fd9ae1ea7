//! RV32IMA + Zicsr instruction encoders, so tests and tools can build programs without an
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
