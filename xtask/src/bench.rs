//! `cargo xtask bench`: runs the project's benchmarks and prints their figures as markdown,
//! each with the command that reproduces it.
//!
//! - `size`: text/data/bss of the qemu_virt release firmware against the size goals.
//! - `fw-decode`: RV32 instructions per received byte for deframing and decoding a full
//!   STREAM, counted with `minstret` by the `bench_lbc_decode` firmware binary under
//!   `qemu-system-riscv32 -icount shift=0`.
//! - `host-decode`: `cargo bench -p lbc-link --bench decode`.
//! - `radio`: `cargo bench -p arena --bench radio`.
//!
//! `--only NAME` runs one of them; `--out FILE` also writes the markdown to a file.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use object::{Object, ObjectSection, ObjectSymbol, SectionKind, SymbolKind};
use qemu_harness::{Qemu, UartAttach};

use crate::{fw, stage, workspace_root};

/// Goal for code and read-only data of the firmware.
const TEXT_GOAL: u64 = 64 * 1024;
/// Goal for static RAM (data + bss) without the buffers.
const STATIC_RAM_GOAL: u64 = 16 * 1024;
/// Static objects at least this large count as buffers (UART rings, frame buffers).
const BUFFER_MIN: u64 = 1024;
/// How many of the largest functions the size report lists.
const TOP_FUNCTIONS: usize = 8;
/// Goal for the on-target LBC receive path.
const INSTRUCTIONS_PER_BYTE_GOAL: f64 = 25.0;
/// The on-target benchmark program (a binary of `ubc-app`).
const FW_BENCH_BIN: &str = "bench_lbc_decode";
/// The stage whose figure is held against the goal.
const HEADLINE_STAGE: &str = "decode_all";
/// How long the on-target benchmark may run in QEMU.
const FW_BENCH_TIMEOUT: Duration = Duration::from_secs(120);

/// Options of `cargo xtask bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Run only this benchmark.
    #[arg(long, value_enum)]
    only: Option<Bench>,
    /// Also write the markdown report to this file.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

/// The benchmarks, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Bench {
    /// Firmware section sizes.
    Size,
    /// Instructions per byte of the LBC receive path on the firmware (QEMU).
    FwDecode,
    /// lbc-link decode throughput on the host.
    HostDecode,
    /// Radio protocol: bytes on air and delivery ratio.
    Radio,
    /// Synthetic camera render rate and host vision rate.
    Camera,
    /// How many QEMU cars keep real time in the arena.
    Arena,
}

impl Bench {
    const ALL: [Bench; 6] = [
        Bench::Size,
        Bench::FwDecode,
        Bench::HostDecode,
        Bench::Radio,
        Bench::Camera,
        Bench::Arena,
    ];

    fn title(self) -> &'static str {
        match self {
            Bench::Size => "firmware size",
            Bench::FwDecode => "lbc-link on the firmware (instructions per byte)",
            Bench::HostDecode => "lbc-link host decode throughput",
            Bench::Radio => "radio",
            Bench::Camera => "synthetic camera",
            Bench::Arena => "QEMU cars in real time",
        }
    }
}

/// Runs the selected benchmarks and prints one markdown report.
pub fn run(args: BenchArgs) -> Result<()> {
    let selected: Vec<Bench> = match args.only {
        Some(one) => vec![one],
        None => Bench::ALL.to_vec(),
    };
    let mut report = String::from("# Benchmarks\n");
    let mut failed = Vec::new();
    for bench in selected {
        stage(bench.title());
        let section = match bench {
            Bench::Size => size(),
            Bench::FwDecode => fw_decode(),
            Bench::HostDecode => cargo_bench("lbc-link", "decode", "lbc-link host decode"),
            Bench::Radio => cargo_bench("arena", "radio", "Radio"),
            Bench::Camera => cargo_bench("arena", "camera", "Synthetic camera"),
            Bench::Arena => arena(),
        };
        match section {
            Ok(text) => {
                report.push('\n');
                report.push_str(&text);
            }
            Err(e) => {
                let _ = write!(report, "\n## {}\n\nFAILED: {e:#}\n", bench.title());
                failed.push(bench.title());
            }
        }
    }
    println!("\n{report}");
    if let Some(out) = &args.out {
        std::fs::write(out, &report).with_context(|| format!("writing {}", out.display()))?;
    }
    if !failed.is_empty() {
        bail!("benchmarks failed: {}", failed.join(", "));
    }
    Ok(())
}

fn kib(bytes: u64) -> String {
    format!("{:.1} KiB", bytes as f64 / 1024.0)
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "**missed**"
    }
}

