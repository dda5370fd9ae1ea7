//! `cargo xtask bench`: runs the project's benchmarks and prints their figures as markdown,
//! each with the command that reproduces it.
//!
//! - `size`: text/data/bss of the softcore release firmware against the size goals, and where
//!   the text goes by crate and symbol group (`size.rs`).
//! - `fw-decode`: RV32 instructions per received byte for deframing and decoding a full
//!   STREAM, counted with `minstret` by the `bench_lbc_decode` firmware binary under
//!   `qemu-system-riscv32 -icount shift=0`.
//! - `host-decode`: `cargo bench -p lbc-link --bench decode`.
//! - `radio`: `cargo bench -p arena --bench radio`.
//! - `softcore`: the soft core (verilator-tb): CPI on the firmware, simulation speed, and area
//!   from yosys `synth_ice40 -dsp`.
//! - `fw-vision`: RV32 instructions per pixel of the vision pipeline on a rendered 640x480
//!   frame, counted by the `bench_vision` firmware binary reading the frame in place from its
//!   frame-grabber window (QEMU shared RAM written by the host, `-icount shift=0`).
//!
//! - `arena`: world seconds per wall second of N cars on the soft core's model in virtual time,
//!   each car's state broadcasts delivered against the radio model's figure, and QEMU cars in
//!   real time (`arena/tests/arena_bench.rs`).
//! - `sweep`: runs per hour of `almc sweep run` (release, every core) on the four-car
//!   formation sweep `experiments/sweeps/formation-wedge-loss.toml`, from scratch.
//! - `fpga`, `lockstep`: the soft core on the iCE40 boards, and 10^8 instructions checked
//!   against the golden model (`bench_fpga`).
//! - `vision-unit`: the SoC's vision unit against the firmware's own pixel pipeline (cycles
//!   per frame, frames per second and processor share at 14.7456 MHz, on the soft core's
//!   model), and the unit's LUT4 and Fmax (`bench_vision`).
//!
//! `--only NAME` runs one of them; `--out FILE` also writes the markdown to a file.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use qemu_harness::{Qemu, UartAttach};

use crate::{fw, stage, workspace_root};

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
    /// Instructions per pixel of the vision pipeline on the firmware (QEMU).
    FwVision,
    /// The arena: virtual-time speed, state delivery against the radio model, QEMU cars.
    Arena,
    /// Soft core: CPI on the firmware, simulation speed, LUT4 from yosys.
    Softcore,
    /// Parameter sweeps: runs per hour of a four-car formation sweep.
    Sweep,
    /// The SoC and the core on the iCE40 boards: utilization and Fmax.
    Fpga,
    /// The planned core's pipeline stages alone on the iCE40 boards (timing probes).
    Probes,
    /// The published cores the FPGA goals were set against, through the same flow (their
    /// netlists downloaded into target/fpga/anchors; rows say how when they are not there).
    Anchors,
    /// The vision unit against the firmware's pixel pipeline: cycles per frame, frames per
    /// second and processor share at 14.7456 MHz; the unit's LUT4 and Fmax.
    VisionUnit,
    /// At least 10^8 instructions in lockstep with the golden model.
    Lockstep,
}

impl Bench {
    const ALL: [Bench; 14] = [
        Bench::Size,
        Bench::FwDecode,
        Bench::HostDecode,
        Bench::Radio,
        Bench::Camera,
        Bench::FwVision,
        Bench::Arena,
        Bench::Softcore,
        Bench::Sweep,
        Bench::Fpga,
        Bench::Probes,
        Bench::Anchors,
        Bench::VisionUnit,
        Bench::Lockstep,
    ];

