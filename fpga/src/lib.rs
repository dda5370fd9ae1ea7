//! The soft core's SoC on iCE40 FPGAs.
//!
//! - [`board`]: the two boards (iCEBreaker's UP5K, the HX8K breakout), what is built for each
//!   ([`Design::Soc`], [`Design::Core`]) and where the Verilog is (`verilator-tb/rtl` for the
//!   SoC, `verilator-tb/fpga` for board tops, FPGA-only modules and pin files).
//! - [`flow`]: yosys `synth_ice40` -> nextpnr-ice40 (fixed seed, timed at the SoC clock) ->
//!   icepack, outputs under a directory of the caller's (`cargo xtask fpga` uses
//!   `target/fpga/`).
//! - [`report`]: cell counts, utilization and timing read from the tools' output, with the
//!   paths through DSP blocks that nextpnr 0.4 leaves out of a clock's Fmax added back.
//! - [`reference`]: another core's published Verilog through the same flow, in a generated
//!   wrapper (what the flow makes of the cores the goals were set against).
//! - [`demo`]: the program image the boards load from their SPI flash.
//!
//! docs/fpga.md describes the flow, the boards, their memory and clocking.

pub mod board;
pub mod demo;
pub mod flow;
pub mod reference;
pub mod report;

pub use board::{Board, Design, Sources, Stage, Target, SOC_CLOCK_MHZ, SOC_CLOCK_NOMINAL_MHZ};
pub use flow::{build, missing_tools, FlowError, Outcome, DEBIAN_PACKAGES};

/// A few lines for people: utilization, Fmax against the clock, the bitstream.
pub fn summary(o: &Outcome) -> String {
    let t = &o.target;
    let mut s = format!(
        "{} {} on {} (seed {}): {} LUT4, {} FF, {} carry, {} RAM, {} SPRAM, {} DSP\n",
        t.design.name(),
        t.top(),
        t.board.title(),
        t.seed,
        o.cells.lut4,
        o.cells.ff,
        o.cells.carry,
        o.cells.ram,
        o.cells.spram,
        o.cells.dsp
    );
    if let Some(lc) = o.logic_cells {
        s.push_str(&format!("  logic cells: {}\n", lc.describe()));
    }
    match (&o.placed, &o.failure) {
        (Some(p), _) => {
            for kind in [
                "ICESTORM_RAM",
                "ICESTORM_SPRAM",
                "ICESTORM_DSP",
                "SB_IO",
                "SB_GB",
            ] {
                if let Some(u) = p.utilization.get(kind) {
                    s.push_str(&format!("  {kind}: {}\n", u.describe()));
                }
            }
            for (net, mhz) in &p.timing.fmax_mhz {
                s.push_str(&format!("  nextpnr Fmax {net}: {mhz:.2} MHz\n"));
            }
            if let Some(d) = p.timing.dsp_bound_mhz(&p.clock) {
                s.push_str(&format!(
                    "  through the DSP blocks (in + between + out): {d:.2} MHz\n"
                ));
            }
            if let Some(c) = p.timing.critical(&p.clock) {
                s.push_str(&format!(
                    "  critical path ({} -> {}): {:.1} ns, {} cells, from {} to {}\n",
                    c.from,
                    c.to,
                    c.delay_ns,
                    c.cells.len(),
                    c.cells.first().map_or("?", String::as_str),
                    c.cells.last().map_or("?", String::as_str),
                ));
            }
            let fmax = o.fmax_mhz().unwrap_or(0.0);
            s.push_str(&format!(
                "  Fmax {fmax:.2} MHz against {:.4} MHz: {}\n  bitstream: {}\n",
                o.target_mhz(),
                if o.timing_met() { "met" } else { "NOT MET" },
                p.bitstream.display()
            ));
        }
        (None, Some(f)) => s.push_str(&format!("  placement failed: {f}\n")),
        (None, None) => s.push_str("  not placed\n"),
    }
    s
}
