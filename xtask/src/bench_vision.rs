//! `vision-unit`: the SoC's vision unit against the firmware's own pixel pipeline, on the soft
//! core's model (cycle counts, so the figures do not depend on the machine's load): the awake
//! cycles a frame's vision costs, the frames per second that allows at the SoC's 14.7456 MHz,
//! and the processor's share at 30 fps (arena benchmark `vision_unit_load`); the unit's LUT4
//! and Fmax from `cargo xtask fpga --vision` on both boards (placer seed 1).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use fpga::{Board, Sources, Target};

use crate::bench::{field, figures, ignored_test_named, verdict};
use crate::bench_fpga::VISION_LUT_GOAL;

/// The goal's frame rate and the processor's largest share on vision at it.
const FPS_GOAL: f64 = 30.0;
const SHARE_GOAL: f64 = 0.25;
/// The SoC clock of the model, Hz.
const CLOCK_HZ: f64 = 14_745_600.0;
/// A VGA row on the camera's pixel stream: 640 pixels and 144 blank clocks (soc-model's
/// `CameraTiming`), 480 rows: the unit's own limit at one pixel a clock.
const VGA_FRAME_CLOCKS: f64 = 784.0 * 480.0;

/// Runs the arena benchmark and the FPGA builds; the report section.
pub fn vision_unit() -> Result<String> {
    let softcore = crate::fw::build("softcore", true)?;
    let load = ignored_test_named(
        "arena",
        "arena_bench",
        "vision_unit_load",
        &[("VTB_FIRMWARE", softcore.as_os_str())],
    )?;
    let f = figures(&load, "vision").context("no vision figures from the arena benchmark")?;
    crate::install::ensure_fpga_tools()?;
    let out = crate::fpga::out_dir().join("bench");
    let sources = Sources::in_workspace();
    let mut units = Vec::new();
    for board in Board::ALL {
        let t = Target::vision(board);
        println!("placing and routing {}", t.dir_name());
        let o = fpga::build(&t, &sources, &out).with_context(|| t.dir_name())?;
        print!("{}", fpga::summary(&o));
        units.push((board, o.cells.lut4, o.fmax_mhz(), o.timing_met()));
    }
    let table: String = load
        .lines()
        .filter(|l| l.starts_with('|'))
        .map(|l| format!("{l}\n"))
        .collect();
    let fpga_rows: Vec<FpgaRow> = units
        .iter()
        .map(|&(board, lut4, fmax, met)| FpgaRow {
            board: board.name(),
            lut4,
            fmax,
            met,
        })
        .collect();
    section(
        &table,
        Figures {
            unit_cycles: field(&f, "unit_cycles")?,
            sw_cycles: field(&f, "sw_cycles")?,
            unit_fps30: field(&f, "unit_fps30")?,
            sw_fps30: field(&f, "sw_fps30")?,
            unit_share30: field(&f, "unit_share30")?,
            sw_share30: field(&f, "sw_share30")?,
        },
        &fpga_rows,
    )
}

/// The arena benchmark's figures.
struct Figures {
    unit_cycles: f64,
    sw_cycles: f64,
    unit_fps30: f64,
    sw_fps30: f64,
    unit_share30: f64,
    sw_share30: f64,
}

/// One board's build of the unit alone.
struct FpgaRow {
    board: &'static str,
    lut4: u64,
    fmax: Option<f64>,
    met: bool,
}

