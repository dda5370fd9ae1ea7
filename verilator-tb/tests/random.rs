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
use verilator_tb::soc::{Exit, RAM_BASE};

#[test]
fn random_streams_match_the_model() {
    for seed in 0..40 {
        let (p, stimuli) = stream(seed);
        let mut ls = Lockstep::new();
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
    let start = Instant::now();
    let (mut retired, mut cycles, mut compressed) = (0u64, 0u64, 0u64);
    for seed in LONG_SEEDS {
        let budget = 12_000 * u64::from(LONG_PASSES);
        let (p, stimuli) = looped(seed, LONG_PASSES, budget);
        let mut ls = Lockstep::new();
        ls.keep_records();
        ls.load(RAM_BASE, &p.words).expect("program fits");
        let run = ls
            .run(u64::MAX, budget * 4, &stimuli)
            .unwrap_or_else(|m| panic!("seed {seed}: {}", describe(&m)));
        assert_eq!(
            run.exit,
            Some(Exit::Pass),
            "seed {seed} did not finish: pc {:#x} retired {} cycles {}",
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
        "random streams: {retired} instructions ({compressed} compressed) in {cycles} cycles, \
         {} streams x {LONG_PASSES} passes, no mismatch, {wall:.0} s",
        LONG_SEEDS.end - LONG_SEEDS.start
    );
    println!(
        "figures: mode=lockstep-random instructions={retired} compressed={compressed} cycles={cycles} mismatches=0 wall_s={wall:.3}"
    );
}
