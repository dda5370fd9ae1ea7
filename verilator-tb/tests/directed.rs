//! Directed tests: every instruction, every trap cause and every interrupt source, each run in
//! lockstep with the golden model, and each checked against values worked out by hand here.
mod common;
use common::*;
use verilator_tb::golden::cause;
use verilator_tb::isa::{self, c, csr, reg::*};
use verilator_tb::lockstep::{Lockstep, Stimulus};
use verilator_tb::soc::{map, CoreVariant, Exit, RAM_BASE};

/// Where the programs keep results.
const OUT: u32 = RAM_BASE + 0x8_0000;
const S2: u8 = 18;

/// A branch encoder: `(rs1, rs2, offset)`.
type Branch = fn(u8, u8, i32) -> u32;

/// Runs `op rd, a0, a1` for each (a, b) and checks the result word by word.
fn binop_cases(op: impl Fn(u8, u8, u8) -> u32, cases: &[(u32, u32, u32)]) {
    let mut p = Prog::new();
    p.li(S0, OUT);
    for (k, (a, b, _)) in cases.iter().enumerate() {
        p.li(A0, *a)
            .li(A1, *b)
            .i(op(A2, A0, A1))
            .i(isa::sw(A2, S0, 4 * k as i32));
    }
    p.exit_pass();
    let (_, ls) = run_pass(&p);
    for (k, (a, b, want)) in cases.iter().enumerate() {
        let got = ls.model_word(OUT + 4 * k as u32).unwrap();
        assert_eq!(got, *want, "case {k}: a={a:#x} b={b:#x}");
    }
}

#[test]
fn register_register_alu() {
    binop_cases(
        isa::add,
        &[
            (1, 2, 3),
            (0xffff_ffff, 1, 0),
            (0x7fff_ffff, 1, 0x8000_0000),
        ],
    );
    binop_cases(
        isa::sub,
        &[(1, 2, 0xffff_ffff), (0x8000_0000, 1, 0x7fff_ffff)],
    );
    binop_cases(
        isa::sll,
        &[(1, 31, 0x8000_0000), (3, 33, 6), (0xf0, 4, 0xf00)],
    );
    binop_cases(
        isa::slt,
        &[(0xffff_ffff, 0, 1), (0, 0xffff_ffff, 0), (5, 5, 0)],
    );
    binop_cases(
        isa::sltu,
        &[(0xffff_ffff, 0, 0), (0, 0xffff_ffff, 1), (4, 5, 1)],
    );
    binop_cases(isa::xor, &[(0xff00_ff00, 0x0ff0_0ff0, 0xf0f0_f0f0)]);
    binop_cases(
        isa::srl,
        &[(0x8000_0000, 31, 1), (0x8000_0000, 35, 0x1000_0000)],
    );
    binop_cases(
        isa::sra,
        &[(0x8000_0000, 31, 0xffff_ffff), (0x4000_0000, 30, 1)],
    );
    binop_cases(isa::or, &[(0xff00_0000, 0x0000_00ff, 0xff00_00ff)]);
    binop_cases(isa::and, &[(0xff0f_0f0f, 0x0fff_00ff, 0x0f0f_000f)]);
}

#[test]
fn multiply_divide() {
    let m = |f3: u32| move |rd, a, b| isa::muldiv(f3, rd, a, b);
    binop_cases(
        m(0),
        &[
            (7, 6, 42),
            (0xffff_ffff, 0xffff_ffff, 1),
            (0x1_0001, 0x1_0001, 0x2_0001),
        ],
    );
    binop_cases(
        m(1),
        &[
            (0xffff_ffff, 0xffff_ffff, 0),
            (0x8000_0000, 0x8000_0000, 0x4000_0000),
            (0x8000_0000, 2, 0xffff_ffff),
        ],
    );
    binop_cases(
        m(2),
        &[(0xffff_ffff, 0xffff_ffff, 0xffff_ffff), (2, 0x8000_0000, 1)],
    );
    binop_cases(
        m(3),
        &[(0xffff_ffff, 0xffff_ffff, 0xffff_fffe), (0x8000_0000, 4, 2)],
    );
    binop_cases(
        m(4),
        &[
            (20, 3, 6),
            (0xffff_ffec, 3, 0xffff_fffa),
            (5, 0, 0xffff_ffff),
            (0x8000_0000, 0xffff_ffff, 0x8000_0000),
        ],
    );
    binop_cases(
        m(5),
        &[
            (20, 3, 6),
            (0xffff_ffff, 2, 0x7fff_ffff),
            (5, 0, 0xffff_ffff),
        ],
    );
    binop_cases(
        m(6),
        &[
            (20, 3, 2),
            (0xffff_ffec, 3, 0xffff_fffe),
            (5, 0, 5),
            (0x8000_0000, 0xffff_ffff, 0),
        ],
    );
    binop_cases(m(7), &[(20, 3, 2), (0xffff_ffff, 16, 15), (5, 0, 5)]);
}

