//! Seeded random instruction streams (`common::stream`) run in lockstep with the golden model:
//! ALU, M, loads and stores (some misaligned), forward branches and jumps, compressed
//! instructions and 32-bit ones at halfword addresses,
//! atomics, CSR accesses, encodings that must be illegal, and an external interrupt line
//! toggled at random cycles. A trap handler skips every trapping instruction.
mod common;
use common::stream::{stream, STREAM_LEN};
use common::*;
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
