//! Seeded random instruction streams: ALU, M, loads and stores (some misaligned), forward
//! branches and jumps (some misaligned), atomics, CSR accesses, encodings that must be
//! illegal, and an external interrupt line toggled at random cycles. A trap handler skips
//! every trapping instruction.
use super::Prog;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashSet;
use verilator_tb::isa::{self, csr};
use verilator_tb::lockstep::Stimulus;
use verilator_tb::soc::RAM_BASE;

/// Registers the stream never writes: data pointers and the handler's scratch.
const DATA: u8 = 8; // s0: aligned data area
const AMO_BASE: u8 = 9; // s1: aligned word for atomics
const AMO_ODD: u8 = 18; // s2: misaligned word address
const LINK: u8 = 30; // t5: auipc base for jalr
const HANDLER: u8 = 31; // t6
const RESERVED: [u8; 5] = [DATA, AMO_BASE, AMO_ODD, LINK, HANDLER];
const DATA_AREA: u32 = RAM_BASE + 0x8_0000;
pub const STREAM_LEN: usize = 3000;
const CSRS: [u16; 14] = [
    csr::MSCRATCH,
    csr::MTVAL,
    csr::MCAUSE,
    csr::MIE,
    csr::MSTATUS,
    csr::MISA,
    csr::MIP,
    csr::MINSTRET,
    csr::MINSTRETH,
    csr::MCYCLE,
    csr::CYCLE,
    csr::INSTRET,
    csr::MHARTID,
    0x7c1,
];

fn rd(rng: &mut ChaCha8Rng) -> u8 {
    loop {
        let r = rng.random_range(0..32u8);
        if !RESERVED.contains(&r) {
            return r;
        }
    }
}

fn rs(rng: &mut ChaCha8Rng) -> u8 {
    rng.random_range(0..32u8)
}

