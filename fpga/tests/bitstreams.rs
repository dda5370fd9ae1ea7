//! The SoC's bitstream for each board: synthesised, placed and routed with nextpnr's fixed
//! seed, packed by icepack, and timed at the SoC clock (14.8125 MHz, the boards' PLL; the
//! paths through DSP blocks included, see `fpga::report`). A design that does not fit, or
//! that misses the clock, fails with the figures.
//!
//! Skipped, with a message, when yosys, nextpnr-ice40 or icepack is not installed
//! (`cargo xtask test` installs them: Debian packages yosys, nextpnr-ice40, fpga-icestorm).

use std::path::PathBuf;

use fpga::{Board, Sources, Target};

fn soc_bitstream(board: Board) {
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
    let target = Target::soc(board);
    let outcome = fpga::build(&target, &Sources::in_workspace(), &out).expect("the flow runs");
    let summary = fpga::summary(&outcome);
    println!("{summary}");
    let placed = outcome
        .placed
        .as_ref()
        .unwrap_or_else(|| panic!("the {board} SoC was not placed and routed:\n{summary}"));
    let size = std::fs::metadata(&placed.bitstream).map_or(0, |m| m.len());
    // an iCE40 bitstream of these devices is over 100 KB
    assert!(
        size > 100_000,
        "{} is {size} bytes",
        placed.bitstream.display()
    );
    assert!(
        outcome.timing_met(),
        "the {board} SoC misses the SoC clock (docs/fpga.md):\n{summary}"
    );
}

#[test]
fn up5k_soc_bitstream_meets_the_soc_clock() {
    soc_bitstream(Board::Up5k);
}

#[test]
fn hx8k_soc_bitstream_meets_the_soc_clock() {
    soc_bitstream(Board::Hx8k);
}
