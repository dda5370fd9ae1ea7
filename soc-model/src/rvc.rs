//! The RV32C extension and Zcb: a compressed (16-bit) instruction's 32-bit equivalent.
//!
//! Zcb (ratified with the code-size extensions, 2023) adds 16-bit forms of byte and halfword
//! loads and stores with a small offset, of `andi rd, rd, 255`, `xori rd, rd, -1` and of `mul`:
//! C.LBU, C.LHU, C.LH, C.SB, C.SH, C.ZEXT.B, C.NOT, C.MUL. Its other forms (C.SEXT.B,
//! C.ZEXT.H, C.SEXT.H need Zbb; C.ZEXT.W is RV64) stay reserved.
//!
//! The core expands compressed instructions in its fetch stage (`rv_core.v`); the models do the
//! same here and then run the 32-bit form, so only the length (2 bytes: the next instruction
//! and the link value are `pc + 2`) and the retirement record (the 16 bits as fetched) differ.

/// Whether the 32 bits fetched at an instruction address start with a compressed instruction.
pub fn is_compressed(fetched: u32) -> bool {
    fetched & 3 != 3
}

/// The 32-bit form of a retirement record's instruction (`rvfi_insn`: a compressed one is its
/// 16 bits, zero-extended); a reserved 16-bit encoding is returned as it is.
pub fn as_32bit(insn: u32) -> u32 {
    if is_compressed(insn) {
        expand(insn as u16).unwrap_or(insn)
    } else {
        insn
    }
}

