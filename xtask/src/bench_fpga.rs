//! Benchmarks of the soft core on FPGAs and of its lockstep checking:
//!
//! - `fpga`: the SoC, the core alone and the vision unit alone on both boards (nextpnr seeds 1
//!   to 3): LUT4, FF, carry, RAM, SPRAM, DSP, logic cells and Fmax against the SoC clock and
//!   the goals; the UP5K SoC at the bring-up clock.
//! - `probes`: the planned core's stages alone; `anchors`: the published cores the goals were
//!   set against, through the same flow, when their netlists have been downloaded.
//! - `lockstep`: at least 10^8 instructions checked against the golden model: seeded random
//!   streams (compressed instructions included) run over and over, and the firmware with
//!   frames for its vision pipeline.

use std::fmt::Write as _;

use anyhow::{Context, Result};
use fpga::{Board, Design, Outcome, Sources, Stage, Target};

use crate::bench::{field, figures, ignored_test_named, verdict};

/// Goal of the issue: LUT4 of the core with C (the Fmax goals: `Board::fmax_goal_mhz`).
const CORE_LUT_GOAL: u64 = 2000;
/// Goal of the vision unit: LUT4 (and it must run at the SoC clock).
pub(crate) const VISION_LUT_GOAL: u64 = 800;
/// Seeds of each placement.
const SEEDS: [u64; 3] = [1, 2, 3];
/// The bring-up clock divider of the UP5K row.
const BRING_UP_DIV_LOG2: u32 = 2;
/// Instructions the lockstep benchmark checks at least.
const LOCKSTEP_GOAL: u64 = 100_000_000;

fn row(o: &Outcome) -> String {
    let t = &o.target;
    let lc = o.logic_cells.map_or("?".into(), |u| u.describe());
    let (fmax, met) = match (&o.placed, o.fmax_mhz()) {
        (Some(_), Some(f)) => (
            format!("{f:.2}"),
            if o.timing_met() { "met" } else { "**missed**" },
        ),
        _ => ("not placed".into(), "**does not fit**"),
    };
    let dsp = o
        .placed
        .as_ref()
        .and_then(|p| p.timing.dsp_bound_mhz(&p.clock))
        .map_or(String::new(), |d| format!(" (DSP paths {d:.1})"));
    format!(
        "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {fmax}{dsp} | {:.4} | {met} |",
        t.board.name(),
        match (t.design, t.clock_div_log2) {
            (Design::Soc, 0) if t.vision_unit => "SoC with the vision unit".to_owned(),
            (Design::Soc, 0) => "SoC".to_owned(),
            (Design::Soc, n) => format!("SoC, clock / {}", 1u32 << n),
            (Design::Core, _) => "core".to_owned(),
            (Design::Vision, _) => format!(
                "vision unit ({} words a buffer)",
                1u32 << t.board.vision_cap_aw()
            ),
            (Design::Probe(stage), _) => format!("{} stage (probe)", stage.name()),
            (Design::Reference, _) => "another core".to_owned(),
        },
        t.seed,
        o.cells.lut4,
        o.cells.ff,
        o.cells.carry,
        o.cells.ram,
        o.cells.spram,
        o.cells.dsp,
        lc,
        o.target_mhz(),
    )
}