fn section(table: &str, f: Figures, fpga: &[FpgaRow]) -> Result<String> {
    anyhow::ensure!(
        f.unit_cycles > 0.0 && f.sw_cycles > 0.0,
        "no cycles per frame measured"
    );
    let mut md = String::from("## The vision unit\n\n");
    let _ = writeln!(
        md,
        "A car seeing two others on the soft core's model (cycle counts: independent of the machine's load); vision's cycles are the car's awake cycles over those of the same car without a camera.\n"
    );
    md.push_str(table);
    let _ = writeln!(
        md,
        "\n| figure | with the unit | without |\n|---|---:|---:|"
    );
    let _ = writeln!(
        md,
        "| awake cycles per frame for vision (10 fps) | {:.0} | {:.0} |",
        f.unit_cycles, f.sw_cycles
    );
    let _ = writeln!(
        md,
        "| frames per second at 14.7456 MHz, processor alone | {:.0} | {:.1} |",
        CLOCK_HZ / f.unit_cycles,
        CLOCK_HZ / f.sw_cycles
    );
    let _ = writeln!(
        md,
        "| frames processed per second, camera at 30 fps | {:.1} | {:.1} |",
        f.unit_fps30, f.sw_fps30
    );
    let _ = writeln!(
        md,
        "| processor on vision, camera at 30 fps | {:.1} % | {:.1} % |",
        100.0 * f.unit_share30,
        100.0 * f.sw_share30
    );
    let _ = writeln!(
        md,
        "\nThe unit's own limit at VGA, one pixel a clock: {:.1} frames per second.\n",
        CLOCK_HZ / VGA_FRAME_CLOCKS
    );
    let _ = writeln!(
        md,
        "| board | LUT4 | Fmax (MHz) | SoC clock met |\n|---|---:|---:|---|"
    );
    for r in fpga {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} |",
            r.board,
            r.lut4,
            r.fmax.map_or("not placed".into(), |m| format!("{m:.2}")),
            if r.met { "yes" } else { "no" }
        );
    }
    let fps_ok = f.unit_fps30 >= FPS_GOAL - 0.5 && f.unit_share30 <= SHARE_GOAL;
    let lut_ok = !fpga.is_empty() && fpga.iter().all(|r| r.lut4 <= VISION_LUT_GOAL && r.met);
    let _ = writeln!(
        md,
        "\n{FPS_GOAL:.0} fps at VGA with the processor at most {:.0} % on vision: {:.1} fps, {:.1} % with the unit: {}",
        100.0 * SHARE_GOAL,
        f.unit_fps30,
        100.0 * f.unit_share30,
        verdict(fps_ok)
    );
    let worst = fpga.iter().map(|r| r.lut4).max().unwrap_or(0);
    let _ = writeln!(
        md,
        "\nThe unit at most {VISION_LUT_GOAL} LUT4 at the SoC clock: {worst} LUT4: {}",
        verdict(lut_ok)
    );
    let _ = write!(
        md,
        "\nReproduce: `cargo xtask bench --only vision-unit`, or `cargo test -p arena --release --test arena_bench vision_unit_load -- --ignored --nocapture` and `cargo xtask fpga --vision`."
    );
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figs(unit_share30: f64) -> Figures {
        Figures {
            unit_cycles: 37_000.0,
            sw_cycles: 780_000.0,
            unit_fps30: 30.0,
            sw_fps30: 5.2,
            unit_share30,
            sw_share30: 0.94,
        }
    }

    fn rows(lut4: u64) -> Vec<FpgaRow> {
        vec![FpgaRow {
            board: "up5k",
            lut4,
            fmax: Some(20.9),
            met: true,
        }]
    }

    #[test]
    fn goals_are_judged() {
        let md = section("| t |\n", figs(0.07), &rows(450)).unwrap();
        assert!(md.contains("| awake cycles per frame for vision (10 fps) | 37000 | 780000 |"));
        assert!(md.contains("| frames per second at 14.7456 MHz, processor alone | 399 | 18.9 |"));
        assert!(!md.contains("**missed**"), "{md}");
        let md = section("", figs(0.3), &rows(450)).unwrap();
        assert!(
            md.contains("30.0 fps, 30.0 % with the unit: **missed**"),
            "{md}"
        );
        assert_eq!(md.matches("**missed**").count(), 1, "{md}");
        let md = section("", figs(0.07), &rows(900)).unwrap();
        assert_eq!(md.matches("**missed**").count(), 1, "{md}");
        let mut zero = figs(0.07);
        zero.unit_cycles = 0.0;
        assert!(section("", zero, &rows(450)).is_err());
    }
}