/// One random instruction (or a short sequence) at `p.here()`; `room` words remain before
/// the end of the stream.
fn gen(rng: &mut ChaCha8Rng, p: &mut Prog, room: usize, targets: &mut HashSet<usize>) {
    match rng.random_range(0..100u32) {
        0..=24 => {
            let ops: [fn(u8, u8, u8) -> u32; 10] = [
                isa::add,
                isa::sub,
                isa::sll,
                isa::slt,
                isa::sltu,
                isa::xor,
                isa::srl,
                isa::sra,
                isa::or,
                isa::and,
            ];
            let op = ops[rng.random_range(0..ops.len())];
            p.i(op(rd(rng), rs(rng), rs(rng)));
        }
        25..=39 => {
            let imm = rng.random_range(-2048..2048);
            let sh = rng.random_range(0..32u8);
            let w = match rng.random_range(0..9) {
                0 => isa::addi(rd(rng), rs(rng), imm),
                1 => isa::slti(rd(rng), rs(rng), imm),
                2 => isa::sltiu(rd(rng), rs(rng), imm),
                3 => isa::xori(rd(rng), rs(rng), imm),
                4 => isa::ori(rd(rng), rs(rng), imm),
                5 => isa::andi(rd(rng), rs(rng), imm),
                6 => isa::slli(rd(rng), rs(rng), sh),
                7 => isa::srli(rd(rng), rs(rng), sh),
                _ => isa::srai(rd(rng), rs(rng), sh),
            };
            p.i(w);
        }
        40..=44 => {
            p.i(isa::lui(rd(rng), rng.random()));
            p.i(isa::auipc(rd(rng), rng.random()));
        }
        45..=52 => {
            p.i(isa::muldiv(
                rng.random_range(0..8),
                rd(rng),
                rs(rng),
                rs(rng),
            ));
        }
        53..=64 => {
            let off = rng.random_range(-256..256);
            let w = match rng.random_range(0..8) {
                0 => isa::lb(rd(rng), DATA, off),
                1 => isa::lh(rd(rng), DATA, off),
                2 => isa::lw(rd(rng), DATA, off),
                3 => isa::lbu(rd(rng), DATA, off),
                4 => isa::lhu(rd(rng), DATA, off),
                5 => isa::sb(rs(rng), DATA, off),
                6 => isa::sh(rs(rng), DATA, off),
                _ => isa::sw(rs(rng), DATA, off),
            };
            p.i(w);
        }
        65..=72 => {
            // forward branches and jumps, occasionally to a half-word boundary
            let words = rng.random_range(1..=room.clamp(1, 6)) as i32;
            let odd = if rng.random_range(0..10) == 0 { 2 } else { 0 };
            let off = 4 * words + odd;
            let kind = rng.random_range(0..8);
            if kind == 7 {
                // the JALR below must not be a branch target: its base comes from the AUIPC
                while targets.contains(&(p.words.len() + 1)) {
                    p.i(isa::NOP);
                }
            }
            let at = p.words.len() + usize::from(kind == 7);
            targets.insert(at + words as usize);
            let w = match kind {
                0 => isa::beq(rs(rng), rs(rng), off),
                1 => isa::bne(rs(rng), rs(rng), off),
                2 => isa::blt(rs(rng), rs(rng), off),
                3 => isa::bge(rs(rng), rs(rng), off),
                4 => isa::bltu(rs(rng), rs(rng), off),
                5 => isa::bgeu(rs(rng), rs(rng), off),
                6 => isa::jal(rd(rng), off),
                _ => {
                    p.i(isa::auipc(LINK, 0));
                    isa::jalr(rd(rng), LINK, off + 4 + rng.random_range(0..2))
                }
            };
            p.i(w);
        }
        73..=80 => {
            let base = match rng.random_range(0..8) {
                0 => AMO_ODD,
                _ => AMO_BASE,
            };
            let f5 = isa::amo::ALL[rng.random_range(0..isa::amo::ALL.len())];
            let src = if f5 == isa::amo::LR { 0 } else { rs(rng) };
            p.i(isa::amo_w(f5, rd(rng), base, src));
        }
        81..=90 => {
            let c = CSRS[rng.random_range(0..CSRS.len())];
            let f3 = [1, 2, 3, 5, 6, 7][rng.random_range(0..6)];
            let mut src = rs(rng);
            if c == csr::MSTATUS || c == csr::MIE {
                // keep the stream's own interrupt enables to set/clear of the real bits
                src = rng.random_range(0..32);
            }
            p.i(isa::csr_op(f3, rd(rng), c, src));
        }
        91..=96 => {
            // encodings that must trap as illegal (rd kept off the reserved registers)
            let rdf = u32::from(rd(rng)) << 7;
            let body = rng.random::<u32>() & 0xffff_f000;
            let w = match rng.random_range(0..7) {
                0 => (body & !(7 << 12)) | (3 << 12) | 0b000_0011 | rdf,
                1 => body | 0b111_1111 | rdf,
                2 => (body | (1 << 12)) & !(1 << 25) | (1 << 26) | 0b001_0011 | rdf,
                3 => (body & !(7 << 12)) | (4 << 12) | 0b111_0011 | rdf,
                4 => (body & !(7 << 12)) | (2 << 12) | (0b00101 << 27) | 0b010_1111 | rdf,
                5 => rng.random::<u32>() & !3,
                _ => (body & !(7 << 12)) | (1 << 12) | 0b000_1111 | rdf,
            };
            p.i(w);
        }
        _ => {
            p.i(match rng.random_range(0..3) {
                0 => isa::ECALL,
                1 => isa::EBREAK,
                _ => isa::fence(),
            });
        }
    }
}

pub fn stream(seed: u64) -> (Prog, Vec<(u64, Stimulus)>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut p = Prog::new();
    let jump = p.hole(1);
    // Handler: skip the trapping instruction; for interrupts, mask them and return.
    let handler = p.here();
    p.i(isa::csrr(HANDLER, csr::MCAUSE));
    p.i(isa::blt(HANDLER, 0, 20));
    p.i(isa::csrr(HANDLER, csr::MEPC))
        .i(isa::addi(HANDLER, HANDLER, 4));
    p.i(isa::csrrw(0, csr::MEPC, HANDLER)).i(isa::MRET);
    p.i(isa::csrrw(0, csr::MIE, 0)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(HANDLER, handler).i(isa::csrrw(0, csr::MTVEC, HANDLER));
    p.li(DATA, DATA_AREA)
        .li(AMO_BASE, DATA_AREA + 0x400)
        .li(AMO_ODD, DATA_AREA + 0x402);
    for r in 1..32u8 {
        if !RESERVED.contains(&r) {
            p.li(r, rng.random());
        }
    }
    let start = p.words.len();
    let mut targets = HashSet::new();
    while p.words.len() - start < STREAM_LEN {
        let room = STREAM_LEN + 8 - (p.words.len() - start);
        gen(&mut rng, &mut p, room, &mut targets);
    }
    p.hole(8);
    p.exit_pass();
    let mut stimuli = Vec::new();
    let mut level = false;
    let mut at = 0;
    for _ in 0..20 {
        at += rng.random_range(50..600);
        level = !level;
        stimuli.push((at, Stimulus::ExternalIrq(level)));
    }
    (p, stimuli)
}
