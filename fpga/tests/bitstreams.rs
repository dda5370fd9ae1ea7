//! Bitstreams through the whole flow: synthesised, placed and routed with nextpnr's fixed seed,
//! packed by icepack, and timed (the paths through DSP blocks included, see `fpga::report`).
//!
//! What holds today (docs/fpga.md, timing): on the UP5K the SoC fits but reaches about 6.7 MHz,
//! so its bitstream is built with the board top's bring-up clock divider (the SoC clock / 4,
//! 3.7 MHz) and must meet that; the HX8K SoC (its core multiplying in the divider's loop, as
//! the part has no DSP blocks) must meet the SoC clock itself. `cargo xtask bench --only
//! fpga` reports the full-clock figures of both SoCs. A design that does not fit, or that
//! misses its clock, fails with the figures.
//!
//! Skipped, with a message, when yosys, nextpnr-ice40 or icepack is not installed
//! (`cargo xtask test` installs them: Debian packages yosys, nextpnr-ice40, fpga-icestorm).

use std::path::PathBuf;

use fpga::{Board, Sources, Target};

fn bitstream(target: Target) {
    let missing = fpga::missing_tools();
    if !missing.is_empty() {
        println!(
            "SKIPPED: {} not installed (Debian packages {})",
            missing.join(", "),
            fpga::DEBIAN_PACKAGES.join(" ")
        );
        return;
    }
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("bitstreams");
    let name = target.dir_name();
    let outcome = fpga::build(&target, &Sources::in_workspace(), &out).expect("the flow runs");
    let summary = fpga::summary(&outcome);
    println!("{summary}");
    let placed = outcome
        .placed
        .as_ref()
        .unwrap_or_else(|| panic!("{name} was not placed and routed:\n{summary}"));
    let size = std::fs::metadata(&placed.bitstream).map_or(0, |m| m.len());
    // an iCE40 bitstream of these devices is over 100 KB
    assert!(
        size > 100_000,
        "{} is {size} bytes",
        placed.bitstream.display()
    );
    assert!(
        outcome.timing_met(),
        "{name} misses its clock of {:.2} MHz (docs/fpga.md):\n{summary}",
        target.clock_mhz()
    );
}

#[test]
fn up5k_soc_bitstream_meets_the_bring_up_clock() {
    let mut t = Target::soc(Board::Up5k);
    t.clock_div_log2 = 2;
    bitstream(t);
}

#[test]
fn hx8k_soc_bitstream_meets_the_soc_clock() {
    bitstream(Target::soc(Board::Hx8k));
}