#[test]
fn immediates_and_upper() {
    let mut p = Prog::new();
    p.li(A0, 0x8000_0001);
    p.i(isa::addi(A1, A0, -1)); // 0x8000_0000
    p.i(isa::slti(A2, A0, 0)); // 1
    p.i(isa::sltiu(A3, A0, -1)); // 1 (imm is 0xffff_ffff)
    p.i(isa::xori(T2, A0, -1)); // 0x7fff_fffe
    p.i(isa::ori(S1, 0, 0x7ff)); // 0x7ff
    p.i(isa::andi(14, A0, 0xf)); // 1
    p.i(isa::slli(15, A0, 4)); // 0x10
    p.i(isa::srli(16, A0, 28)); // 8
    p.i(isa::srai(17, A0, 28)); // 0xffff_fff8
    p.i(isa::lui(19, 0xabcde)); // 0xabcde000
    let at = p.here();
    p.i(isa::auipc(20, 1)); // at + 0x1000
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!(
        [x[11], x[12], x[13], x[7], x[9], x[14], x[15], x[16], x[17], x[19], x[20]],
        [
            0x8000_0000,
            1,
            1,
            0x7fff_fffe,
            0x7ff,
            1,
            0x10,
            8,
            0xffff_fff8,
            0xabcd_e000,
            at + 0x1000
        ]
    );
}

#[test]
fn loads_and_stores() {
    let mut p = Prog::new();
    p.li(S0, OUT).li(A0, 0x8899_aabb);
    p.i(isa::sw(A0, S0, 0));
    p.i(isa::sb(A0, S0, 5)); // byte 5 = 0xbb
    p.i(isa::sh(A0, S0, 10)); // bytes 10..12 = 0xaabb
    p.i(isa::lb(A1, S0, 0)); // 0xffff_ffbb
    p.i(isa::lbu(A2, S0, 1)); // 0xaa
    p.i(isa::lh(A3, S0, 2)); // 0xffff_8899
    p.i(isa::lhu(T2, S0, 2)); // 0x8899
    p.i(isa::lw(S1, S0, 4)); // 0x0000_bb00
    p.i(isa::lw(14, S0, 8)); // 0xaabb_0000
    p.i(isa::lb(15, S0, 3)); // 0xffff_ff88
    p.exit_pass();
    let (run, ls) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!(
        [x[11], x[12], x[13], x[7], x[9], x[14], x[15]],
        [
            0xffff_ffbb,
            0xaa,
            0xffff_8899,
            0x8899,
            0xbb00,
            0xaabb_0000,
            0xffff_ff88
        ]
    );
    assert_eq!(ls.model_word(OUT + 4), Some(0xbb00));
}

/// A load's address from the word loaded just before: the alignment is the loaded word's, not
/// what is in the pipeline while the address waits for it (the pipelined core checks the
/// alignment in the stage that waits).
#[test]
fn loaded_base_used_at_once() {
    let mut p = Prog::new();
    p.li(S0, OUT).li(A0, OUT + 2).li(A1, 0x1234_5678);
    p.i(isa::sw(A0, S0, 0)); // OUT: OUT + 2
    p.i(isa::sw(A1, S0, 4)); // OUT + 4: 0x1234_5678
    p.i(isa::lw(A2, S0, 0)); // OUT + 2
    p.i(isa::lw(A3, A2, 2)); // OUT + 4: aligned through the loaded base
    p.i(isa::lw(A2, S0, 0));
    p.i(isa::sw(A3, A2, 6)); // OUT + 8
    p.i(isa::lw(A2, S0, 0));
    p.i(isa::lh(T2, A2, 4)); // OUT + 6: 0x1234
    p.exit_pass();
    let (run, ls) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!([x[13], x[7]], [0x1234_5678, 0x1234]);
    assert_eq!(ls.model_word(OUT + 8), Some(0x1234_5678));
}

#[test]
fn branches_and_jumps() {
    // Each taken branch skips an `addi a2, a2, 1`; each fall-through executes one.
    let mut p = Prog::new();
    p.li(A0, 0xffff_fffe).li(A1, 1);
    let cases: [(Branch, bool); 6] = [
        (isa::beq, false),
        (isa::bne, true),
        (isa::blt, true),
        (isa::bge, false),
        (isa::bltu, false),
        (isa::bgeu, true),
    ];
    for (br, _) in cases {
        p.i(br(A0, A1, 8)).i(isa::addi(A2, A2, 1));
    }
    let link_at = p.here();
    p.i(isa::jal(RA, 8)).i(isa::addi(A3, A3, 1)); // skipped
    p.i(isa::auipc(T2, 0)).i(isa::jalr(S1, T2, 13)); // target auipc + 12 (bit 0 cleared)
    p.i(isa::addi(A3, A3, 1)); // skipped
    p.i(isa::beq(0, 0, -0)); // replaced below
    let last = p.words.len() - 1;
    p.words[last] = isa::addi(A3, A3, 0x10);
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let not_taken = cases.iter().filter(|c| !c.1).count() as u32;
    assert_eq!(run.hart.x[A2 as usize], not_taken);
    assert_eq!(run.hart.x[A3 as usize], 0x10);
    assert_eq!(run.hart.x[RA as usize], link_at + 4);
    assert_eq!(run.hart.x[S1 as usize], link_at + 16);
}