/// Places and routes the SoC and the core on both boards and tabulates the figures.
pub fn fpga() -> Result<String> {
    crate::install::ensure_fpga_tools()?;
    let out = crate::fpga::out_dir().join("bench");
    let sources = Sources::in_workspace();
    let mut targets = Vec::new();
    for board in Board::ALL {
        for seed in SEEDS {
            targets.push(Target {
                seed,
                ..Target::soc(board)
            });
        }
        for seed in SEEDS {
            targets.push(Target {
                seed,
                ..Target::core(board)
            });
        }
        for seed in SEEDS {
            targets.push(Target {
                seed,
                ..Target::vision(board)
            });
        }
    }
    targets.push(Target {
        clock_div_log2: BRING_UP_DIV_LOG2,
        ..Target::soc(Board::Up5k)
    });
    // Each board's SoC with its vision unit (the other rows' SoCs are without it).
    for board in Board::ALL {
        targets.push(Target {
            vision_unit: true,
            ..Target::soc(board)
        });
    }
    let mut outcomes = Vec::new();
    for t in &targets {
        println!("placing and routing {}", t.dir_name());
        let o = fpga::build(t, &sources, &out).with_context(|| t.dir_name())?;
        print!("{}", fpga::summary(&o));
        outcomes.push(o);
    }

    let mut md = String::from("## The soft core on iCE40 FPGAs\n\n");
    let _ = writeln!(
        md,
        "`synth_ice40 -abc9` (`-dsp` on UP5K), nextpnr-ice40 timed at the SoC clock ({:.4} MHz, the boards' PLL), three placer seeds. Fmax is nextpnr's for the SoC clock, or the bound of the paths through the DSP blocks when lower (nextpnr 0.4 times a combinational DSP block as registered; docs/fpga.md). LUT4, FF and carry are yosys's cells; logic cells are nextpnr's after packing.\n",
        fpga::SOC_CLOCK_MHZ
    );
    let _ = writeln!(
        md,
        "| board | design | seed | LUT4 | FF | carry | RAM | SPRAM | DSP | logic cells | Fmax (MHz) | clock (MHz) | timing |"
    );
    let _ = writeln!(
        md,
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|---:|---|"
    );
    for o in &outcomes {
        let _ = writeln!(md, "{}", row(o));
    }
    let _ = writeln!(
        md,
        "\n| goal | measured (best seed) | verdict |\n|---|---|---|"
    );
    for board in Board::ALL {
        let best = outcomes
            .iter()
            .filter(|o| {
                o.target.board == board
                    && o.target.design == Design::Soc
                    && o.target.clock_div_log2 == 0
                    && !o.target.vision_unit
            })
            .filter_map(Outcome::fmax_mhz)
            .fold(None, |m: Option<f64>, f| Some(m.map_or(f, |m| m.max(f))));
        let _ = writeln!(
            md,
            "| SoC Fmax on {} >= {} MHz | {} | {} |",
            board.name(),
            board.fmax_goal_mhz(),
            best.map_or("not placed".into(), |f| format!("{f:.2} MHz")),
            verdict(best.is_some_and(|f| f >= board.fmax_goal_mhz()))
        );
    }
    if let Some(core) = outcomes
        .iter()
        .find(|o| o.target.design == Design::Core && o.target.board == Board::Up5k)
    {
        let _ = writeln!(
            md,
            "| core with C <= {CORE_LUT_GOAL} LUT4 (UP5K, multiplier in DSP blocks) | {} | {} |",
            core.cells.lut4,
            verdict(core.cells.lut4 <= CORE_LUT_GOAL)
        );
    }
    for board in Board::ALL {
        let units: Vec<&Outcome> = outcomes
            .iter()
            .filter(|o| o.target.design == Design::Vision && o.target.board == board)
            .collect();
        if let Some(first) = units.first() {
            let fmax = units
                .iter()
                .filter_map(|o| o.fmax_mhz())
                .fold(f64::NAN, f64::min);
            let ok = first.cells.lut4 <= VISION_LUT_GOAL && units.iter().all(|o| o.timing_met());
            let _ = writeln!(
                md,
                "| vision unit <= {VISION_LUT_GOAL} LUT4 at the SoC clock ({}) | {} LUT4, Fmax {fmax:.1} MHz (worst seed) | {} |",
                board.name(),
                first.cells.lut4,
                verdict(ok)
            );
        }
    }
    let _ = write!(
        md,
        "\nReproduce: `cargo xtask bench --only fpga`; one build: `cargo xtask fpga --board up5k --seed 1` (`--core` for the core alone, `--vision` for the vision unit alone, `--clock-div 2` for the bring-up clock). Outputs, logs and reports in `target/fpga/`."
    );
    Ok(md)
}

