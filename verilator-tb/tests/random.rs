//! Seeded random instruction streams (`common::stream`) run in lockstep with the golden model:
//! ALU, M, loads and stores (some misaligned), forward branches and jumps, compressed
//! instructions and 32-bit ones at halfword addresses,
//! atomics, CSR accesses, encodings that must be illegal, and an external interrupt line
//! toggled at random cycles. A trap handler skips every trapping instruction.
mod common;
use common::stream::{looped, stream, STREAM_LEN};
use common::*;
use std::time::Instant;
use verilator_tb::lockstep::Lockstep;
use verilator_tb::soc::{CoreVariant, Exit, RAM_BASE};

#[test]
fn random_streams_match_the_model() {
    streams_match_the_model(CoreVariant::Dsp, 0..40);
}

/// The reference core for parts without DSP blocks (MUL* in the divider's loop, shifts on a
/// barrel shifter) retires the same streams as the golden model.
#[test]
fn random_streams_match_the_model_on_the_sequential_multiplier() {
    streams_match_the_model(CoreVariant::MulSeq, 0..20);
}

#[test]
fn random_streams_match_the_model_on_the_pipelined_core() {
    streams_match_the_model(CoreVariant::Pipe, 0..20);
}

#[test]
fn random_streams_match_the_model_on_the_pipelined_core_with_the_sequential_multiplier() {
    streams_match_the_model(CoreVariant::PipeMulSeq, 0..20);
}

/// On the sequential multiplier an interrupt that becomes pending during a product is taken
/// after it (as during a division). Seed 2004's looped stream raises six during products.
#[test]
fn sequential_multiplier_finishes_before_an_interrupt() {
    const PASSES: u32 = 20;
    let budget = 12_000 * u64::from(PASSES);
    let (p, stimuli) = looped(2004, PASSES, budget);
    let mut ls = Lockstep::with_core(CoreVariant::MulSeq);
    ls.keep_records();
    ls.load(RAM_BASE, &p.words).expect("program fits");
    let run = ls
        .run(u64::MAX, budget * 4, &stimuli)
        .unwrap_or_else(|m| panic!("{}", describe(&m)));
    assert_eq!(run.exit, Some(Exit::Pass), "retired {}", run.retired);
    // the case itself: a product retired and an interrupt was taken right after it
    // (a compressed record holds its 16 bits: C.MUL is a product too)
    let is_mul = |insn: u32| soc_model::rvc::as_32bit(insn) & 0xfe00_407f == 0x0200_0033;
    let after_product = run
        .records
        .windows(2)
        .filter(|w| is_mul(w[0].1.insn) && w[1].1.intr)
        .count();
    assert!(after_product > 0, "no interrupt right after a product");
}

/// MUL, MULH, MULHSU and MULHU take 34 cycles on the reference core's sequential multiplier,
/// 11 on the pipelined core's (7 when the multiplier has at most 16 bits) and one on a DSP,
/// and give the same products (every sign combination, both words, zero, the extremes and the
/// 16-bit boundary of either sign) on all four cores, checked against the golden model and
/// against Rust's arithmetic.
#[test]
fn sequential_multiplier_products_and_cycles() {
    use verilator_tb::isa::{self, reg::*};
    const S0: u8 = 8;
    let operands = [
        0u32,
        1,
        2,
        3,
        0x7fff_ffff,
        0x8000_0000,
        0xffff_ffff,
        0x1234_5678,
        0xdead_beef,
        0x0001_0000,
        0xffff_0001,
        0x0000_ffff,
        0xffff_8000,
        0x0001_8000,
    ];
    let out = RAM_BASE + 0x8_0000;
    // (funct3, the product's word as Rust computes it)
    type Word = fn(u32, u32) -> u32;
    let ops: [(u32, Word); 4] = [
        (0, |a, b| a.wrapping_mul(b)),
        (1, |a, b| {
            ((i64::from(a as i32) * i64::from(b as i32)) >> 32) as u32
        }),
        (2, |a, b| {
            ((i64::from(a as i32) * i64::from(b)) >> 32) as u32
        }),
        (3, |a, b| ((u64::from(a) * u64::from(b)) >> 32) as u32),
    ];
    let mut p = Prog::new();
    p.li(S0, out);
    let mut want = Vec::new();
    for a in operands {
        for b in operands {
            for (op, f) in ops {
                // a store's offset reaches 2 KiB: the base moves on every 256 words
                let k = want.len();
                if k > 0 && k % 256 == 0 {
                    p.i(isa::addi(S0, S0, 1024));
                }
                p.li(A0, a)
                    .li(A1, b)
                    .i(isa::muldiv(op, A2, A0, A1))
                    .i(isa::sw(A2, S0, 4 * (k % 256) as i32));
                want.push((a, b, f(a, b)));
            }
        }
    }
    p.exit_pass();
    let mut cycles = Vec::new();
    for core in [
        CoreVariant::Dsp,
        CoreVariant::MulSeq,
        CoreVariant::Pipe,
        CoreVariant::PipeMulSeq,
    ] {
        let mut ls = Lockstep::with_core(core);
        ls.load(RAM_BASE, &p.words).expect("program fits");
        let run = ls
            .run(1_000_000, 10_000_000, &[])
            .unwrap_or_else(|m| panic!("{core:?}: {}", describe(&m)));
        assert_eq!(run.exit, Some(Exit::Pass), "{core:?}");
        for (k, (a, b, w)) in want.iter().enumerate() {
            let got = ls.model_word(out + 4 * k as u32).unwrap();
            assert_eq!(got, *w, "{core:?} op {} a={a:#x} b={b:#x}", k % 4);
        }
        cycles.push(run.cycles);
    }
    // Each product 33 cycles longer, plus the counter-carry cycles of the longer run (one
    // each time the 6-bit cycle count wraps, between instructions).
    let longer = cycles[1] as i64 - cycles[0] as i64;
    let carries = longer - 33 * want.len() as i64;
    assert!(
        (0..=longer / 64 + 2).contains(&carries),
        "cycles {cycles:?}: {carries} beyond 33 a product"
    );
    // The pipelined core's sequential multiplier takes four bits a cycle, after a cycle that
    // works out three times the multiplicand: 11 cycles in X where the DSP takes one, 7 when
    // the multiplier (rs1, as a magnitude where the operation takes it signed) has no more
    // than 16 significant bits.
    let extra: u64 = want
        .iter()
        .enumerate()
        .map(|(k, (a, _, _))| {
            let signed = matches!(k % 4, 1 | 2);
            let magnitude = if signed {
                (*a as i32).unsigned_abs()
            } else {
                *a
            };
            if magnitude >> 16 == 0 {
                6
            } else {
                10
            }
        })
        .sum();
    assert!(extra > 6 * want.len() as u64 && extra < 10 * want.len() as u64);
    assert_eq!(cycles[3] - cycles[2], extra, "pipelined cycles {cycles:?}");
}