/// Firmware section sizes against the goals.
fn size() -> Result<String> {
    let elf = fw::build("qemu_virt", true)?;
    let s = fw::sizes(&elf)?;
    let buffers = buffer_objects(&elf)?;
    // Every static object counts, the UART rings too; only camera frame buffers would be
    // left out (the frame grabber's window is outside the image).
    let static_ram = s.data + s.bss;
    let mut md = String::from("## Firmware size (qemu_virt, release)\n\n");
    let _ = writeln!(md, "| section | bytes | goal | |");
    let _ = writeln!(md, "|---|---:|---:|---|");
    let _ = writeln!(
        md,
        "| text (code + read-only data) | {} ({}) | <= {} | {} |",
        s.text,
        kib(s.text),
        kib(TEXT_GOAL),
        verdict(s.text <= TEXT_GOAL)
    );
    let _ = writeln!(md, "| data | {} | | |", s.data);
    let _ = writeln!(md, "| bss | {} ({}) | | |", s.bss, kib(s.bss));
    let _ = writeln!(
        md,
        "| static RAM (data + bss) | {static_ram} ({}) | <= {} | {} |",
        kib(static_ram),
        kib(STATIC_RAM_GOAL),
        verdict(static_ram <= STATIC_RAM_GOAL)
    );
    let _ = writeln!(
        md,
        "\nLarge static objects ({BUFFER_MIN} bytes or more), counted above:\n"
    );
    if buffers.is_empty() {
        let _ = writeln!(md, "- none");
    }
    for (name, bytes) in &buffers {
        let _ = writeln!(md, "- `{name}`: {bytes} bytes");
    }
    let _ = writeln!(md, "\nLargest functions (bytes of code):\n");
    for (bytes, name) in largest_functions(&elf, TOP_FUNCTIONS)? {
        let _ = writeln!(md, "- {bytes} `{name}`");
    }
    let _ = writeln!(
        md,
        "\nStack and heap reservations of the linker script are not counted.\n\
         Reproduce: `cargo xtask fw --board qemu_virt` (prints `text N data N bss N`)."
    );
    Ok(md)
}

/// The `n` largest function symbols of the ELF, largest first, demangled.
fn largest_functions(elf: &Path, n: usize) -> Result<Vec<(u64, String)>> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let mut funcs: Vec<(u64, String)> = file
        .symbols()
        .filter(|sym| sym.kind() == SymbolKind::Text && sym.size() > 0)
        .map(|sym| {
            let name = sym.name().unwrap_or("?");
            (sym.size(), format!("{:#}", rustc_demangle::demangle(name)))
        })
        .collect();
    funcs.sort_by(|a, b| b.cmp(a));
    funcs.dedup();
    funcs.truncate(n);
    Ok(funcs)
}

/// Writable static objects of at least [`BUFFER_MIN`] bytes, by demangled name.
fn buffer_objects(elf: &Path) -> Result<BTreeMap<String, u64>> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let mut out = BTreeMap::new();
    for sym in file.symbols() {
        if sym.kind() != SymbolKind::Data || sym.size() < BUFFER_MIN {
            continue;
        }
        let Some(index) = sym.section_index() else {
            continue;
        };
        let Ok(section) = file.section_by_index(index) else {
            continue;
        };
        if !matches!(
            section.kind(),
            SectionKind::Data | SectionKind::UninitializedData
        ) || matches!(section.name(), Ok(".stack" | ".heap"))
        {
            continue;
        }
        let name = sym.name().unwrap_or("?");
        out.insert(format!("{:#}", rustc_demangle::demangle(name)), sym.size());
    }
    Ok(out)
}

/// One `bench stage=...` line of the on-target benchmark.
#[derive(Debug, Clone, PartialEq, Eq)]
struct StageFigure {
    stage: String,
    instructions: u64,
    bytes: u64,
    frames: u64,
}

impl StageFigure {
    fn parse(message: &str) -> Option<StageFigure> {
        let mut words = message.split_whitespace();
        if words.next() != Some("bench") {
            return None;
        }
        let mut fig = StageFigure {
            stage: String::new(),
            instructions: 0,
            bytes: 0,
            frames: 0,
        };
        let mut seen = 0;
        for word in words {
            let (key, value) = word.split_once('=')?;
            match key {
                "stage" => fig.stage = value.to_owned(),
                "instructions" => fig.instructions = value.parse().ok()?,
                "bytes" => fig.bytes = value.parse().ok()?,
                "frames" => fig.frames = value.parse().ok()?,
                _ => continue,
            }
            seen += 1;
        }
        (seen == 4 && !fig.stage.is_empty()).then_some(fig)
    }

    fn per_byte(&self) -> Option<f64> {
        (self.bytes > 0).then(|| self.instructions as f64 / self.bytes as f64)
    }
}