/// Backward branches, which the pipelined core guesses taken in decode: loops that close with
/// a 32-bit branch, a compressed one and one at a halfword address, their exits (the guess
/// is wrong), a backward branch that is never taken, and an interrupt-free count of each.
#[test]
fn backward_branches() {
    let pair = |a: u16, b: u16| u32::from(a) | u32::from(b) << 16;
    let mut p = Prog::new();
    // a0 counts down from 5 with BNE back over two instructions: a1 = 5 passes
    p.li(A0, 5).li(A1, 0);
    p.i(isa::addi(A1, A1, 1))
        .i(isa::addi(A0, A0, -1))
        .i(isa::bne(A0, 0, -8));
    // C.BNEZ back: a2 = 3 passes (the loop body is one word: C.ADDI a2, C.ADDI a3)
    p.li(A3, 3).li(A2, 0);
    p.i(pair(c::addi(A2, 1), c::addi(A3, -1)));
    p.i(pair(c::bnez(A3, -4), c::NOP));
    // a 32-bit BLT at a halfword address, back to a C.ADDI: a4 counts to 4
    p.li(A4, 0).li(A5, 4);
    p.i(pair(c::NOP, c::addi(A4, 1)));
    let blt = isa::blt(A4, A5, -4);
    p.i(pair(c::NOP, blt as u16));
    p.i(blt >> 16 | u32::from(c::NOP) << 16);
    // never taken: BEQ back with unequal operands, then C.BEQZ back on a nonzero register
    p.li(T2, 1);
    p.i(isa::beq(T2, 0, -4)).i(pair(c::beqz(A1, -2), c::NOP));
    p.i(isa::addi(16, 0, 7));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!([x[11], x[12], x[14], x[16]], [5, 3, 4, 7]);
}

/// The pipelined core's branch history: a forward branch taken every time is guessed taken
/// once its counter has learnt it (one cycle instead of two), a backward branch never taken
/// is guessed not taken, and a guess that turns out wrong (the counters say taken, the branch
/// falls through; 32-bit and compressed, at word and halfword addresses) still runs the
/// program as the golden model does.
#[test]
fn branch_history_guesses() {
    let pair = |a: u16, b: u16| u32::from(a) | u32::from(b) << 16;
    // `n` passes of: BNE forward, taken (skips an ADDI); C.BEQZ forward, taken, at a halfword
    // address; BEQ backward, never taken; the loop's BNE back
    let lp = |n: u32| {
        let mut p = Prog::new();
        p.li(A0, 1).li(A1, n).li(A2, 0).li(A3, 0);
        p.i(isa::bne(A0, 0, 8)) // taken
            .i(isa::addi(A2, A2, 1)) // skipped
            .i(pair(c::NOP, c::beqz(A3, 6))) // taken, over the next word
            .i(isa::addi(A2, A2, 0x100)) // skipped
            .i(isa::beq(A0, 0, -16)) // never taken
            .i(isa::addi(A1, A1, -1))
            .i(isa::bne(A1, 0, -24));
        p.exit_pass();
        p
    };
    let mut cycles = Vec::new();
    for core in [CoreVariant::Pipe, CoreVariant::PipeMulSeq] {
        for n in [40, 80] {
            let p = lp(n);
            let mut ls = Lockstep::with_core(core);
            ls.load(RAM_BASE, &p.words).expect("program fits");
            let run = ls
                .run(100_000, 1_000_000, &[])
                .unwrap_or_else(|m| panic!("{core:?}: {}", describe(&m)));
            assert_eq!(run.exit, Some(Exit::Pass), "{core:?}");
            assert_eq!(run.hart.x[A2 as usize], 0, "{core:?}");
            cycles.push(run.cycles);
        }
    }
    // 40 passes more: 6 instructions, a cycle for each of the three taken branches guessed,
    // none for the one never taken (9 cycles a pass; 13 with the static guesses)
    assert_eq!(cycles[1] - cycles[0], 40 * 9, "cycles {cycles:?}");
    assert_eq!(cycles[3] - cycles[2], 40 * 9, "cycles {cycles:?}");

    // Wrong guesses: a forward branch taken 8 times, then not (its counter says taken), in
    // 32-bit and compressed forms; the golden model and every core agree on the count.
    let mut p = Prog::new();
    p.li(A1, 12).li(A2, 0).li(A4, 4);
    let top = p.here();
    p.i(isa::blt(A4, A1, 8)) // taken while a1 > 4
        .i(isa::addi(A2, A2, 1)) // counts the last 4 passes
        .i(pair(c::addi(A1, -1), c::bnez(A1, 4))) // taken until a1 reaches 0
        .i(pair(c::addi(A2, 0x10), c::NOP)); // once, when a1 is 0
    let back = top as i32 - p.here() as i32;
    p.i(isa::bne(A1, 0, back));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    assert_eq!(run.hart.x[A2 as usize], 4 + 0x10);
}

/// Installs a handler that records mcause, mepc and mtval to OUT.. and returns past the
/// trapping instruction; returns the program with `mtvec` set.
fn with_trap_recorder() -> Prog {
    let mut p = Prog::new();
    p.li(S0, OUT);
    let jump = p.hole(1);
    let handler = p.here();
    p.i(isa::csrr(T2, csr::MCAUSE)).i(isa::sw(T2, S0, 0));
    p.i(isa::csrr(T2, csr::MEPC)).i(isa::sw(T2, S0, 4));
    p.i(isa::csrr(T2, csr::MTVAL)).i(isa::sw(T2, S0, 8));
    p.i(isa::csrr(T2, csr::MSTATUS)).i(isa::sw(T2, S0, 12));
    p.i(isa::csrr(T2, csr::MEPC))
        .i(isa::addi(T2, T2, 4))
        .i(isa::csrrw(0, csr::MEPC, T2));
    p.i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T2, handler).i(isa::csrrw(0, csr::MTVEC, T2));
    p
}