/// The 32-bit instruction that the compressed instruction `c` stands for, or `None` for an
/// encoding that is reserved or belongs to an extension the core lacks (F, D, Zbb, RV64/128
/// forms, shift amounts of 32 and more): those raise an illegal-instruction exception. HINTs
/// (writes to x0, C.NOP with an immediate, zero shift amounts) are legal and run as the
/// instruction they expand to.
pub fn expand(c: u16) -> Option<u32> {
    let c = u32::from(c);
    let bit = |n: u32| (c >> n) & 1;
    let bits = |hi: u32, lo: u32| (c >> lo) & ((1 << (hi - lo + 1)) - 1);
    // registers: full fields and the x8..x15 fields
    let rd = bits(11, 7);
    let rs2 = bits(6, 2);
    let rdp = 8 + bits(4, 2);
    let rs1p = 8 + bits(9, 7);
    // sign-extended 6-bit immediate {c[12], c[6:2]}
    let imm6 = ((bit(12) << 5 | rs2) ^ 0x20).wrapping_sub(0x20);
    let quadrant = c & 3;
    let f3 = bits(15, 13);
    let i_type = |op: u32, f3: u32, rd: u32, rs1: u32, imm: u32| {
        (imm & 0xfff) << 20 | rs1 << 15 | f3 << 12 | rd << 7 | op
    };
    let s_type = |f3: u32, rs1: u32, rs2: u32, imm: u32| {
        ((imm >> 5) & 0x7f) << 25 | rs2 << 20 | rs1 << 15 | f3 << 12 | (imm & 0x1f) << 7 | 0x23
    };
    let r_type = |f7: u32, f3: u32, rd: u32, rs1: u32, rs2: u32| {
        f7 << 25 | rs2 << 20 | rs1 << 15 | f3 << 12 | rd << 7 | 0x33
    };
    const OPIMM: u32 = 0x13;
    const LOAD: u32 = 0x03;
    match (quadrant, f3) {
        (0, 0) => {
            // C.ADDI4SPN: nzuimm[5:4|9:6|2|3]
            let imm = bits(12, 11) << 4 | bits(10, 7) << 6 | bit(6) << 2 | bit(5) << 3;
            (imm != 0).then(|| i_type(OPIMM, 0, rdp, 2, imm))
        }
        (0, 2) => {
            // C.LW: uimm[5:3|2|6]
            let imm = bits(12, 10) << 3 | bit(6) << 2 | bit(5) << 6;
            Some(i_type(LOAD, 2, rdp, rs1p, imm))
        }
        (0, 4) => {
            // Zcb loads and stores: funct6 100 0xy, rs1', uimm[0|1] (halfwords: bit 6 is the
            // signedness of a load, and must be 0 in a store), rd'/rs2'
            let half = bit(10) == 1;
            let imm = bit(5) << 1 | if half { 0 } else { bit(6) };
            match (bits(12, 11), half, bit(6)) {
                (0, false, _) => Some(i_type(LOAD, 4, rdp, rs1p, imm)),
                (0, true, 0) => Some(i_type(LOAD, 5, rdp, rs1p, imm)),
                (0, true, _) => Some(i_type(LOAD, 1, rdp, rs1p, imm)),
                (1, false, _) => Some(s_type(0, rs1p, rdp, imm)),
                (1, true, 0) => Some(s_type(1, rs1p, rdp, imm)),
                _ => None,
            }
        }
        (0, 6) => {
            let imm = bits(12, 10) << 3 | bit(6) << 2 | bit(5) << 6;
            Some(s_type(2, rs1p, rdp, imm))
        }
        (1, 0) => Some(i_type(OPIMM, 0, rd, rd, imm6)),
        (1, 1) | (1, 5) => {
            // C.JAL, C.J: offset[11|4|9:8|10|6|7|3:1|5]
            let off = bit(12) << 11
                | bit(11) << 4
                | bits(10, 9) << 8
                | bit(8) << 10
                | bit(7) << 6
                | bit(6) << 7
                | bits(5, 3) << 1
                | bit(2) << 5;
            let off = (off ^ 0x800).wrapping_sub(0x800);
            let link = if f3 == 1 { 1 } else { 0 };
            Some(crate::isa::jal(link as u8, off as i32))
        }
        (1, 2) => Some(i_type(OPIMM, 0, rd, 0, imm6)),
        (1, 3) => {
            if imm6 == 0 {
                None
            } else if rd == 2 {
                // C.ADDI16SP: nzimm[9|4|6|8:7|5]
                let imm = bit(12) << 9 | bit(6) << 4 | bit(5) << 6 | bits(4, 3) << 7 | bit(2) << 5;
                let imm = (imm ^ 0x200).wrapping_sub(0x200);
                Some(i_type(OPIMM, 0, 2, 2, imm))
            } else {
                Some((imm6 << 12) | rd << 7 | 0x37)
            }
        }
        (1, 4) => match bits(11, 10) {
            0 | 1 if bit(12) == 0 => {
                let f7 = if bit(10) == 1 { 0x400 } else { 0 };
                Some(i_type(OPIMM, 5, rs1p, rs1p, f7 | rs2))
            }
            0 | 1 => None,
            2 => Some(i_type(OPIMM, 7, rs1p, rs1p, imm6)),
            _ if bit(12) == 1 => match (bits(6, 5), bits(4, 2)) {
                // Zcb: C.ZEXT.B, C.NOT, C.MUL on rd'
                (3, 0) => Some(i_type(OPIMM, 7, rs1p, rs1p, 0xff)),
                (3, 5) => Some(i_type(OPIMM, 4, rs1p, rs1p, 0xfff)),
                (2, _) => Some(r_type(1, 0, rs1p, rs1p, rdp)),
                _ => None,
            },
            _ => {
                let (f7, f3) = match bits(6, 5) {
                    0 => (0x20, 0),
                    1 => (0, 4),
                    2 => (0, 6),
                    _ => (0, 7),
                };
                Some(r_type(f7, f3, rs1p, rs1p, rdp))
            }
        },
        (1, 6) | (1, 7) => {
            // C.BEQZ, C.BNEZ: offset[8|4:3] [7:6|2:1|5]
            let off =
                bit(12) << 8 | bits(11, 10) << 3 | bits(6, 5) << 6 | bits(4, 3) << 1 | bit(2) << 5;
            let off = (off ^ 0x100).wrapping_sub(0x100);
            let b = if f3 == 6 {
                crate::isa::beq(rs1p as u8, 0, off as i32)
            } else {
                crate::isa::bne(rs1p as u8, 0, off as i32)
            };
            Some(b)
        }
        (2, 0) => (bit(12) == 0).then(|| i_type(OPIMM, 1, rd, rd, rs2)),
        (2, 2) => {
            // C.LWSP: uimm[5] [4:2|7:6]
            let imm = bit(12) << 5 | bits(6, 4) << 2 | bits(3, 2) << 6;
            (rd != 0).then(|| i_type(LOAD, 2, rd, 2, imm))
        }
        (2, 4) => match (bit(12), rd, rs2) {
            (0, 0, 0) => None,
            (0, _, 0) => Some(i_type(0x67, 0, 0, rd, 0)),
            (0, _, _) => Some(r_type(0, 0, rd, 0, rs2)),
            (_, 0, 0) => Some(0x0010_0073),
            (_, _, 0) => Some(i_type(0x67, 0, 1, rd, 0)),
            _ => Some(r_type(0, 0, rd, rd, rs2)),
        },
        (2, 6) => {
            // C.SWSP: uimm[5:2|7:6]
            let imm = bits(12, 9) << 2 | bits(8, 7) << 6;
            Some(s_type(2, 2, rs2, imm))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isa::{self, c};
    use proptest::prelude::*;

    #[test]
    fn reserved_and_foreign_encodings_are_illegal() {
        assert_eq!(expand(0), None, "all zeros");
        assert_eq!(expand(0x2000), None, "C.FLD");
        assert_eq!(expand(0x4002), None, "C.LWSP x0");
        assert_eq!(expand(0x8002), None, "C.JR x0");
        assert_eq!(expand(0x6101), None, "C.ADDI16SP 0");
        assert_eq!(expand(0x1006), None, "C.SLLI by 32+");
        assert_eq!(expand(0x9c01), None, "C.SUBW");
        assert_eq!(expand(0x9000), None, "reserved quadrant 0 (funct6 100100)");
        assert_eq!(expand(0x9c41), Some(isa::mul(8, 8, 8)), "C.MUL");
        assert_eq!(expand(0x9c61), Some(isa::andi(8, 8, 0xff)), "C.ZEXT.B");
        assert_eq!(expand(0x9c65), None, "C.SEXT.B (Zbb)");
        assert_eq!(expand(0x9c69), None, "C.ZEXT.H (Zbb)");
        assert_eq!(expand(0x9c6d), None, "C.SEXT.H (Zbb)");
        assert_eq!(expand(0x9c71), None, "C.ZEXT.W (RV64)");
        assert_eq!(expand(0x9c75), Some(isa::xori(8, 8, -1)), "C.NOT");
        assert_eq!(expand(0x9c79), None, "reserved C.NOT neighbour");
        assert_eq!(expand(0x8c40), None, "C.SH with bit 6 set");
        assert_eq!(expand(0x8000), Some(isa::lbu(8, 8, 0)), "C.LBU");
        assert_eq!(expand(0x9002), Some(isa::EBREAK), "C.EBREAK");
        assert_eq!(expand(0x0001), Some(isa::NOP), "C.NOP");
    }

    #[test]
    fn every_legal_encoding_expands_to_a_32_bit_instruction() {
        for h in 0..=u16::MAX {
            if is_compressed(u32::from(h)) {
                if let Some(w) = expand(h) {
                    assert_eq!(w & 3, 3, "{h:#06x} -> {w:#010x}");
                }
            }
        }
    }

    proptest! {
        #[test]
        fn encoders_expand_to_their_32_bit_forms(
            r in 1u8..32, p in 8u8..16, q in 8u8..16, imm6 in -32i32..32, sh in 1u8..32,
            w in 0u32..64, sp4 in 1u32..256, sp16 in -32i32..32, half in -1024i32..1024,
            bhalf in -128i32..128,
        ) {
            prop_assert_eq!(expand(c::addi(r, imm6)), Some(isa::addi(r, r, imm6)));
            prop_assert_eq!(expand(c::li(r, imm6)), Some(isa::addi(r, 0, imm6)));
            if imm6 != 0 && r != 2 {
                prop_assert_eq!(expand(c::lui(r, imm6)), Some(isa::lui(r, imm6 as u32)));
            }
            if sp16 != 0 {
                prop_assert_eq!(expand(c::addi16sp(sp16 * 16)), Some(isa::addi(2, 2, sp16 * 16)));
            }
            prop_assert_eq!(expand(c::addi4spn(p, sp4 * 4)), Some(isa::addi(p, 2, (sp4 * 4) as i32)));
            prop_assert_eq!(expand(c::lw(p, q, w % 32 * 4)), Some(isa::lw(p, q, (w % 32 * 4) as i32)));
            prop_assert_eq!(expand(c::sw(p, q, w % 32 * 4)), Some(isa::sw(p, q, (w % 32 * 4) as i32)));
            prop_assert_eq!(expand(c::lwsp(r, w * 4)), Some(isa::lw(r, 2, (w * 4) as i32)));
            prop_assert_eq!(expand(c::swsp(r, w * 4)), Some(isa::sw(r, 2, (w * 4) as i32)));
            prop_assert_eq!(expand(c::srli(p, sh)), Some(isa::srli(p, p, sh)));
            prop_assert_eq!(expand(c::srai(p, sh)), Some(isa::srai(p, p, sh)));
            prop_assert_eq!(expand(c::slli(r, sh)), Some(isa::slli(r, r, sh)));
            prop_assert_eq!(expand(c::andi(p, imm6)), Some(isa::andi(p, p, imm6)));
            prop_assert_eq!(expand(c::sub(p, q)), Some(isa::sub(p, p, q)));
            prop_assert_eq!(expand(c::xor(p, q)), Some(isa::xor(p, p, q)));
            prop_assert_eq!(expand(c::or(p, q)), Some(isa::or(p, p, q)));
            prop_assert_eq!(expand(c::and(p, q)), Some(isa::and(p, p, q)));
            prop_assert_eq!(expand(c::mv(r, q)), Some(isa::add(r, 0, q)));
            prop_assert_eq!(expand(c::add(r, q)), Some(isa::add(r, r, q)));
            prop_assert_eq!(expand(c::jr(r)), Some(isa::jalr(0, r, 0)));
            prop_assert_eq!(expand(c::jalr(r)), Some(isa::jalr(1, r, 0)));
            prop_assert_eq!(expand(c::j(half * 2)), Some(isa::jal(0, half * 2)));
            prop_assert_eq!(expand(c::jal(half * 2)), Some(isa::jal(1, half * 2)));
            prop_assert_eq!(expand(c::beqz(p, bhalf * 2)), Some(isa::beq(p, 0, bhalf * 2)));
            prop_assert_eq!(expand(c::bnez(p, bhalf * 2)), Some(isa::bne(p, 0, bhalf * 2)));
            let (b, h) = ((w % 4) as i32, (w % 2 * 2) as i32);
            prop_assert_eq!(expand(c::lbu(p, q, b as u32)), Some(isa::lbu(p, q, b)));
            prop_assert_eq!(expand(c::lhu(p, q, h as u32)), Some(isa::lhu(p, q, h)));
            prop_assert_eq!(expand(c::lh(p, q, h as u32)), Some(isa::lh(p, q, h)));
            prop_assert_eq!(expand(c::sb(p, q, b as u32)), Some(isa::sb(p, q, b)));
            prop_assert_eq!(expand(c::sh(p, q, h as u32)), Some(isa::sh(p, q, h)));
            prop_assert_eq!(expand(c::zext_b(p)), Some(isa::andi(p, p, 0xff)));
            prop_assert_eq!(expand(c::not(p)), Some(isa::xori(p, p, -1)));
            prop_assert_eq!(expand(c::mul(p, q)), Some(isa::mul(p, p, q)));
        }
    }
}
