//! Seeded random instruction streams: ALU, M, loads and stores (some misaligned), pointers
//! loaded from memory and used as a base by the next instruction, forward branches and jumps,
//! atomics, CSR accesses, encodings that must be illegal, compressed instructions (ALU, loads
//! and stores, branches and jumps, C.EBREAK, reserved encodings) and 32-bit ones at halfword
//! addresses, and an external interrupt line toggled at random cycles.
//! A trap handler skips every trapping instruction (2 or 4 bytes).
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
const SP_DATA: u8 = 2; // sp: aligned data for C.LWSP/C.SWSP/C.ADDI4SPN
const SCRATCH: u8 = 29; // t4: the handler's second register
const LINK: u8 = 30; // t5: auipc base for jalr
const HANDLER: u8 = 31; // t6
const RESERVED: [u8; 7] = [DATA, AMO_BASE, AMO_ODD, SP_DATA, SCRATCH, LINK, HANDLER];
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
/// the end of the stream. Every word starts an instruction except the second of a 32-bit
/// instruction at a halfword address, which no branch targets.
fn gen(rng: &mut ChaCha8Rng, p: &mut Prog, room: usize, targets: &mut HashSet<usize>) {
    match rng.random_range(0..126u32) {
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
            // forward branches and jumps
            let words = rng.random_range(1..=room.clamp(1, 6)) as i32;
            let off = 4 * words;
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
                5 => (rng.random::<u32>() & !0x7f) | 0x7f,
                _ => (body & !(7 << 12)) | (1 << 12) | 0b000_1111 | rdf,
            };
            p.i(w);
        }
        97..=99 => {
            p.i(match rng.random_range(0..3) {
                0 => isa::ECALL,
                1 => isa::EBREAK,
                _ => isa::fence(),
            });
        }
        100..=111 => {
            // compressed instructions, and a 32-bit one at a halfword address between two
            let mut g = || rng.random::<u32>();
            let pair = isa::c_random::pair(&mut g, &|r| r != 0 && !RESERVED.contains(&r));
            if rng.random_range(0..2) == 0 {
                p.i(pair);
            } else {
                let w = match rng.random_range(0..5) {
                    0 => isa::add(rd(rng), rs(rng), rs(rng)),
                    1 => isa::lw(rd(rng), DATA, 4 * rng.random_range(-64..64)),
                    2 => isa::sh(rs(rng), DATA, 2 * rng.random_range(-64..64)),
                    3 => isa::muldiv(rng.random_range(0..8), rd(rng), rs(rng), rs(rng)),
                    _ => isa::addi(rd(rng), rs(rng), rng.random_range(-2048..2048)),
                };
                // the second word is no instruction boundary: no branch may land there
                while targets.contains(&(p.words.len() + 1)) {
                    p.i(isa::NOP);
                }
                p.i((pair & 0xffff) | w << 16)
                    .i(w >> 16 | (pair & 0xffff_0000));
            }
        }
        112..=116 => {
            // compressed branches and jumps to a word boundary ahead
            let words = rng.random_range(1..=room.clamp(1, 6)) as i32;
            let second = rng.random_range(0..2) == 0;
            let off = 4 * words - if second { 2 } else { 0 };
            let p8 = rng.random_range(8..16u8);
            let cb = match rng.random_range(0..4) {
                0 => isa::c::beqz(p8, off),
                1 => isa::c::bnez(p8, off),
                2 => isa::c::j(off),
                _ => isa::c::jal(off),
            };
            targets.insert(p.words.len() + words as usize);
            let nop = u32::from(isa::c::NOP);
            p.i(if second {
                nop | u32::from(cb) << 16
            } else {
                u32::from(cb) | nop << 16
            });
        }
        120..=124 => {
            // a pointer loaded from memory and used as a base at once (the load-use case of
            // an address: alignment, forwarding), a quarter of them misaligned; no branch may
            // land inside, where the pointer would be a stale value
            while (1..=3).any(|k| targets.contains(&(p.words.len() + k))) {
                p.i(isa::NOP);
            }
            let slot = 4 * rng.random_range(-64..64);
            let skew = if rng.random_range(0..4) == 0 {
                rng.random_range(1..4)
            } else {
                0
            };
            let tmp = rd(rng);
            // C.LW/C.SW need x8..x15 (x8 and x9 are reserved)
            let ptr = if rng.random_range(0..3) == 0 {
                rng.random_range(10..16u8)
            } else {
                rd(rng)
            };
            let off = rng.random_range(-64..64) * 4;
            p.i(isa::addi(tmp, DATA, skew))
                .i(isa::sw(tmp, DATA, slot))
                .i(isa::lw(ptr, DATA, slot));
            match rng.random_range(0..9) {
                0 => p.i(isa::lw(rd(rng), ptr, off)),
                1 => p.i(isa::lh(rd(rng), ptr, off)),
                2 => p.i(isa::lbu(rd(rng), ptr, off + 1)),
                3 => p.i(isa::sw(rs(rng), ptr, off)),
                4 => p.i(isa::sh(rs(rng), ptr, off)),
                5 => p.i(isa::amo_w(isa::amo::ADD, rd(rng), ptr, rs(rng))),
                6 => p.i(isa::addi(rd(rng), ptr, off)),
                _ if (10..16).contains(&ptr) => {
                    let uimm = 4 * rng.random_range(0..32u32);
                    let c = if rng.random_range(0..2) == 0 {
                        isa::c::lw(rng.random_range(10..16u8), ptr, uimm)
                    } else {
                        isa::c::sw(rng.random_range(8..16u8), ptr, uimm)
                    };
                    p.i(u32::from(c) | u32::from(isa::c::NOP) << 16)
                }
                _ => p.i(isa::lw(rd(rng), ptr, off)),
            };
        }
        _ => {
            // C.JR / C.JALR to LINK + off: neither the ADDI nor the jump may be a target
            let words = rng.random_range(1..=room.clamp(1, 6)) as i32;
            while (1..=2).any(|k| targets.contains(&(p.words.len() + k))) {
                p.i(isa::NOP);
            }
            let at = p.words.len();
            targets.insert(at + 2 + words as usize);
            let j = if rng.random_range(0..2) == 0 {
                isa::c::jr(LINK)
            } else {
                isa::c::jalr(LINK)
            };
            p.i(isa::auipc(LINK, 0))
                .i(isa::addi(LINK, LINK, 4 * (2 + words)))
                .i(u32::from(j) | u32::from(isa::c::NOP) << 16);
        }
    }
}