fn expect_trap(body: &[u32], want_cause: u32, want_tval: Option<u32>) {
    let mut p = with_trap_recorder();
    p.words.extend(&body[..body.len() - 1]);
    let epc = p.here();
    p.i(body[body.len() - 1]);
    p.i(isa::addi(A3, 0, 0x55)); // runs after the handler returns
    p.exit_pass();
    let (run, ls) = run_pass(&p);
    assert_eq!(ls.model_word(OUT), Some(want_cause), "mcause");
    assert_eq!(ls.model_word(OUT + 4), Some(epc), "mepc");
    if let Some(t) = want_tval {
        assert_eq!(ls.model_word(OUT + 8), Some(t), "mtval");
    }
    assert_eq!(
        ls.model_word(OUT + 12),
        Some(0x1800),
        "mstatus in the handler: MPP=M, MIE=0"
    );
    assert_eq!(run.hart.x[A3 as usize], 0x55);
}

#[test]
fn exceptions() {
    expect_trap(&[isa::ECALL], cause::ECALL_M, Some(0));
    let mut body = vec![isa::EBREAK];
    expect_trap(&body, cause::BREAKPOINT, None);
    for bad in [
        0xffff_ffff,
        0x0000_0000,
        0x0000_3003,
        0x0200_1013,
        0x4000_1033,
        0x0000_007f,
        0x3020_00f3,
        0x0000_4073,
        0x0000_100f,
        0x0800_302f,
        0x1010_a02f,
        0x2800_202f,
    ] {
        expect_trap(&[bad], cause::ILLEGAL_INSTRUCTION, Some(bad));
    }
    // Writing a read-only CSR and touching an unimplemented one.
    expect_trap(
        &[isa::csrrw(A0, csr::CYCLE, A1)],
        cause::ILLEGAL_INSTRUCTION,
        None,
    );
    expect_trap(&[isa::csrr(A0, 0x7c0)], cause::ILLEGAL_INSTRUCTION, None);
    body = isa::li(A0, OUT + 1).to_vec();
    body.push(isa::lw(A1, A0, 0));
    expect_trap(&body, cause::MISALIGNED_LOAD, Some(OUT + 1));
    body = isa::li(A0, OUT + 3).to_vec();
    body.push(isa::sh(A1, A0, 0));
    expect_trap(&body, cause::MISALIGNED_STORE, Some(OUT + 3));
    body = isa::li(A0, OUT + 2).to_vec();
    body.push(isa::amo_w(isa::amo::ADD, A1, A0, A1));
    expect_trap(&body, cause::MISALIGNED_STORE, Some(OUT + 2));
    // Compressed: C.EBREAK, and reserved or foreign 16-bit encodings, whose mtval is their
    // 16 bits (the handler skips the whole word, a C.NOP after them).
    let nop = u32::from(c::NOP) << 16;
    expect_trap(&[u32::from(c::EBREAK) | nop], cause::BREAKPOINT, Some(0));
    for bad in [
        0x0001_u32 << 16, // 0x0000 with a C.NOP after it
        0x2000 | nop,
        0x4002 | nop,
        0x8002 | nop,
        0x6101 | nop,
        0x1006 | nop,
        0x9c01 | nop,
        0x9000 | nop, // quadrant 0, funct6 100100: reserved (100000..100011 are Zcb's)
        0x8c40 | nop, // C.SH with bit 6 set
        0x9c65 | nop, // C.SEXT.B (Zbb)
        0x9c71 | nop, // C.ZEXT.W (RV64)
        0xe002 | nop,
    ] {
        expect_trap(&[bad], cause::ILLEGAL_INSTRUCTION, Some(bad & 0xffff));
    }
}

#[test]
fn compressed_instructions() {
    let pair = |a: u16, b: u16| u32::from(a) | u32::from(b) << 16;
    let mut p = Prog::new();
    p.li(A0, 5).li(S1, OUT);
    p.i(pair(c::addi(A0, 3), c::li(A1, -7))); // a0 = 8, a1 = -7
    p.i(pair(c::mv(A2, A0), c::add(A2, A1))); // a2 = 1
    p.i(pair(c::slli(A2, 4), c::lui(A3, 1))); // a2 = 16, a3 = 0x1000
                                              // jal +6 lands on a halfword address: a 32-bit ADDI between two compressed instructions
    p.i(isa::jal(RA, 6));
    let addi = isa::addi(A4, A2, 100);
    p.i(pair(c::li(A4, 1), addi as u16)); // the C.LI is jumped over
    p.i(addi >> 16 | u32::from(c::NOP) << 16); // a4 = 116
                                               // C.JALR links pc + 2
    p.i(isa::auipc(T0, 0)).i(isa::addi(T0, T0, 12));
    p.i(pair(c::jalr(T0), c::li(A0, 0))); // the C.LI is jumped over
    p.i(isa::sub(16, T0, RA)); // 2
                               // C.SW / C.LW through x9; C.BNEZ to a halfword address
    p.i(pair(c::sw(A2, S1, 4), c::lw(A5, S1, 4))); // a5 = 16
    p.i(pair(c::bnez(A1, 6), c::NOP));
    p.i(pair(c::li(A0, 0), c::addi(A0, 1))); // the C.LI is jumped over: a0 = 9
    p.i(pair(c::addi4spn(S0, 64), c::NOP));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!(
        [x[10], x[11], x[12], x[13]],
        [9, (-7i32) as u32, 16, 0x1000]
    );
    assert_eq!([x[14], x[15], x[16]], [116, 16, 2]);
    assert_eq!(x[usize::from(S0)], x[2].wrapping_add(64));
}