/// Places and routes each timing probe (a pipeline stage of the planned core alone between
/// flip-flops) on both boards and holds its Fmax against the SoC's goal.
pub fn probes() -> Result<String> {
    crate::install::ensure_fpga_tools()?;
    let out = crate::fpga::out_dir().join("bench");
    let sources = Sources::in_workspace();
    let mut md = String::from("## The planned core's stages on iCE40 FPGAs\n\n");
    md.push_str(
        "Each pipeline stage of the six-stage core that docs/fpga.md plans, alone between flip-flops and fed by an LFSR (`verilator-tb/fpga/probe/`), through the SoC's flow (`synth_ice40 -abc9`, `-dsp` on UP5K; nextpnr-ice40, three placer seeds). A stage holds the SoC's Fmax goal when its worst seed does; what the goal leaves over is what the stage's share of the rest of the core (its control, the fuller part) may take.\n\n",
    );
    md.push_str(
        "| stage | board | LUT4 | FF | carry | RAM | logic cells | Fmax by seed (MHz) | goal (MHz) | worst seed's margin |\n|---|---|---:|---:|---:|---:|---|---|---:|---|\n",
    );
    for stage in Stage::ALL {
        for board in Board::ALL {
            let mut fmax = Vec::new();
            let mut first: Option<Outcome> = None;
            for seed in SEEDS {
                let t = Target {
                    board,
                    design: Design::Probe(stage),
                    seed,
                    clock_div_log2: 0,
                    vision_unit: false,
                };
                println!("placing and routing {}", t.dir_name());
                let o = fpga::build(&t, &sources, &out).with_context(|| t.dir_name())?;
                print!("{}", fpga::summary(&o));
                fmax.push(o.fmax_mhz());
                first.get_or_insert(o);
            }
            let o = first.context("no seeds")?;
            let worst = fmax.iter().flatten().copied().fold(f64::NAN, f64::min);
            let seeds: Vec<String> = fmax
                .iter()
                .map(|f| f.map_or("not placed".into(), |f| format!("{f:.2}")))
                .collect();
            let placed = fmax.iter().all(Option::is_some);
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                stage.name(),
                board.name(),
                o.cells.lut4,
                o.cells.ff,
                o.cells.carry,
                o.cells.ram,
                o.logic_cells.map_or("?".into(), |u| u.describe()),
                seeds.join(" / "),
                board.fmax_goal_mhz(),
                if placed {
                    format!("{:+.0} %", (worst / board.fmax_goal_mhz() - 1.0) * 100.0)
                } else {
                    "**not placed**".into()
                }
            );
        }
    }
    md.push_str(
        "\nReproduce: `cargo xtask bench --only probes`; one: `cargo xtask fpga --board hx8k --probe fetch --seed 1`. Outputs in `target/fpga/bench/`.\n",
    );
    Ok(md)
}

/// The long lockstep run: random streams and the firmware, with the golden model.
pub fn lockstep() -> Result<String> {
    let random = ignored_test_named(
        "verilator-tb",
        "random",
        "random_streams_in_lockstep_long",
        &[],
    )?;
    let r = figures(&random, "lockstep-random").context("no figures from the random streams")?;
    let random_seq = ignored_test_named(
        "verilator-tb",
        "random",
        "random_streams_in_lockstep_long_hx8k_core",
        &[],
    )?;
    let q = figures(&random_seq, "lockstep-random-hx8k")
        .context("no figures from the random streams on the HX8K's core")?;
    let elf = crate::fw::build("softcore", true)?;
    let firmware = ignored_test_named(
        "verilator-tb",
        "firmware",
        "firmware_in_lockstep_long",
        &[("VTB_FIRMWARE", elf.as_os_str())],
    )?;
    let f = figures(&firmware, "lockstep-firmware").context("no figures from the firmware")?;
    let (ri, rc, rw) = (
        field(&r, "instructions")?,
        field(&r, "compressed")?,
        field(&r, "wall_s")?,
    );
    let (fi, fw, frames) = (
        field(&f, "instructions")?,
        field(&f, "wall_s")?,
        field(&f, "frames")?,
    );
    let (qi, qc, qw) = (
        field(&q, "instructions")?,
        field(&q, "compressed")?,
        field(&q, "wall_s")?,
    );
    let total = ri + qi + fi;
    let mut md = String::from("## Lockstep with the golden model\n\n");
    let _ = writeln!(
        md,
        "| run | instructions checked | mismatches | wall time |"
    );
    let _ = writeln!(md, "|---|---:|---:|---:|");
    let _ = writeln!(
        md,
        "| random streams (360 seeds x 100 passes; {rc:.0} compressed) | {ri:.0} | 0 | {rw:.0} s |"
    );
    let _ = writeln!(
        md,
        "| random streams on the HX8K's core (pipelined, sequential multiplier; 36 seeds x 100 passes; {qc:.0} compressed) | {qi:.0} | 0 | {qw:.0} s |"
    );
    let _ = writeln!(
        md,
        "| firmware + lbc-emu + ground station, {frames:.0} camera frames | {fi:.0} | 0 | {fw:.0} s |"
    );
    let _ = writeln!(
        md,
        "| total (goal >= {LOCKSTEP_GOAL}) | **{total:.0}** | 0 | {} |",
        verdict(total >= LOCKSTEP_GOAL as f64)
    );
    let _ = write!(
        md,
        "\nReproduce: `cargo xtask bench --only lockstep` (`cargo test -p verilator-tb --release --test random -- --ignored --exact random_streams_in_lockstep_long` and `random_streams_in_lockstep_long_hx8k_core`; the firmware half with `VTB_FIRMWARE`: `--test firmware -- --ignored firmware_in_lockstep_long`). A mismatch fails the run."
    );
    Ok(md)
}