/// What each stage of the on-target benchmark measures.
fn stage_meaning(stage: &str) -> &'static str {
    match stage {
        "empty" => "an empty region (the reads, plus what the compiler schedules between)",
        "loop1000" => "calibration: 1000 iterations of a 2-instruction loop",
        "loop2000" => "calibration: 2000 iterations of a 2-instruction loop",
        "deframe" => "`Deframer::push` per byte, messages counted, no STREAM decoding",
        "deframe_slice" => "`Deframer::push_slice` (bulk), no STREAM decoding",
        "decode_all" => "`lbc_link::decode_all`: deframe + checksum + STREAM decode",
        "decode_keep" => "deframe + `StreamSample::decode`, every sample kept (`black_box`)",
        _ => "",
    }
}

/// Runs the on-target benchmark in QEMU and turns its log into a table.
fn fw_decode() -> Result<String> {
    crate::install::ensure_qemu()?;
    let elf = fw::build_bin("qemu_virt", FW_BENCH_BIN, true)?;
    let mut qemu = Qemu::builder(&elf)
        .lbc(UartAttach::Null)
        .radio(UartAttach::Null)
        .icount(Some(0))
        .spawn()
        .with_context(|| format!("starting QEMU with {}", elf.display()))?;
    let status = qemu.wait_exit(FW_BENCH_TIMEOUT);
    // Reaps QEMU and lets the log readers reach the end of its output.
    let _ = qemu.kill();
    let lines = qemu.log().lines();
    for line in &lines {
        eprintln!("fw: {line}");
    }
    let status = status.context("waiting for the benchmark firmware to exit")?;
    if !status.success() {
        bail!(
            "the benchmark firmware failed ({status}); QEMU stderr: {}",
            qemu.stderr_text()
        );
    }
    let figures: Vec<StageFigure> = lines
        .iter()
        .filter_map(|l| StageFigure::parse(&l.message))
        .collect();
    fw_decode_table(&figures)
}

fn fw_decode_table(figures: &[StageFigure]) -> Result<String> {
    let find = |name: &str| figures.iter().find(|f| f.stage == name);
    let (Some(short), Some(long)) = (find("loop1000"), find("loop2000")) else {
        bail!("the benchmark log has no calibration lines");
    };
    if long.instructions.checked_sub(short.instructions) != Some(2000) {
        bail!(
            "minstret is not an exact instruction count: loops of 1000 and 2000 iterations \
             gave {} and {}",
            short.instructions,
            long.instructions
        );
    }
    // The counter includes one of the two reads; the loops show it.
    let overhead = short.instructions.saturating_sub(2000);
    let Some(headline) = find(HEADLINE_STAGE) else {
        bail!("the benchmark log has no `{HEADLINE_STAGE}` line");
    };
    let per_byte = headline.per_byte().unwrap_or(f64::INFINITY);

    let mut md = String::from("## lbc-link on the firmware: instructions per received byte\n\n");
    let _ = writeln!(
        md,
        "STREAM at 30 Hz with every valid variable (format `0x0FDF9F1F` = all 28 bits except \
         the NOT-IN-USE mask `0x002060E0`), {} messages of {} bytes, counted with `minstret` \
         on RV32IMA under `qemu-system-riscv32 -icount shift=0` (release build, opt-level \"s\").\n",
        headline.frames,
        headline.bytes.checked_div(headline.frames).unwrap_or(0)
    );
    let _ = writeln!(
        md,
        "| stage | what | instructions | bytes | messages | instructions/byte | instructions/message |"
    );
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|");
    for f in figures {
        let per_byte = f
            .per_byte()
            .map_or_else(|| "-".to_owned(), |v| format!("{v:.2}"));
        let per_msg = if f.frames > 0 {
            format!("{:.0}", f.instructions as f64 / f.frames as f64)
        } else {
            "-".to_owned()
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} | {} |",
            f.stage,
            stage_meaning(&f.stage),
            f.instructions,
            f.bytes,
            f.frames,
            per_byte,
            per_msg
        );
    }
    let _ = writeln!(
        md,
        "\n**{per_byte:.2} instructions per byte** for `{HEADLINE_STAGE}` (goal <= {:.0}: {}). \
         Calibration: the two loops differ by exactly 2000 instructions; a count includes {} \
         instruction(s) of the reads themselves.\n",
        INSTRUCTIONS_PER_BYTE_GOAL,
        verdict(per_byte <= INSTRUCTIONS_PER_BYTE_GOAL),
        overhead
    );
    let _ = writeln!(md, "Reproduce: `cargo xtask bench --only fw-decode`.");
    Ok(md)
}