/// Zcb: byte and halfword loads (zero- and sign-extended) and stores with their 2-bit
/// offsets, C.ZEXT.B, C.NOT and C.MUL, against the golden model on every core.
#[test]
fn zcb_instructions() {
    let pair = |a: u16, b: u16| u32::from(a) | u32::from(b) << 16;
    let mut p = Prog::new();
    p.li(S1, OUT)
        .li(S0, OUT + 4)
        .li(A0, 0x8281_80ff)
        .li(A1, 0x1234_5678);
    p.i(isa::sw(A0, S1, 0)).i(isa::sw(0, S1, 4));
    p.i(pair(c::lbu(A2, S1, 0), c::lbu(A3, S1, 3))); // a2 = 0xff, a3 = 0x82
    p.i(pair(c::lhu(A4, S1, 2), c::lh(A5, S1, 2))); // a4 = 0x8281, a5 = 0xffff_8281
    p.i(pair(c::sb(A1, S0, 1), c::sh(A1, S0, 2))); // word 1 = 0x5678_7800
    p.i(isa::lw(16, S1, 4));
    p.i(pair(c::zext_b(A0), c::not(A1))); // a0 = 0xff, a1 = !0x1234_5678
    p.li(S0, 3);
    p.i(pair(c::mul(S0, S1), c::NOP)); // s0 = 3 * OUT
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!(
        [x[12], x[13], x[14], x[15]],
        [0xff, 0x82, 0x8281, 0xffff_8281]
    );
    assert_eq!(x[16], 0x5678_7800, "C.SB and C.SH");
    assert_eq!(x[10], 0xff, "C.ZEXT.B");
    assert_eq!(x[11], !0x1234_5678u32, "C.NOT");
    assert_eq!(x[usize::from(S0)], OUT.wrapping_mul(3), "C.MUL");
}

#[test]
fn csrs_and_counters() {
    let mut p = Prog::new();
    p.li(A0, 0x1234_5678);
    p.i(isa::csrrw(0, csr::MSCRATCH, A0));
    p.i(isa::csrrsi(A1, csr::MSCRATCH, 0x3)); // a1 = old, scratch |= 3
    p.li(T2, 0xff);
    p.i(isa::csrrc(A2, csr::MSCRATCH, T2)); // a2 = 0x1234567b, scratch = 0x12345600
    p.i(isa::csrr(A3, csr::MSCRATCH));
    p.i(isa::csrr(S1, csr::MISA));
    p.i(isa::csrr(14, csr::MHARTID));
    p.i(isa::csrr(15, csr::MINSTRET)); // instructions before this one
    p.i(isa::csrr(16, csr::MCYCLE));
    p.i(isa::csrr(17, csr::MCYCLE));
    p.li(T2, 0xffff_fff0).i(isa::csrrw(0, csr::MINSTRET, T2));
    p.i(isa::csrr(19, csr::MINSTRET)); // 0xffff_fff0
    p.i(isa::csrr(20, csr::MINSTRETH)); // 0
    p.li(T2, 0xffff_ffff).i(isa::csrrw(0, csr::MTVEC, T2));
    p.i(isa::csrr(21, csr::MTVEC)); // bit 1 reads zero
    p.i(isa::csrrw(0, csr::MIE, T2)).i(isa::csrr(22, csr::MIE));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    assert_eq!(
        [x[11], x[12], x[13]],
        [0x1234_5678, 0x1234_567b, 0x1234_5600]
    );
    assert_eq!(x[9], 0x4000_1105);
    assert_eq!(x[14], 0);
    assert_eq!(x[15], 10);
    // one cycle per CSR read (two when a counter carry falls in between)
    let d = x[17].wrapping_sub(x[16]);
    assert!((1..=2).contains(&d), "mcycle counts every cycle: {d}");
    assert_eq!([x[19], x[20]], [0xffff_fff0, 0]);
    assert_eq!(
        x[21], 0xffff_ffc1,
        "vectored: bit 1 and the table's low bits read zero"
    );
    assert_eq!(x[22], 0x888);
}

/// The counters count low bits in the core and carry into the register-file words between
/// instructions; these cross both 32-bit boundaries and the two writes that race a carry.
#[test]
fn counter_carries() {
    let mut p = Prog::new();
    // minstret across 2^32 by counting
    p.li(T2, 0xffff_fff0).i(isa::csrrw(0, csr::MINSTRET, T2));
    for _ in 0..40 {
        p.i(isa::NOP);
    }
    p.i(isa::csrr(A0, csr::MINSTRET))
        .i(isa::csrr(A1, csr::MINSTRETH));
    // a write of the low word when it is all ones: this instruction's increment still carries
    p.li(T2, u32::MAX).li(T1, 5);
    p.i(isa::csrrw(0, csr::MINSTRET, T2))
        .i(isa::csrrw(0, csr::MINSTRET, T1));
    p.i(isa::csrr(A2, csr::MINSTRET))
        .i(isa::csrr(A3, csr::MINSTRETH));
    // a write of the high word when the low word wraps: the write wins over the carry
    p.li(T2, u32::MAX).li(T1, 7);
    p.i(isa::csrrw(0, csr::MINSTRET, T2))
        .i(isa::csrrw(0, csr::MINSTRETH, T1));
    p.i(isa::csrr(14, csr::MINSTRET))
        .i(isa::csrr(15, csr::INSTRETH));
    // mcycle across 2^32 while the core waits
    p.li(T2, 0xffff_ff00).i(isa::csrrw(0, csr::MCYCLE, T2));
    p.i(isa::csrrw(0, csr::MCYCLEH, 0));
    p.li(T1, 200);
    let top = p.here();
    p.i(isa::addi(T1, T1, -1));
    let here = p.here();
    p.i(isa::bne(T1, 0, top as i32 - here as i32));
    p.i(isa::csrr(16, csr::MCYCLE))
        .i(isa::csrr(17, csr::CYCLEH));
    p.exit_pass();
    let (run, _) = run_pass(&p);
    let x = run.hart.x;
    // the first read sees the 40 NOPs after the write: 0xffff_fff0 + 40 = 2^32 + 0x18
    assert_eq!([x[10], x[11]], [0x18, 1]);
    assert_eq!([x[12], x[13]], [5, 2]);
    assert_eq!([x[14], x[15]], [0, 7]);
    assert_eq!(x[17], 1, "mcycleh after the low word wrapped");
    assert!(x[16] < 0x400, "mcycle {:#x}", x[16]);
}