/// A published core the FPGA goals were set against, as its project generated it.
struct Anchor {
    /// What it is.
    name: &'static str,
    /// Its configuration, as its generator's arguments give it.
    config: &'static str,
    /// The file's name in [`anchors_dir`].
    file: &'static str,
    /// Its top module.
    top: &'static str,
    /// Where the file is published (a commit's raw URL).
    url: &'static str,
    /// The boards it is placed on.
    boards: &'static [Board],
}

const ANCHORS: [Anchor; 3] = [
    Anchor {
        name: "VexRiscv Up5kPerf (SoC)",
        config: "RV32IM, no C or A; six stages, two of fetch; branch prediction; the product on four SB_MAC16, written back after memory; SPRAM; 27 MHz with iCEcube2 by its README",
        file: "Up5kPerf.v",
        top: "Up5kPerf",
        url: "https://raw.githubusercontent.com/SpinalHDL/VexRiscvSoftcoreContest2018/403d49b43e845d2d21bf58d35342a48dd0a86808/hardware/netlist/Up5kPerf.v",
        boards: &[Board::Up5k],
    },
    Anchor {
        name: "VexRiscv IMAC (LiteX's core)",
        config: "RV32IMC (LiteX's `--atomics` sets the multiplier, so no A); five stages, full bypass, static branch prediction, 4 KiB instruction and data caches, products in four 17x17 parts, iterative divider",
        file: "VexRiscv_IMAC.v",
        top: "VexRiscv",
        url: "https://raw.githubusercontent.com/litex-hub/pythondata-cpu-vexriscv/8845e3a9a32457c69df989b312f7b77a9939976f/pythondata_cpu_vexriscv/verilog/VexRiscv_IMAC.v",
        boards: &[Board::Up5k, Board::Hx8k],
    },
    Anchor {
        name: "VexRiscv Min (LiteX's core)",
        config: "RV32I; five stages, no bypass (interlocks), no branch prediction, no caches, shifts a bit a cycle",
        file: "VexRiscv_Min.v",
        top: "VexRiscv",
        url: "https://raw.githubusercontent.com/litex-hub/pythondata-cpu-vexriscv/712322a6b708eeef84b4afa54a0ccd58f88c0a43/pythondata_cpu_vexriscv/verilog/VexRiscv_Min.v",
        boards: &[Board::Hx8k, Board::Up5k],
    },
];

/// Where the anchors' netlists are read from (downloaded by hand: they are other projects'
/// files, not ours).
pub fn anchors_dir() -> std::path::PathBuf {
    crate::fpga::out_dir().join("anchors")
}

