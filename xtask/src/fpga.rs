//! `cargo xtask fpga`: the SoC on the iCE40 boards, synthesised, placed, routed, timed and
//! packed into bitstreams, with the program image the boards load from their SPI flash.
//! Outputs go to `target/fpga/`; see docs/fpga.md.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fpga::{Board, Design, Sources, Stage, Target};

use crate::{install, stage, workspace_root};

/// Options of `cargo xtask fpga`.
#[derive(Debug, clap::Args)]
pub struct FpgaArgs {
    /// Board to build for (both when left out).
    #[arg(long, value_parser = parse_board)]
    board: Option<Board>,
    /// nextpnr's placer seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Run the SoC at its clock divided by 2^N (bring-up where timing is not met at the full
    /// clock; 0 is the SoC clock, 14.8125 MHz).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=3))]
    clock_div: u32,
    /// Build the core alone instead of the SoC (area and clock figures; no bitstream to use).
    #[arg(long, conflicts_with = "vision")]
    core: bool,
    /// Build the vision unit alone instead of the SoC (area and clock figures).
    #[arg(long, conflicts_with = "vision_unit")]
    vision: bool,
    /// Build the SoC with its vision unit (the UP5K SoC does not fit with it).
    #[arg(long, conflicts_with = "core")]
    vision_unit: bool,
    /// Build a timing probe instead of the SoC: one pipeline stage of the planned core alone
    /// between flip-flops (fetch, decode or execute; docs/fpga.md).
    #[arg(long, value_name = "STAGE", conflicts_with_all = ["core", "vision", "vision_unit"])]
    probe: Option<Stage>,
    /// Build another core instead of the SoC: its Verilog file(s), in a generated wrapper that
    /// drives its inputs from an LFSR and takes its outputs into two pins, held to the board's
    /// Fmax goal (how the same flow does with the cores the goals were set against;
    /// docs/fpga.md). Needs --top.
    #[arg(long, value_name = "FILE", num_args = 1.., requires = "top",
          conflicts_with_all = ["core", "vision", "vision_unit", "probe"])]
    reference: Vec<PathBuf>,
    /// The top module of --reference.
    #[arg(long, value_name = "MODULE", requires = "reference")]
    top: Option<String>,
    /// The clock input of --reference (else clk, clock, io_clk, io_mainClk or CLK).
    #[arg(long, value_name = "PORT", requires = "reference")]
    clock_port: Option<String>,
    /// The reset input of --reference (else reset, rst, io_reset, resetn, rst_n or
    /// io_asyncReset if there is one; a name ending in n or _b is active low).
    #[arg(long, value_name = "PORT", requires = "reference")]
    reset_port: Option<String>,
}

/// `--reference`: another core on each board; fails only when it cannot be placed.
fn run_reference(
    args: &FpgaArgs,
    top: &str,
    boards: &[Board],
    sources: &Sources,
    out: &Path,
) -> Result<()> {
    for f in &args.reference {
        if !f.is_file() {
            bail!("--reference: no file {}", f.display());
        }
    }
    let reference = fpga::reference::Reference {
        files: args.reference.clone(),
        top: top.to_owned(),
        clock: args.clock_port.clone(),
        reset: args.reset_port.clone(),
    };
    let mut failed = Vec::new();
    for &board in boards {
        stage(&format!(
            "{} {} (another core)",
            board.title(),
            reference.name()
        ));
        let built = fpga::reference::build(&reference, board, args.seed, sources, out)
            .with_context(|| format!("building {top} for {}", board.name()))?;
        let (ins, outs) = built.wrapper_bits();
        println!(
            "{top} in the wrapper: {ins} input and {outs} output bits in its registers (about \
             {} logic cells of the figures below are the wrapper's)",
            built.wrapper_cells()
        );
        let outcome = built.outcome;
        print!("{}", fpga::summary(&outcome));
        if outcome.placed.is_none() {
            failed.push(fpga::reference::dir_name(board, &reference, args.seed));
        }
    }
    if !failed.is_empty() {
        bail!(
            "not placed: {} (outputs in {})",
            failed.join(", "),
            out.display()
        );
    }
    Ok(())
}

fn parse_board(s: &str) -> Result<Board, String> {
    s.parse::<Board>().map_err(|e| e.to_string())
}

/// Where the flow's outputs go.
pub fn out_dir() -> PathBuf {
    workspace_root().join("target/fpga")
}

/// Builds the requested targets; fails when one does not fit or misses its clock.
pub fn run(args: FpgaArgs) -> Result<()> {
    install::ensure_fpga_tools()?;
    let boards: Vec<Board> = args.board.map_or(Board::ALL.to_vec(), |b| vec![b]);
    let out = out_dir();
    let sources = Sources::in_workspace();
    if let Some(top) = &args.top {
        return run_reference(&args, top, &boards, &sources, &out);
    }
    let mut failed = Vec::new();
    for board in boards {
        let target = Target {
            board,
            design: if let Some(stage) = args.probe {
                Design::Probe(stage)
            } else if args.core {
                Design::Core
            } else if args.vision {
                Design::Vision
            } else {
                Design::Soc
            },
            seed: args.seed,
            clock_div_log2: args.clock_div,
            vision_unit: args.vision_unit,
        };
        stage(&format!("{} {}", board.title(), target.design.name()));
        let outcome = fpga::build(&target, &sources, &out)
            .with_context(|| format!("building {}", target.dir_name()))?;
        print!("{}", fpga::summary(&outcome));
        if target.design == Design::Soc {
            let image = out.join(format!("{}-program.bin", target.dir_name()));
            std::fs::write(&image, fpga::demo::image(board, args.clock_div))
                .with_context(|| format!("writing {}", image.display()))?;
            if let Some(p) = &outcome.placed {
                println!(
                    "  program image: {}\n  flash both: iceprog {}  then  iceprog -o 1M {}",
                    image.display(),
                    p.bitstream.display(),
                    image.display()
                );
            }
        }
        if !outcome.timing_met() {
            failed.push(target.dir_name());
        }
    }
    if !failed.is_empty() {
        bail!(
            "not placed, or timing not met at the clock: {} (outputs in {})",
            failed.join(", "),
            out.display()
        );
    }
    Ok(())
}