#[test]
fn atomics() {
    use isa::amo;
    // (op, memory before, rs2, memory after)
    let cases = [
        (amo::SWAP, 5, 9, 9),
        (amo::ADD, 5, 9, 14),
        (amo::XOR, 0xf0, 0xff, 0x0f),
        (amo::AND, 0xf0, 0x3c, 0x30),
        (amo::OR, 0xf0, 0x0f, 0xff),
        (amo::MIN, 0xffff_fffe, 1, 0xffff_fffe),
        (amo::MAX, 0xffff_fffe, 1, 1),
        (amo::MINU, 0xffff_fffe, 1, 1),
        (amo::MAXU, 0xffff_fffe, 1, 0xffff_fffe),
    ];
    let mut p = Prog::new();
    p.li(S0, OUT);
    for (k, (op, before, rs2, _)) in cases.iter().enumerate() {
        p.li(A0, *before).li(A1, *rs2).i(isa::sw(A0, S0, 0));
        p.i(isa::amo_w(*op, A2, S0, A1))
            .i(isa::sw(A2, S0, 64 + 4 * k as i32));
        p.i(isa::lw(A3, S0, 0))
            .i(isa::sw(A3, S0, 128 + 4 * k as i32));
    }
    // LR/SC: success, then a failing SC without reservation, then a failing SC on another
    // address after LR.
    p.li(A0, 77).i(isa::sw(A0, S0, 0));
    p.i(isa::lr_w(A1, S0))
        .i(isa::addi(A1, A1, 1))
        .i(isa::sc_w(A2, S0, A1)); // a2 = 0
    p.i(isa::sc_w(A3, S0, A1)); // a3 = 1
    p.i(isa::addi(S1, S0, 4))
        .i(isa::lr_w(T2, S0))
        .i(isa::sc_w(S2, S1, A1)); // s2 = 1
    p.i(isa::lw(14, S0, 0));
    p.exit_pass();
    let (run, ls) = run_pass(&p);
    for (k, (_, before, _, after)) in cases.iter().enumerate() {
        assert_eq!(
            ls.model_word(OUT + 64 + 4 * k as u32),
            Some(*before),
            "old value {k}"
        );
        assert_eq!(
            ls.model_word(OUT + 128 + 4 * k as u32),
            Some(*after),
            "new value {k}"
        );
    }
    let x = run.hart.x;
    assert_eq!([x[12], x[13], x[18], x[14]], [0, 1, 1, 78]);
}

/// Program that enables one interrupt source, waits in WFI and records the cause.
fn interrupt_program(
    setup: &dyn Fn(&mut Prog),
    mie_bits: u32,
    ack: &dyn Fn(&mut Prog),
    vectored: bool,
) -> Prog {
    let mut p = Prog::new();
    p.li(S0, OUT);
    let jump = p.hole(1);
    // Vector table (used when vectored, 64-byte aligned): 12 slots each jumping to the common
    // handler.
    while !p.here().is_multiple_of(64) {
        p.i(isa::NOP);
    }
    let table = p.here();
    let slots = p.hole(12);
    let handler = p.here();
    for k in 0..12 {
        p.words[slots + k] = isa::jal(0, (handler - p.addr_of(slots + k)) as i32);
    }
    p.i(isa::csrr(T2, csr::MCAUSE)).i(isa::sw(T2, S0, 0));
    p.i(isa::csrr(T2, csr::MEPC)).i(isa::sw(T2, S0, 4));
    p.i(isa::addi(A3, A3, 1));
    ack(&mut p);
    p.i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T2, table | u32::from(vectored))
        .i(isa::csrrw(0, csr::MTVEC, T2));
    p.li(T2, mie_bits).i(isa::csrrw(0, csr::MIE, T2));
    setup(&mut p);
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let wfi = p.here();
    p.i(isa::WFI);
    p.li(T2, wfi + 4).i(isa::sw(T2, S0, 8));
    p.exit_pass();
    p
}

fn check_interrupt(p: &Prog, stimuli: &[(u64, Stimulus)], want: u32) {
    let (run, ls) = run_with(p, stimuli);
    assert_eq!(ls.model_word(OUT), Some(want), "mcause");
    let wfi_next = ls.model_word(OUT + 8).unwrap();
    assert_eq!(
        ls.model_word(OUT + 4),
        Some(wfi_next),
        "mepc is the instruction after WFI"
    );
    assert_eq!(run.hart.x[A3 as usize], 1, "handler ran once");
}

