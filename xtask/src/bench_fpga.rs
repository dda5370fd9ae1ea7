//! Benchmarks of the soft core on FPGAs and of its lockstep checking:
//!
//! - `fpga`: the SoC, the core alone and the vision unit alone on both boards (nextpnr seeds 1
//!   to 3): LUT4, FF, carry, RAM, SPRAM, DSP, logic cells and Fmax against the SoC clock and
//!   the goals; the UP5K SoC at the bring-up clock.
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