pub fn stream(seed: u64) -> (Prog, Vec<(u64, Stimulus)>) {
    stream_with(seed, None)
}

/// Where [`looped`] keeps its loop counter: away from every address the stream touches.
const LOOP_COUNTER: u32 = DATA_AREA + 0x1_0000;

/// The stream of `seed` run `iterations` times over (registers, memory and CSRs carry on from
/// one pass to the next), with the interrupt line toggled every 50 to 600 cycles for
/// `cycles` cycles.
pub fn looped(seed: u64, iterations: u32, cycles: u64) -> (Prog, Vec<(u64, Stimulus)>) {
    stream_with(seed, Some((iterations, cycles)))
}

fn stream_with(seed: u64, looped: Option<(u32, u64)>) -> (Prog, Vec<(u64, Stimulus)>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut p = Prog::new();
    let jump = p.hole(1);
    // Handler: skip the trapping instruction (2 or 4 bytes by its low bits); for interrupts,
    // mask them and return.
    let handler = p.here();
    p.i(isa::csrr(HANDLER, csr::MCAUSE));
    p.i(isa::blt(HANDLER, 0, 40));
    p.i(isa::csrr(HANDLER, csr::MEPC))
        .i(isa::lhu(SCRATCH, HANDLER, 0))
        .i(isa::andi(SCRATCH, SCRATCH, 3))
        .i(isa::addi(SCRATCH, SCRATCH, -3))
        .i(isa::addi(HANDLER, HANDLER, 2))
        .i(isa::bne(SCRATCH, 0, 8))
        .i(isa::addi(HANDLER, HANDLER, 2));
    p.i(isa::csrrw(0, csr::MEPC, HANDLER)).i(isa::MRET);
    p.i(isa::csrrw(0, csr::MIE, 0)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(HANDLER, handler).i(isa::csrrw(0, csr::MTVEC, HANDLER));
    p.li(SP_DATA, DATA_AREA + 0x100);
    p.li(DATA, DATA_AREA)
        .li(AMO_BASE, DATA_AREA + 0x400)
        .li(AMO_ODD, DATA_AREA + 0x402);
    if let Some((iterations, _)) = looped {
        p.li(5, LOOP_COUNTER).li(6, iterations).i(isa::sw(6, 5, 0));
    }
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
    if looped.is_some() {
        // count the passes down in RAM and go round again
        p.li(5, LOOP_COUNTER)
            .i(isa::lw(6, 5, 0))
            .i(isa::addi(6, 6, -1))
            .i(isa::sw(6, 5, 0))
            .i(isa::beq(6, 0, 8));
        let here = p.here();
        p.i(isa::jal(0, (p.addr_of(start) as i32) - (here as i32)));
    }
    p.exit_pass();
    let mut stimuli = Vec::new();
    let mut level = false;
    let mut at = 0;
    let end = looped.map_or(0, |(_, cycles)| cycles);
    let mut k = 0;
    while k < 20 || at < end {
        at += rng.random_range(50..600);
        level = !level;
        stimuli.push((at, Stimulus::ExternalIrq(level)));
        k += 1;
    }
    (p, stimuli)
}