/// `anchors`: the published cores the goals were set against through the same flow, each
/// in the generated wrapper (`fpga::reference`), three seeds on each board it is placed on.
/// A netlist that is not in [`anchors_dir`] is a row that says how to get it.
pub fn anchors() -> Result<String> {
    crate::install::ensure_fpga_tools()?;
    let dir = anchors_dir();
    let out = crate::fpga::out_dir().join("bench");
    let sources = Sources::in_workspace();
    let mut md = String::from("## The anchors through this flow\n\n");
    md.push_str(
        "Published cores the FPGA goals were set against, as their projects generated them, each in the wrapper of `fpga::reference` (every input bit from a register of its own fed by an LFSR, the outputs into a signature register whose two bits are the core alone's pins) through the same flow as ours (`synth_ice40 -abc9`, `-dsp` on UP5K; nextpnr-ice40, three placer seeds), held to the boards' goals. The logic cells include the wrapper's registers (one per input and output bit, and the fold).\n\n",
    );
    md.push_str(
        "| core | configuration | board | LUT4 | FF | RAM | DSP | logic cells | wrapper bits (in / out) | Fmax by seed (MHz) | goal (MHz) |\n|---|---|---|---:|---:|---:|---:|---|---|---|---:|\n",
    );
    let mut missing = Vec::new();
    for a in &ANCHORS {
        let file = dir.join(a.file);
        if !file.is_file() {
            missing.push(a);
            let _ = writeln!(
                md,
                "| {} | {} | | | | | | netlist not present: `{}` | | | |",
                a.name,
                a.config,
                file.strip_prefix(crate::workspace_root())
                    .unwrap_or(&file)
                    .display()
            );
            continue;
        }
        let reference = fpga::reference::Reference {
            files: vec![file],
            top: a.top.into(),
            clock: None,
            reset: None,
        };
        for &board in a.boards {
            let mut fmax = Vec::new();
            let mut first = None;
            for seed in SEEDS {
                println!(
                    "placing and routing {}",
                    fpga::reference::dir_name(board, &reference, seed)
                );
                let b = fpga::reference::build(&reference, board, seed, &sources, &out)
                    .with_context(|| format!("{} on {}", a.name, board.name()))?;
                print!("{}", fpga::summary(&b.outcome));
                fmax.push(b.outcome.fmax_mhz());
                let placed = b.outcome.placed.is_some();
                first.get_or_insert(b);
                if !placed {
                    // the same netlist does not fit at another seed either
                    break;
                }
            }
            let b = first.context("no seeds")?;
            let o = &b.outcome;
            let (ins, outs) = b.wrapper_bits();
            let dsp = o
                .placed
                .as_ref()
                .and_then(|p| p.utilization.get("ICESTORM_DSP"))
                .map_or(o.cells.dsp, |u| u.used);
            let seeds: Vec<String> = fmax
                .iter()
                .map(|f| f.map_or("**not placed**".into(), |f| format!("{f:.2}")))
                .collect();
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {ins} / {outs} | {} | {} |",
                a.name,
                a.config,
                board.name(),
                o.cells.lut4,
                o.cells.ff,
                o.cells.ram,
                dsp,
                o.logic_cells.map_or("?".into(), |u| u.describe()),
                seeds.join(" / "),
                board.fmax_goal_mhz()
            );
        }
    }
    let shown = dir
        .strip_prefix(crate::workspace_root())
        .unwrap_or(&dir)
        .display();
    let _ = writeln!(
        md,
        "\nReproduce: put the netlists in `{shown}` and run `cargo xtask bench --only anchors`; one: `cargo xtask fpga --board up5k --reference {shown}/Up5kPerf.v --top Up5kPerf --seed 1`. The netlists, at the commits measured:\n"
    );
    for a in &ANCHORS {
        let _ = writeln!(md, "- `{}`: <{}>", a.file, a.url);
    }
    if !missing.is_empty() {
        let names: Vec<&str> = missing.iter().map(|a| a.file).collect();
        println!(
            "anchors: {} not in {} (download them from the URLs in the report to measure them)",
            names.join(", "),
            dir.display()
        );
    }
    Ok(md)
}