#[test]
fn timer_interrupt() {
    let setup = |p: &mut Prog| {
        p.li(A0, map::CLINT + 0x4000).li(A1, 300);
        p.i(isa::sw(0, A0, 4)).i(isa::sw(A1, A0, 0));
    };
    let ack = |p: &mut Prog| {
        p.li(A0, map::CLINT + 0x4000)
            .li(A1, 0xffff_ffff)
            .i(isa::sw(A1, A0, 4));
    };
    for vectored in [false, true] {
        let p = interrupt_program(&setup, 1 << 7, &ack, vectored);
        check_interrupt(&p, &[], cause::M_TIMER);
    }
}

#[test]
fn software_interrupt() {
    let setup = |p: &mut Prog| {
        p.li(A0, map::CLINT).li(A1, 1).i(isa::sw(A1, A0, 0));
    };
    let ack = |p: &mut Prog| {
        p.li(A0, map::CLINT).i(isa::sw(0, A0, 0));
    };
    let p = interrupt_program(&setup, 1 << 3, &ack, true);
    // The interrupt arrives before WFI, on the instruction after MIE is set.
    let (_, ls) = run_with(&p, &[]);
    assert_eq!(ls.model_word(OUT), Some(cause::M_SOFTWARE));
}

#[test]
fn external_interrupt() {
    let ack = |p: &mut Prog| {
        p.i(isa::csrrw(0, csr::MIE, 0));
    };
    let p = interrupt_program(&|_| {}, 1 << 11, &ack, false);
    // Raise the line well after the core went to sleep in WFI.
    check_interrupt(&p, &[(400, Stimulus::ExternalIrq(true))], cause::M_EXTERNAL);
}

#[test]
fn external_beats_software_beats_timer() {
    let setup = |p: &mut Prog| {
        p.li(A0, map::CLINT).li(A1, 1).i(isa::sw(A1, A0, 0));
        p.li(A0, map::CLINT + 0x4000)
            .i(isa::sw(0, A0, 4))
            .i(isa::sw(0, A0, 0));
    };
    let ack = |p: &mut Prog| {
        p.i(isa::csrrw(0, csr::MIE, 0));
    };
    let all = (1 << 3) | (1 << 7) | (1 << 11);
    let p = interrupt_program(&setup, all, &ack, true);
    let (_, ls) = run_with(&p, &[(0, Stimulus::ExternalIrq(true))]);
    assert_eq!(ls.model_word(OUT), Some(cause::M_EXTERNAL));
    let p = interrupt_program(&setup, all & !(1 << 11), &ack, true);
    let (_, ls) = run_with(&p, &[(0, Stimulus::ExternalIrq(true))]);
    assert_eq!(ls.model_word(OUT), Some(cause::M_SOFTWARE));
}

/// Every shift amount of every shift instruction (they run on the multiplier) on values with
/// either sign, against hand-computed results, in lockstep; register forms ignore the upper
/// bits of rs2.
#[test]
fn every_shift_amount() {
    let values = [0x8000_0001u32, 0x7fff_ffff, 0xdead_beef, 1, 0xffff_ffff, 0];
    for v in values {
        let mut p = Prog::new();
        p.li(A0, v).li(S0, RAM_BASE + 0x4_0000);
        let mut want = Vec::new();
        for sh in 0..32u32 {
            p.li(A1, sh | 0xa5a5_a5a0 & !31);
            p.i(isa::slli(A2, A0, sh as u8)).i(isa::sw(A2, S0, 0));
            p.i(isa::srli(A2, A0, sh as u8)).i(isa::sw(A2, S0, 4));
            p.i(isa::srai(A2, A0, sh as u8)).i(isa::sw(A2, S0, 8));
            p.i(isa::sll(A2, A0, A1)).i(isa::sw(A2, S0, 12));
            p.i(isa::srl(A2, A0, A1)).i(isa::sw(A2, S0, 16));
            p.i(isa::sra(A2, A0, A1)).i(isa::sw(A2, S0, 20));
            p.i(isa::addi(S0, S0, 24));
            let sra = ((v as i32) >> sh) as u32;
            want.extend([v << sh, v >> sh, sra, v << sh, v >> sh, sra]);
        }
        p.exit_pass();
        let (_, ls) = run_pass(&p);
        for (k, w) in want.iter().enumerate() {
            let addr = RAM_BASE + 0x4_0000 + 4 * k as u32;
            assert_eq!(ls.model_word(addr), Some(*w), "value {v:#x}, result {k}");
        }
    }
}

/// Every MUL* on the corner values of both signs (signed products multiply magnitudes and
/// negate), against 64-bit host arithmetic, in lockstep.
#[test]
fn multiply_corner_values() {
    let values = [
        0u32,
        1,
        0xffff_ffff,
        0x8000_0000,
        0x7fff_ffff,
        0x1234_5678,
        0xedcb_a988,
        0x0001_0000,
    ];
    let mut p = Prog::new();
    p.li(S0, RAM_BASE + 0x4_0000);
    let mut want = Vec::new();
    for a in values {
        for b in values {
            p.li(A0, a).li(A1, b);
            for f3 in 0..4u32 {
                p.i(isa::muldiv(f3, A2, A0, A1)).i(isa::sw(A2, S0, 0));
                p.i(isa::addi(S0, S0, 4));
            }
            let (sa, sb) = (i64::from(a as i32), i64::from(b as i32));
            let (ua, ub) = (u64::from(a), u64::from(b));
            want.extend([
                a.wrapping_mul(b),
                ((sa * sb) >> 32) as u32,
                ((sa * ub as i64) >> 32) as u32,
                ((ua * ub) >> 32) as u32,
            ]);
        }
    }
    p.exit_pass();
    let (_, ls) = run_pass(&p);
    for (k, w) in want.iter().enumerate() {
        let addr = RAM_BASE + 0x4_0000 + 4 * k as u32;
        assert_eq!(ls.model_word(addr), Some(*w), "product {k}");
    }
}