/// Runs `cargo bench -p <package> --bench <bench>` and returns its markdown output from the
/// first line that starts with `|` or `#`.
fn cargo_bench(package: &str, bench: &str, title: &str) -> Result<String> {
    let args = ["bench", "-p", package, "--bench", bench];
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let out = Command::new(cargo)
        .args(args)
        .current_dir(workspace_root())
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("running cargo {}", args.join(" ")))?;
    if !out.status.success() {
        bail!("cargo {} failed ({})", args.join(" "), out.status);
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let body = markdown_part(&text);
    if body.is_empty() {
        bail!("cargo {} printed no markdown", args.join(" "));
    }
    let mut md = String::new();
    if !body.starts_with('#') {
        let _ = writeln!(md, "## {title}\n");
    }
    md.push_str(body.trim_end());
    let _ = writeln!(md, "\n\nReproduce: `cargo {}`.", args.join(" "));
    Ok(md)
}

/// Car counts the arena benchmark tries.
const ARENA_CARS: &str = "1,2,4,8,12,16";

/// Boots N cars in QEMU (N from [`ARENA_CARS`]) and reports whether each keeps its 30 Hz
/// stream, tracking and console; the benchmark is an ignored test of `arena`.
fn arena() -> Result<String> {
    let elf = crate::fw::build("qemu_virt", true)?;
    let args = [
        "test",
        "-p",
        "arena",
        "--release",
        "--test",
        "arena_bench",
        "--",
        "--ignored",
        "--nocapture",
    ];
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let out = Command::new(cargo)
        .args(args)
        .env("ARENA_BENCH_N", ARENA_CARS)
        .env("UBC_FW_ELF", &elf)
        .current_dir(workspace_root())
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("running cargo {}", args.join(" ")))?;
    if !out.status.success() {
        bail!("cargo {} failed ({})", args.join(" "), out.status);
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let table: Vec<&str> = text.lines().filter(|l| l.starts_with('|')).collect();
    if table.is_empty() {
        bail!("the arena benchmark printed no table");
    }
    let mut md = String::from("## QEMU cars in real time\n\n");
    for line in table {
        md.push_str(line);
        md.push('\n');
    }
    let _ = write!(
        md,
        "\nReproduce: `ARENA_BENCH_N={ARENA_CARS} cargo {}` (or `cargo xtask bench --only arena`).",
        args.join(" ")
    );
    Ok(md)
}

/// The output from its first markdown line (a table row or a heading) on.
fn markdown_part(text: &str) -> &str {
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let t = line.trim_start();
        if t.starts_with('|') || t.starts_with('#') {
            return &text[offset..];
        }
        offset += line.len();
    }
    ""
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fig(stage: &str, instructions: u64, bytes: u64, frames: u64) -> StageFigure {
        StageFigure {
            stage: stage.to_owned(),
            instructions,
            bytes,
            frames,
        }
    }

    #[test]
    fn parses_stage_lines() {
        assert_eq!(
            StageFigure::parse("bench stage=decode_all instructions=42 bytes=61 frames=1"),
            Some(fig("decode_all", 42, 61, 1))
        );
        assert_eq!(
            StageFigure::parse("bench lbc_decode format=0x0fdf9f1f frames=300 bytes=18300"),
            None
        );
        assert_eq!(
            StageFigure::parse("bench stage=x instructions=many bytes=1 frames=1"),
            None
        );
        assert_eq!(StageFigure::parse("tick 1 mtime=10"), None);
    }

    #[test]
    fn table_reports_goal_and_checks_calibration() {
        let good = [
            fig("loop1000", 2001, 0, 0),
            fig("loop2000", 4001, 0, 0),
            fig("decode_all", 610, 61, 1),
        ];
        let md = fw_decode_table(&good).unwrap();
        assert!(md.contains("**10.00 instructions per byte**"), "{md}");
        assert!(md.contains("goal <= 25: met"), "{md}");

        let slow = [
            fig("loop1000", 2001, 0, 0),
            fig("loop2000", 4001, 0, 0),
            fig("decode_all", 6100, 61, 1),
        ];
        assert!(fw_decode_table(&slow).unwrap().contains("**missed**"));

        let inexact = [
            fig("loop1000", 2500, 0, 0),
            fig("loop2000", 4300, 0, 0),
            fig("decode_all", 610, 61, 1),
        ];
        let err = fw_decode_table(&inexact).unwrap_err().to_string();
        assert!(err.contains("not an exact instruction count"), "{err}");
    }

    #[test]
    fn markdown_starts_at_first_table_or_heading() {
        assert_eq!(markdown_part("noise\n| a |\n|---|\n"), "| a |\n|---|\n");
        assert_eq!(markdown_part("x\n## H\ny\n"), "## H\ny\n");
        assert_eq!(markdown_part("no table\n"), "");
    }
}