    fn title(self) -> &'static str {
        match self {
            Bench::Size => "firmware size",
            Bench::FwDecode => "lbc-link on the firmware (instructions per byte)",
            Bench::HostDecode => "lbc-link host decode throughput",
            Bench::Radio => "radio",
            Bench::Camera => "synthetic camera",
            Bench::FwVision => "vision on the firmware (instructions per pixel)",
            Bench::Arena => "the arena: virtual-time speed, state delivery, QEMU cars",
            Bench::Softcore => "soft core",
            Bench::Sweep => "sweeps",
            Bench::Fpga => "the soft core on iCE40 FPGAs",
            Bench::Probes => "the planned core's stages on iCE40 FPGAs",
            Bench::Anchors => "the anchors through this flow",
            Bench::VisionUnit => "the vision unit",
            Bench::Lockstep => "lockstep with the golden model",
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
            Bench::Size => crate::size::bench(),
            Bench::FwDecode => fw_decode(),
            Bench::HostDecode => cargo_bench("lbc-link", "decode", "lbc-link host decode"),
            Bench::Radio => cargo_bench("arena", "radio", "Radio"),
            Bench::Camera => cargo_bench("arena", "camera", "Synthetic camera"),
            Bench::FwVision => fw_vision(),
            Bench::Arena => arena(),
            Bench::Softcore => softcore(),
            Bench::Sweep => sweep(),
            Bench::Fpga => crate::bench_fpga::fpga(),
            Bench::Probes => crate::bench_fpga::probes(),
            Bench::Anchors => crate::bench_fpga::anchors(),
            Bench::VisionUnit => crate::bench_vision::vision_unit(),
            Bench::Lockstep => crate::bench_fpga::lockstep(),
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

pub(crate) fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "**missed**"
    }
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
         on RV32IMAC under `qemu-system-riscv32 -icount shift=0` (release build, opt-level \"s\").\n",
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

/// Goal for the on-target vision pipeline.
const INSTRUCTIONS_PER_PIXEL_GOAL: f64 = 4.0;
/// The on-target vision benchmark program (a binary of `ubc-app`).
const FW_VISION_BIN: &str = "bench_vision";
/// The stage whose figure is held against the goal.
const VISION_HEADLINE_STAGE: &str = "process_frame";

/// What each stage of the vision benchmark measures.
fn vision_stage_meaning(stage: &str) -> &'static str {
    match stage {
        "runs" => "row scan only: classification into runs (count = runs)",
        "process_frame" => "`vision::process_frame`: classification, runs, components, blob list",
        "process_frame_rows2" => "the same with `row_step = 2` (every other row)",
        "observe" => "`CameraModel::observe`: bearing and range of one blob (fixed point)",
        other => stage_meaning(other),
    }
}

/// Builds `bench_vision`, then runs the ignored arena test that renders the benchmark scene into
/// a RAM file and boots the program on it in QEMU; turns its `bench stage=` lines into a table.
fn fw_vision() -> Result<String> {
    crate::install::ensure_qemu()?;
    let elf = fw::build_bin("qemu_virt", FW_VISION_BIN, true)?;
    let text = ignored_test(
        "arena",
        "camera_fw_bench",
        &[("UBC_BENCH_VISION_ELF", elf.as_os_str())],
    )?;
    for line in text.lines().filter(|l| l.starts_with("fw: ")) {
        eprintln!("{line}");
    }
    // The test prints the firmware's log lines, each prefixed with `fw: `.
    let figures: Vec<StageFigure> = text
        .lines()
        .filter_map(|l| l.strip_prefix("fw: ").and_then(StageFigure::parse))
        .collect();
    let text_size = fw::sizes(&elf)?.text;
    fw_vision_table(&figures, text_size)
}

fn fw_vision_table(figures: &[StageFigure], text_size: u64) -> Result<String> {
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
    let Some(headline) = find(VISION_HEADLINE_STAGE) else {
        bail!("the benchmark log has no `{VISION_HEADLINE_STAGE}` line");
    };
    let per_pixel = headline.per_byte().unwrap_or(f64::INFINITY);
    let mut md = String::from(
        "## Vision on the firmware: instructions per pixel

",
    );
    let _ = writeln!(
        md,
        "A rendered 640x480 RGB332 view with four cars in sight (`arena::camera_feed::bench_scene`), \
         published by the host into the frame-grabber window (QEMU RAM shared file) and read in \
         place by `bench_vision` through the board's frame grabber; `minstret` on RV32IMAC under \
         `qemu-system-riscv32 -icount shift=0`, release build (opt-level \"s\"). The firmware's \
         blobs equal the host pipeline's exactly (checked by the run).\n"
    );
    let _ = writeln!(
        md,
        "| stage | what | instructions | pixels | count | instructions/pixel |"
    );
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|");
    for f in figures {
        let per = f
            .per_byte()
            .map_or_else(|| "-".to_owned(), |v| format!("{v:.2}"));
        let _ = writeln!(
            md,
            "| {} | {} | {} | {} | {} | {} |",
            f.stage,
            vision_stage_meaning(&f.stage),
            f.instructions,
            f.bytes,
            f.frames,
            per
        );
    }
    let _ = writeln!(
        md,
        "\n**{per_pixel:.2} instructions per pixel** for `{VISION_HEADLINE_STAGE}` (goal <= {:.0}: {}).\n",
        INSTRUCTIONS_PER_PIXEL_GOAL,
        verdict(per_pixel <= INSTRUCTIONS_PER_PIXEL_GOAL)
    );
    let _ = writeln!(
        md,
        "`bench_vision` image: text {text_size} bytes ({}).\n\nReproduce: `cargo xtask bench --only fw-vision`.",
        kib(text_size)
    );
    Ok(md)
}

/// Car counts of the virtual-time speed benchmark.
const ARENA_SPEED_CARS: &str = "4,16,64,100";
/// Car counts of the state-delivery comparison with the radio model.
const ARENA_DELIVERY_CARS: &str = "4,12,16";
/// Car counts of the QEMU real-time capacity benchmark.
const ARENA_QEMU_CARS: &str = "1,4,8,16";
/// Goals: world seconds per wall second at 16 and at 100 cars; state delivery within this
/// many points of the radio model, and at least this much at 12 cars.
const SPEED_GOAL_16: f64 = 10.0;
const SPEED_GOAL_100: f64 = 1.0;
const DELIVERY_POINTS: f64 = 0.5;
const DELIVERY_GOAL_12: f64 = 0.99;

/// The arena: virtual-time speed at 4..100 cars (formation, soft-core model), each car's state
/// broadcasts delivered against the radio model's figure, and QEMU cars in real time.
fn arena() -> Result<String> {
    let softcore = crate::fw::build("softcore", true)?;
    let qemu = crate::fw::build("qemu_virt", true)?;
    let env = |k: &'static str, v: &'static str| (k, std::ffi::OsStr::new(v));
    let speed = ignored_test_named(
        "arena",
        "arena_bench",
        "virtual_time_speed",
        &[
            env("ARENA_BENCH_N", ARENA_SPEED_CARS),
            ("VTB_FIRMWARE", softcore.as_os_str()),
        ],
    )?;
    let delivery = ignored_test_named(
        "arena",
        "arena_bench",
        "state_delivery",
        &[
            env("ARENA_DELIVERY_N", ARENA_DELIVERY_CARS),
            ("VTB_FIRMWARE", softcore.as_os_str()),
        ],
    )?;
    let realtime = ignored_test_named(
        "arena",
        "arena_bench",
        "qemu_realtime_capacity",
        &[
            env("ARENA_QEMU_N", ARENA_QEMU_CARS),
            ("UBC_FW_ELF", qemu.as_os_str()),
        ],
    )?;
    let table = |text: &str| -> String {
        text.lines()
            .filter(|l| l.starts_with('|'))
            .map(|l| format!("{l}\n"))
            .collect()
    };
    let mut md =
        String::from("## The arena\n\n### Virtual time: world seconds per wall second\n\n");
    md.push_str(&table(&speed));
    let all = |mode: &str| -> Vec<BTreeMap<String, String>> {
        speed
            .lines()
            .chain(delivery.lines())
            .filter_map(|l| l.trim().strip_prefix("figures:"))
            .map(|rest| {
                rest.split_whitespace()
                    .filter_map(|kv| kv.split_once('='))
                    .map(|(k, v)| (k.to_owned(), v.to_owned()))
                    .collect::<BTreeMap<_, _>>()
            })
            .filter(|f| f.get("mode").is_some_and(|m| m == mode))
            .collect()
    };
    for (cars, goal) in [("16", SPEED_GOAL_16), ("100", SPEED_GOAL_100)] {
        if let Some(f) = all("speed")
            .iter()
            .find(|f| f.get("cars").is_some_and(|c| c == cars))
        {
            let v = field(f, "speed")?;
            let _ = writeln!(
                md,
                "\n{cars} cars: {v:.2} world s per wall s (goal >= {goal}): {}",
                verdict(v >= goal)
            );
        }
    }
    md.push_str("\n### State broadcasts delivered, arena against the radio model\n\n");
    md.push_str(&table(&delivery));
    for f in all("delivery") {
        let (cars, arena, model) = (field(&f, "cars")?, field(&f, "arena")?, field(&f, "model")?);
        let close = (arena - model).abs() * 100.0 <= DELIVERY_POINTS;
        let lowest = field(&f, "lowest").unwrap_or(arena);
        let _ = write!(
            md,
            "\n{cars:.0} cars: {:.2} % against {:.2} % (mean over the seeds; lowest seed {:.2} %): {}",
            100.0 * arena,
            100.0 * model,
            100.0 * lowest,
            verdict(close)
        );
        if cars == 12.0 {
            let _ = write!(
                md,
                "; at least 99 %: {}",
                verdict(arena >= DELIVERY_GOAL_12)
            );
        }
        md.push('\n');
    }
    md.push_str("\n### QEMU cars in real time\n\n");
    md.push_str(&table(&realtime));
    let _ = write!(
        md,
        "\nReproduce: `cargo xtask bench --only arena`, or `ARENA_BENCH_N={ARENA_SPEED_CARS} cargo test -p arena --release \
         --test arena_bench virtual_time_speed -- --ignored --nocapture` (likewise `state_delivery` with \
         `ARENA_DELIVERY_N`, `qemu_realtime_capacity` with `ARENA_QEMU_N`)."
    );
    Ok(md)
}

/// Firmware cycles the soft-core benchmark co-simulates (about 4 s of SoC time).
const SOFTCORE_CYCLES: &str = "60000000";
/// Goals of the soft core (issue: CPI, simulation speed, area).
const SOFTCORE_CPI_GOAL: f64 = 1.6;
const SOFTCORE_SPEED_GOAL: f64 = 2.0e6;
const SOFTCORE_LUT_GOAL: u64 = 2000;

/// `key=value` fields of the last line starting with `figures:` whose `mode` is `mode`.
pub(crate) fn figures(text: &str, mode: &str) -> Option<BTreeMap<String, String>> {
    text.lines()
        .filter_map(|l| l.trim().strip_prefix("figures:"))
        .map(|rest| {
            rest.split_whitespace()
                .filter_map(|kv| kv.split_once('='))
                .map(|(k, v)| (k.to_owned(), v.to_owned()))
                .collect::<BTreeMap<_, _>>()
        })
        .rfind(|f| f.get("mode").is_some_and(|m| m == mode))
}

pub(crate) fn field(f: &BTreeMap<String, String>, key: &str) -> Result<f64> {
    f.get(key)
        .and_then(|v| v.parse().ok())
        .with_context(|| format!("no numeric `{key}` in the figures"))
}

/// Runs `cmd` and returns its stdout; a failure status is an error unless `any_status` (a
/// firmware that runs until the cycle limit ends `vtb-run` with status 3).
/// Runs the ignored tests of one test target in release mode (how the host-driven benchmarks
/// are packaged) and returns their standard output.
fn ignored_test(package: &str, test: &str, env: &[(&str, &std::ffi::OsStr)]) -> Result<String> {
    ignored_test_named(package, test, "", env)
}

/// Like [`ignored_test`], only the test named `name` (all of them when `name` is empty).
pub(crate) fn ignored_test_named(
    package: &str,
    test: &str,
    name: &str,
    env: &[(&str, &std::ffi::OsStr)],
) -> Result<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let mut cmd = Command::new(cargo);
    cmd.args([
        "test",
        "-p",
        package,
        "--release",
        "--test",
        test,
        "--",
        name,
        "--ignored",
        "--nocapture",
    ]);
    if !name.is_empty() {
        // the test of that name only, not every test whose name contains it
        cmd.arg("--exact");
    }
    for (k, v) in env {
        cmd.env(k, v);
    }
    run_captured(
        &mut cmd,
        &format!("the {test} benchmark of {package}"),
        false,
    )
}