fn streams_match_the_model(core: CoreVariant, seeds: std::ops::Range<u64>) {
    for seed in seeds {
        let (p, stimuli) = stream(seed);
        let mut ls = Lockstep::with_core(core);
        ls.keep_records();
        ls.load(RAM_BASE, &p.words).expect("program fits");
        let run = ls
            .run(200_000, 2_000_000, &stimuli)
            .unwrap_or_else(|m| panic!("seed {seed}: {}", describe(&m)));
        assert_eq!(
            run.exit,
            Some(Exit::Pass),
            "seed {seed} did not finish: pc {:#x} retired {} cycles {}",
            run.hart.pc,
            run.retired,
            run.cycles
        );
        assert!(
            run.retired > STREAM_LEN as u64 / 2,
            "seed {seed} retired {}",
            run.retired
        );
        // compressed instructions, and 32-bit ones at halfword addresses, ran
        let short = run.records.iter().filter(|(_, r)| r.insn & 3 != 3).count();
        let half = run
            .records
            .iter()
            .filter(|(_, r)| r.insn & 3 == 3 && r.pc_rdata & 2 != 0)
            .count();
        assert!(
            short > 200 && half > 20,
            "seed {seed}: {short} compressed, {half} at 2 mod 4"
        );
    }
}

/// Seeds of the long run (none of them is a seed of the test above).
const LONG_SEEDS: std::ops::Range<u64> = 1000..1360;
/// Passes over each seed's stream.
const LONG_PASSES: u32 = 100;

/// The long lockstep run of `cargo xtask bench --only lockstep`: 360 seeded streams, each run
/// 100 times over (about 2.5e5 instructions a stream, compressed ones included, the interrupt
/// line toggling throughout), every instruction checked against the golden model. Prints the
/// `figures:` line the benchmark reads.
#[test]
#[ignore = "long: run by cargo xtask bench --only lockstep"]
fn random_streams_in_lockstep_long() {
    long_run(CoreVariant::Dsp, LONG_SEEDS, "lockstep-random");
}

/// Seeds of the long run on the HX8K's core (a tenth of [`LONG_SEEDS`]).
const LONG_SEEDS_HX8K: std::ops::Range<u64> = 2000..2036;

/// The same on the HX8K's core (pipelined, multiplication in the divider's loop), over 36
/// seeds.
#[test]
#[ignore = "long: run by cargo xtask bench --only lockstep"]
fn random_streams_in_lockstep_long_hx8k_core() {
    long_run(
        CoreVariant::PipeMulSeq,
        LONG_SEEDS_HX8K,
        "lockstep-random-hx8k",
    );
}

fn long_run(core: CoreVariant, seeds: std::ops::Range<u64>, mode: &str) {
    let start = Instant::now();
    let (mut retired, mut cycles, mut compressed) = (0u64, 0u64, 0u64);
    for seed in seeds.clone() {
        let budget = 12_000 * u64::from(LONG_PASSES);
        let (p, stimuli) = looped(seed, LONG_PASSES, budget);
        let mut ls = Lockstep::with_core(core);
        ls.keep_records();
        ls.load(RAM_BASE, &p.words).expect("program fits");
        let run = ls
            .run(u64::MAX, budget * 4, &stimuli)
            .unwrap_or_else(|m| panic!("{core:?} seed {seed}: {}", describe(&m)));
        assert_eq!(
            run.exit,
            Some(Exit::Pass),
            "{core:?} seed {seed} did not finish: pc {:#x} retired {} cycles {}",
            run.hart.pc,
            run.retired,
            run.cycles
        );
        retired += run.retired;
        cycles += run.cycles;
        compressed += run.records.iter().filter(|(_, r)| r.insn & 3 != 3).count() as u64;
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "random streams ({core:?} core): {retired} instructions ({compressed} compressed) in \
         {cycles} cycles, {} streams x {LONG_PASSES} passes, no mismatch, {wall:.0} s",
        seeds.end - seeds.start
    );
    println!(
        "figures: mode={mode} instructions={retired} compressed={compressed} cycles={cycles} mismatches=0 wall_s={wall:.3}"
    );
}