/// Every DIV/DIVU/REM/REMU on the corner values of both signs, division by zero and the
/// signed overflow included, against the ISA's definitions, in lockstep.
#[test]
fn divide_corner_values() {
    let values = [
        0u32,
        1,
        0xffff_ffff,
        0x8000_0000,
        0x7fff_ffff,
        0x1234_5678,
        0xedcb_a988,
        7,
    ];
    let mut p = Prog::new();
    p.li(S0, RAM_BASE + 0x4_0000);
    let mut want = Vec::new();
    for a in values {
        for b in values {
            p.li(A0, a).li(A1, b);
            for f3 in 4..8u32 {
                p.i(isa::muldiv(f3, A2, A0, A1)).i(isa::sw(A2, S0, 0));
                p.i(isa::addi(S0, S0, 4));
            }
            let (sa, sb) = (a as i32, b as i32);
            want.extend(match a.checked_div(b) {
                None => [u32::MAX, u32::MAX, a, a],
                Some(q) => [
                    sa.wrapping_div(sb) as u32,
                    q,
                    sa.wrapping_rem(sb) as u32,
                    a % b,
                ],
            });
        }
    }
    p.exit_pass();
    let (_, ls) = run_pass(&p);
    for (k, w) in want.iter().enumerate() {
        let addr = RAM_BASE + 0x4_0000 + 4 * k as u32;
        assert_eq!(ls.model_word(addr), Some(*w), "quotient/remainder {k}");
    }
}

/// The CSR read mux decodes only some address bits: every implemented CSR reads its own
/// value, and addresses next to them (differing in one bit) trap as illegal.
#[test]
fn csr_addresses_decode_exactly() {
    let implemented: [u16; 23] = [
        0x300, 0x301, 0x304, 0x305, 0x310, 0x340, 0x341, 0x342, 0x343, 0x344, 0xb00, 0xc00, 0xb80,
        0xc80, 0xb02, 0xc02, 0xb82, 0xc82, 0xf11, 0xf12, 0xf13, 0xf14, 0xf15,
    ];
    let mut neighbours = Vec::new();
    for a in implemented {
        for bit in 0..12 {
            let n = a ^ (1 << bit);
            if !implemented.contains(&n) && !neighbours.contains(&n) {
                neighbours.push(n);
            }
        }
    }
    // implemented: read in lockstep (the model checks every value)
    let mut p = Prog::new();
    p.li(T1, 0x1234_5678).i(isa::csrrw(0, csr::MSCRATCH, T1));
    for a in implemented {
        p.i(isa::csrr(A0, a));
    }
    p.exit_pass();
    run_pass(&p);
    // neighbours: each traps with the instruction as mtval
    for n in neighbours {
        let insn = isa::csrr(A0, n);
        expect_trap(&[insn], cause::ILLEGAL_INSTRUCTION, Some(insn));
    }
}

/// A store into an instruction the core has already fetched (the next one, or one to three
/// further on): the instruction runs as stored, as in the golden model. The pipelined core
/// discards what it fetched and fetches it again. The reference core takes a store into its
/// instruction word while it waits, but the instruction right after a store was fetched
/// before the store landed and runs as it was (RISC-V leaves that to FENCE.I, which neither
/// core has): it is held to distances 1 to 3.
#[test]
fn stores_into_the_instruction_stream() {
    for core in CoreVariant::ALL {
        let pipelined = matches!(core, CoreVariant::Pipe | CoreVariant::PipeMulSeq);
        for distance in u32::from(!pipelined)..4 {
            let mut p = Prog::new();
            p.li(T1, isa::addi(A0, ZERO, 42));
            let base = p.here();
            p.i(isa::auipc(T0, 0));
            let target = base + 8 + 4 * distance;
            p.i(isa::sw(T1, T0, (target - base) as i32));
            for _ in 0..distance {
                p.i(isa::NOP);
            }
            assert_eq!(p.here(), target);
            p.i(isa::addi(A0, ZERO, 1)); // replaced by `addi a0, zero, 42`
            p.li(T2, 42);
            p.i(isa::beq(A0, T2, 8));
            p.i(isa::jal(ZERO, 0)); // the old instruction ran: never exits
            p.exit_pass();
            let mut ls = Lockstep::with_core(core);
            ls.load(RAM_BASE, &p.words).expect("program fits");
            let run = ls
                .run(1_000, 10_000, &[])
                .unwrap_or_else(|m| panic!("{core:?}, distance {distance}: {}", describe(&m)));
            assert_eq!(run.exit, Some(Exit::Pass), "{core:?}, distance {distance}");
            assert_eq!(
                run.hart.x[usize::from(A0)],
                42,
                "{core:?}, distance {distance}"
            );
        }
    }
}