fn run_captured(cmd: &mut Command, what: &str, any_status: bool) -> Result<String> {
    let out = cmd
        .current_dir(workspace_root())
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .with_context(|| format!("running {what}"))?;
    if !out.status.success() && !any_status {
        bail!("{what} failed ({})", out.status);
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The yosys script of the area figure, run in `verilator-tb/`.
const SOFTCORE_AREA_SCRIPT: &str =
    "read_verilog rtl/rv_expand.v rtl/rv_core.v rtl/synth_top.v; synth_ice40 -dsp -top synth_top; stat";

/// Cell counts of `yosys ... synth_ice40 -dsp; stat` on the core (`rtl/synth_top.v`).
fn softcore_area() -> Result<BTreeMap<String, u64>> {
    crate::install::ensure_fpga_tools()?;
    let out = Command::new("yosys")
        .args(["-p", SOFTCORE_AREA_SCRIPT])
        .current_dir(workspace_root().join("verilator-tb"))
        .stdin(Stdio::null())
        .stderr(Stdio::inherit())
        .output()
        .context("running yosys (Debian package `yosys`)")?;
    if !out.status.success() {
        bail!("yosys failed ({})", out.status);
    }
    let text = String::from_utf8_lossy(&out.stdout);
    // the last `stat` block is the flattened top
    let mut cells = BTreeMap::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        if let (Some(name), Some(count), None) = (words.next(), words.next(), words.next()) {
            if name.starts_with("SB_") {
                if let Ok(n) = count.parse() {
                    cells.insert(name.to_owned(), n);
                }
            }
        }
    }
    if !cells.contains_key("SB_LUT4") {
        bail!("yosys printed no SB_LUT4 count");
    }
    Ok(cells)
}

/// The soft core: the `softcore` firmware co-simulated with `lbc-emu` (CPI while awake,
/// cycles/s), a busy loop free-running and in lockstep (cycles/s), and the core's area.
fn softcore() -> Result<String> {
    let elf = crate::fw::build("softcore", true)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let run_args = [
        "run",
        "-q",
        "-p",
        "verilator-tb",
        "--release",
        "--bin",
        "vtb-run",
        "--",
    ];
    let text = run_captured(
        Command::new(&cargo).args(run_args).arg(&elf).args([
            "--lbc-emu",
            "3",
            "--max-cycles",
            SOFTCORE_CYCLES,
        ]),
        "vtb-run (firmware co-simulation)",
        true,
    )?;
    let fw = figures(&text, "cosim").context("vtb-run printed no figures")?;
    let (cycles, insns, awake, wall) = (
        field(&fw, "cycles")?,
        field(&fw, "instructions")?,
        field(&fw, "awake")?,
        field(&fw, "wall_s")?,
    );
    let cpi = awake / insns.max(1.0);
    let fw_speed = cycles / wall.max(1e-9);

    // `busy_speed` is the one ignored test of `soc`
    let text = ignored_test("verilator-tb", "soc", &[])?;
    let busy = figures(&text, "busy").context("busy_speed printed no figures")?;
    let busy_speed = field(&busy, "cycles")? / field(&busy, "wall_s")?.max(1e-9);
    let ls = figures(&text, "busy-lockstep").context("busy_speed printed no lockstep figures")?;
    let ls_speed = field(&ls, "cycles")? / field(&ls, "wall_s")?.max(1e-9);

    let area = softcore_area()?;
    let cell = |name: &str| area.get(name).copied().unwrap_or(0);
    let luts = cell("SB_LUT4");
    let ffs: u64 = area
        .iter()
        .filter(|(k, _)| k.starts_with("SB_DFF"))
        .map(|(_, v)| v)
        .sum();

    let mut md = String::from(
        "## Soft core (verilator-tb)\n\n| figure | value | goal | verdict |\n|---|---|---|---|\n",
    );
    let _ = writeln!(
        md,
        "| CPI while awake, firmware + lbc-emu ({SOFTCORE_CYCLES} cycles) | {cpi:.3} ({insns:.0} instructions in {awake:.0} awake cycles) | <= {SOFTCORE_CPI_GOAL} | {} |",
        verdict(cpi <= SOFTCORE_CPI_GOAL)
    );
    let _ = writeln!(
        md,
        "| simulation speed, firmware + lbc-emu co-simulation | {:.2} M cycles/s | >= {:.0} M | {} |",
        fw_speed / 1e6,
        SOFTCORE_SPEED_GOAL / 1e6,
        verdict(fw_speed >= SOFTCORE_SPEED_GOAL)
    );
    let _ = writeln!(
        md,
        "| simulation speed, busy core, free-running | {:.2} M cycles/s | >= {:.0} M | {} |",
        busy_speed / 1e6,
        SOFTCORE_SPEED_GOAL / 1e6,
        verdict(busy_speed >= SOFTCORE_SPEED_GOAL)
    );
    let _ = writeln!(
        md,
        "| simulation speed, busy core, lockstep with the golden model | {:.2} M cycles/s | | |",
        ls_speed / 1e6
    );
    let _ = writeln!(
        md,
        "| area, core (`synth_ice40 -dsp`) | {luts} SB_LUT4, {} SB_CARRY, {ffs} flip-flops, {} SB_RAM40_4K, {} SB_MAC16 | <= {SOFTCORE_LUT_GOAL} LUT4 | {} |",
        cell("SB_CARRY"),
        cell("SB_RAM40_4K"),
        cell("SB_MAC16"),
        verdict(luts <= SOFTCORE_LUT_GOAL)
    );
    let _ = write!(
        md,
        "\nReproduce: `cargo xtask bench --only softcore` (firmware: `cargo {} ELF --lbc-emu 3 --max-cycles {SOFTCORE_CYCLES}`; busy core: `cargo test -p verilator-tb --release --test soc -- --ignored --nocapture busy_speed`; area: `cd verilator-tb && yosys -p \"{SOFTCORE_AREA_SCRIPT}\"`). Speeds depend on the machine's load.",
        run_args.join(" "),
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

/// The sweep the `sweep` benchmark runs.
const SWEEP_BENCH_FILE: &str = "experiments/sweeps/formation-wedge-loss.toml";

/// Runs the four-car formation sweep from scratch with `almc sweep run` (release build, one
/// worker per core) and reports its runs per hour, from the sweep's own summary line and the
/// runs' `run.json` (wall and world time of each).
fn sweep() -> Result<String> {
    let elf = crate::fw::build("softcore", true)?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    run_captured(
        Command::new(&cargo).args(["build", "-q", "--release", "-p", "almc"]),
        "cargo build --release -p almc",
        false,
    )?;
    let out = std::env::temp_dir().join(format!("almc-bench-sweep-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let text = run_captured(
        Command::new(&cargo)
            .args(["run", "-q", "--release", "-p", "almc", "--", "sweep", "run"])
            .arg(SWEEP_BENCH_FILE)
            .arg("--out")
            .arg(&out)
            .arg("--firmware")
            .arg(&elf),
        "almc sweep run",
        true,
    );
    let runs: Vec<serde_json::Value> = std::fs::read_dir(out.join("runs"))
        .map(|rd| {
            rd.filter_map(|e| e.ok())
                .filter_map(|e| std::fs::read_to_string(e.path().join("run.json")).ok())
                .filter_map(|t| serde_json::from_str(&t).ok())
                .collect()
        })
        .unwrap_or_default();
    let _ = std::fs::remove_dir_all(&out);
    let text = text?;
    let line = text
        .lines()
        .find(|l| l.starts_with("sweep ") && l.contains("runs per hour"))
        .context("almc sweep run printed no summary line")?;
    // "sweep NAME: N runs: C complete, F failed, ...; W s on K workers, R runs per hour"
    let number_before = |word: &str| -> Result<f64> {
        let at = line
            .find(word)
            .with_context(|| format!("no `{word}` in `{line}`"))?;
        line[..at]
            .split_whitespace()
            .last()
            .and_then(|n| n.trim_start_matches('(').parse().ok())
            .with_context(|| format!("no number before `{word}` in `{line}`"))
    };
    let total = number_before(" runs:")?;
    let complete = number_before(" complete")?;
    let wall = number_before(" s on ")?;
    let workers = number_before(" workers")?;
    let per_hour = number_before(" runs per hour")?;
    let sum = |k: &str| -> f64 { runs.iter().filter_map(|r| r[k].as_f64()).sum() };
    let (run_wall, run_world) = (sum("wall_s"), sum("world_s"));
    let n = runs.len().max(1) as f64;
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    let mut md = String::from("## Sweeps\n\n");
    let _ = writeln!(
        md,
        "`{SWEEP_BENCH_FILE}`: the four-car wedge of `formation-wedge-four.toml`, 5 radio losses \
         x 2 slot spacings x 4 seeds, every run from scratch (release build, {cores} cores).\n"
    );
    let _ = writeln!(
        md,
        "| runs | complete | workers | wall time | runs per hour | mean run: wall | mean run: world time | world s per wall s per worker |"
    );
    let _ = writeln!(md, "|---:|---:|---:|---:|---:|---:|---:|---:|");
    let _ = writeln!(
        md,
        "| {total:.0} | {complete:.0} | {workers:.0} | {wall:.0} s | **{per_hour:.0}** | {:.1} s | {:.1} s | {:.2} |",
        run_wall / n,
        run_world / n,
        run_world / run_wall.max(1e-9),
    );
    let _ = write!(
        md,
        "\nReproduce: `cargo run --release -p almc -- sweep run {SWEEP_BENCH_FILE} --out DIR` \
         (a new DIR: finished runs are kept) or `cargo xtask bench --only sweep`."
    );
    Ok(md)
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
    fn vision_table_reports_instructions_per_pixel() {
        let figs = [
            fig("loop1000", 2001, 0, 0),
            fig("loop2000", 4001, 0, 0),
            fig("process_frame", 792_320, 307_200, 4),
            fig("observe", 16_248, 0, 1),
        ];
        let md = fw_vision_table(&figs, 40_000).unwrap();
        assert!(md.contains("**2.58 instructions per pixel**"), "{md}");
        assert!(md.contains("goal <= 4: met"), "{md}");
        assert!(md.contains("| observe |"), "{md}");
        let slow = [
            fig("loop1000", 2001, 0, 0),
            fig("loop2000", 4001, 0, 0),
            fig("process_frame", 1_600_000, 307_200, 4),
        ];
        assert!(fw_vision_table(&slow, 1).unwrap().contains("**missed**"));
        assert!(fw_vision_table(&slow[2..], 1).is_err());
    }

    #[test]
    fn markdown_starts_at_first_table_or_heading() {
        assert_eq!(markdown_part("noise\n| a |\n|---|\n"), "| a |\n|---|\n");
        assert_eq!(markdown_part("x\n## H\ny\n"), "## H\ny\n");
        assert_eq!(markdown_part("no table\n"), "");
    }
}
