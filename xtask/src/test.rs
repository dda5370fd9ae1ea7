//! `cargo xtask test`: every check the project has, in the order that fails fastest.
//!
//! Stages: formatting, clippy (host and firmware), the firmware build, host tests (which include
//! the QEMU end-to-end tests, given the firmware ELF through `UBC_FW_ELF`), and short fuzz runs
//! when a nightly toolchain is installed.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use crate::{fw, install, stage, workspace_root};

#[derive(Debug, clap::Args)]
pub struct TestArgs {
    /// Skip the firmware build and the QEMU end-to-end tests.
    #[arg(long)]
    no_qemu: bool,
    /// Skip rustfmt and clippy.
    #[arg(long)]
    no_lint: bool,
    /// Seconds each fuzz target runs for (0 skips fuzzing).
    #[arg(long, default_value_t = 20)]
    fuzz_seconds: u32,
}

/// Outcome of one stage.
struct StageResult {
    name: &'static str,
    ok: bool,
    seconds: f64,
    note: String,
}

pub fn run(args: TestArgs) -> Result<()> {
    // The soft core's Verilog is compiled by `verilator-tb`'s build script, which every
    // workspace build (clippy and tests) runs.
    install::ensure_verilator()?;
    // The report test opens a run's report.html in headless Chromium; without it that test
    // says it was skipped.
    if let Err(e) = install::ensure_debian_packages(&["chromium"]) {
        eprintln!("xtask: warning: {e:#}\nxtask: the report's browser test will be skipped");
    }
    // The bitstream tests (fpga/tests) run yosys, nextpnr-ice40 and icepack; they are
    // skipped, with a message, where these cannot be installed.
    if let Err(e) = install::ensure_fpga_tools() {
        eprintln!("xtask: the FPGA bitstream tests will be skipped: {e:#}");
    }
    // The sweep test on Slurm (almc/tests/sweep_slurm.rs) starts a one-node cluster; it is
    // skipped, with a message, where these cannot be installed.
    if let Err(e) = install::ensure_debian_packages(&["slurm-wlm", "munge"]) {
        eprintln!("xtask: the Slurm sweep test will be skipped: {e:#}");
    }
    let mut results: Vec<StageResult> = Vec::new();
    let mut totals = TestCounts::default();

    let mut record = |name: &'static str, f: &mut dyn FnMut() -> Result<String>| {
        stage(name);
        let start = Instant::now();
        let outcome = f();
        let seconds = start.elapsed().as_secs_f64();
        let (ok, note) = match outcome {
            Ok(note) => (true, note),
            Err(err) => {
                eprintln!("xtask: stage `{name}` failed: {err:#}");
                (false, format!("{err:#}"))
            }
        };
        results.push(StageResult {
            name,
            ok,
            seconds,
            note,
        });
        ok
    };

    if !args.no_lint {
        record("rustfmt", &mut || {
            cargo(&["fmt", "--all", "--", "--check"])?;
            cargo(&[
                "fmt",
                "--manifest-path",
                "ubc-app/Cargo.toml",
                "--",
                "--check",
            ])?;
            Ok(String::new())
        });
        record("clippy (host)", &mut || {
            cargo(&[
                "clippy",
                "--workspace",
                "--all-targets",
                "--",
                "-D",
                "warnings",
            ])?;
            Ok(String::new())
        });
    }

    let mut elfs = None;
    if !args.no_qemu {
        record("firmware build (qemu_virt)", &mut || {
            install::ensure_qemu()?;
            let program = fw::build("qemu_virt", true)?;
            let echo = fw::build_features("qemu_virt", fw::BIN, &["echo-test"], true)?;
            let softcore = fw::build("softcore", true)?;
            let note = format!("{} (+ echo-test, softcore)", program.display());
            elfs = Some((program, echo, softcore));
            Ok(note)
        });
        if !args.no_lint {
            record("clippy (firmware)", &mut || {
                let mut notes = Vec::new();
                for board in fw::BOARDS {
                    notes.push(fw::clippy(board)?);
                }
                Ok(notes.join("; "))
            });
        }
    }

    record("host and QEMU tests", &mut || {
        let mut cmd = Command::new(cargo_bin());
        // The whole workspace, including the soft core's test bench (not a default member).
        // Every test binary runs even when one fails, so the summary counts them all.
        cmd.args(["test", "--workspace", "--no-fail-fast"]);
        match (&elfs, args.no_qemu) {
            (Some((program, echo, softcore)), _) => {
                cmd.env("UBC_FW_ELF", program)
                    .env("UBC_FW_ECHO_ELF", echo)
                    .env("VTB_FIRMWARE", softcore);
            }
            (None, true) => {
                cmd.env("UBC_SKIP_QEMU", "1");
            }
            (None, false) => bail!("the firmware did not build, so the QEMU tests cannot run"),
        }
        tally(run_counting(&mut cmd)?, &mut totals)
    });

    record("firmware logic tests (host)", &mut || {
        let mut cmd = Command::new(cargo_bin());
        cmd.args([
            "test",
            "--manifest-path",
            "ubc-app/Cargo.toml",
            "--lib",
            "--tests",
            "--target-dir",
            "ubc-app/target/host",
        ]);
        tally(run_counting(&mut cmd)?, &mut totals)
    });

    if args.fuzz_seconds > 0 {
        record("fuzz smoke runs", &mut || fuzz_smoke(args.fuzz_seconds));
    }

    println!("\n==> summary");
    for r in &results {
        println!(
            "  {:<28} {:>4}  {:>7.1}s  {}",
            r.name,
            if r.ok { "ok" } else { "FAIL" },
            r.seconds,
            r.note
        );
    }
    let failed: Vec<&str> = results.iter().filter(|r| !r.ok).map(|r| r.name).collect();
    println!("tests: {} passed, {} failed", totals.passed, totals.failed);
    if !totals.failures.is_empty() {
        println!("\n==> failed tests");
        for f in &totals.failures {
            println!("  {}", f.name);
            for line in &f.excerpt {
                println!("      {line}");
            }
        }
    }
    if !failed.is_empty() {
        bail!("failed stages: {}", failed.join(", "));
    }
    Ok(())
}

fn cargo_bin() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string())
}

/// Runs cargo in the workspace root, failing on a non-zero exit.
pub fn cargo(args: &[&str]) -> Result<()> {
    let status = Command::new(cargo_bin())
        .args(args)
        .current_dir(workspace_root())
        .status()
        .with_context(|| format!("running cargo {}", args.join(" ")))?;
    if !status.success() {
        bail!("cargo {} failed ({status})", args.join(" "));
    }
    Ok(())
}

#[derive(Debug, Default)]
struct TestCounts {
    passed: u64,
    failed: u64,
    ignored: u64,
    /// Each failed test's name and the first lines of what it printed, so the summary at the
    /// end of a long log says what failed without scrolling back.
    failures: Vec<Failure>,
}

#[derive(Debug)]
struct Failure {
    name: String,
    excerpt: Vec<String>,
}

/// Lines of a failed test's output that the summary repeats.
const EXCERPT_LINES: usize = 8;

impl TestCounts {
    fn add(&mut self, other: TestCounts) {
        self.passed += other.passed;
        self.failed += other.failed;
        self.ignored += other.ignored;
        self.failures.extend(other.failures);
    }

    /// Reads libtest's `test result: ok. 12 passed; 0 failed; 1 ignored; ...` line.
    fn parse_line(line: &str) -> Option<TestCounts> {
        let rest = line.trim().strip_prefix("test result: ")?;
        let mut counts = TestCounts::default();
        for part in rest.split(';') {
            let mut words = part.split_whitespace().rev();
            let label = words.next()?;
            let number = words.next().and_then(|n| n.parse::<u64>().ok());
            match (label, number) {
                ("passed", Some(n)) => counts.passed = n,
                ("failed", Some(n)) => counts.failed = n,
                ("ignored", Some(n)) => counts.ignored = n,
                _ => {}
            }
        }
        Some(counts)
    }
}

/// Collects libtest's `---- NAME stdout ----` sections (printed for each failed test).
#[derive(Default)]
struct FailureReader {
    current: Option<Failure>,
    done: Vec<Failure>,
}

impl FailureReader {
    fn line(&mut self, line: &str) {
        if let Some(name) = line
            .strip_prefix("---- ")
            .and_then(|rest| rest.strip_suffix(" stdout ----"))
        {
            self.finish();
            self.current = Some(Failure {
                name: name.to_string(),
                excerpt: Vec::new(),
            });
            return;
        }
        // A section ends at libtest's `failures:` list or the next section.
        if line == "failures:" || line.starts_with("test result: ") {
            self.finish();
            return;
        }
        if let Some(f) = &mut self.current {
            if f.excerpt.len() < EXCERPT_LINES && !line.trim().is_empty() {
                f.excerpt.push(line.to_string());
            }
        }
    }

    fn finish(&mut self) {
        if let Some(f) = self.current.take() {
            self.done.push(f);
        }
    }
}

/// Runs a `cargo test` command, passing its output through and adding up its result lines.
fn run_counting(cmd: &mut Command) -> Result<(TestCounts, std::process::ExitStatus)> {
    cmd.current_dir(workspace_root()).stdout(Stdio::piped());
    let mut child = cmd.spawn().context("starting cargo test")?;
    let stdout = child.stdout.take().context("cargo test stdout")?;
    let mut counts = TestCounts::default();
    let mut failures = FailureReader::default();
    for line in BufReader::new(stdout).lines() {
        let line = line.context("reading cargo test output")?;
        println!("{line}");
        failures.line(&line);
        if let Some(c) = TestCounts::parse_line(&line) {
            counts.add(c);
        }
    }
    failures.finish();
    counts.failures = failures.done;
    let status = child.wait().context("waiting for cargo test")?;
    Ok((counts, status))
}

/// Adds a `cargo test` run's counts and failures to `totals` (a failed run's too, so that the
/// summary names its failed tests), then fails if the run did.
fn tally(run: (TestCounts, std::process::ExitStatus), totals: &mut TestCounts) -> Result<String> {
    let (counts, status) = run;
    let note = format!(
        "{} passed, {} failed, {} ignored",
        counts.passed, counts.failed, counts.ignored
    );
    let failed = counts.failed;
    totals.add(counts);
    if !status.success() {
        bail!("cargo test failed ({status}): {failed} failed");
    }
    Ok(note)
}

/// Runs each fuzz target for a few seconds with cargo-fuzz on the nightly toolchain.
fn fuzz_smoke(seconds: u32) -> Result<String> {
    let nightly = Command::new("rustup")
        .args(["run", "nightly", "rustc", "--version"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !nightly {
        println!("no nightly toolchain installed: fuzz smoke runs skipped");
        return Ok("skipped: no nightly toolchain".into());
    }
    let have_fuzz = Command::new(cargo_bin())
        .args(["fuzz", "--version"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !have_fuzz {
        println!("installing cargo-fuzz");
        cargo(&["install", "--locked", "cargo-fuzz"])?;
    }
    let targets = fuzz_targets()?;
    // The fuzzed crates forbid `unsafe`, so AddressSanitizer would find nothing that a panic
    // does not show; without it the targets build and run several times faster. One build
    // of every target first: cargo then compiles the shared dependencies in parallel.
    let status = Command::new("cargo")
        .args(["+nightly", "fuzz", "build", "--sanitizer", "none"])
        .current_dir(workspace_root())
        .env_remove("RUSTC")
        .env_remove("RUSTDOC")
        .env_remove("CARGO")
        .env_remove("RUSTUP_TOOLCHAIN")
        .status()
        .context("building the fuzz targets")?;
    if !status.success() {
        bail!("building the fuzz targets failed ({status})");
    }
    for target in &targets {
        let max_time = format!("-max_total_time={seconds}");
        let status = Command::new("cargo")
            .args([
                "+nightly",
                "fuzz",
                "run",
                "--sanitizer",
                "none",
                target,
                "--",
                &max_time,
                "-max_len=512",
            ])
            .current_dir(workspace_root())
            .env_remove("RUSTC")
            .env_remove("RUSTDOC")
            .env_remove("CARGO")
            .env_remove("RUSTUP_TOOLCHAIN")
            .status()
            .with_context(|| format!("running fuzz target {target}"))?;
        if !status.success() {
            bail!("fuzz target {target} failed ({status}); see fuzz/artifacts/{target}");
        }
    }
    Ok(format!("{} targets x {seconds}s", targets.len()))
}

fn fuzz_targets() -> Result<Vec<String>> {
    let dir = workspace_root().join("fuzz/fuzz_targets");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let p = e.path();
            (p.extension()? == "rs").then(|| p.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    names.sort();
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::{FailureReader, TestCounts};

    #[test]
    fn collects_failed_tests_with_their_message() {
        let log = "running 2 tests\ntest a ... ok\ntest b::c ... FAILED\n\nfailures:\n\n\
                   ---- b::c stdout ----\n\nthread 'b::c' panicked at src/x.rs:3:5:\nboom\n\n\
                   failures:\n    b::c\n\ntest result: FAILED. 1 passed; 1 failed; 0 ignored\n";
        let mut r = FailureReader::default();
        for line in log.lines() {
            r.line(line);
        }
        r.finish();
        assert_eq!(r.done.len(), 1);
        assert_eq!(r.done[0].name, "b::c");
        assert_eq!(
            r.done[0].excerpt,
            ["thread 'b::c' panicked at src/x.rs:3:5:", "boom"]
        );
    }

    #[test]
    fn parses_libtest_result_line() {
        let c = TestCounts::parse_line(
            "test result: ok. 12 passed; 3 failed; 1 ignored; 0 measured; 0 filtered out; finished in 0.01s",
        )
        .unwrap();
        assert_eq!((c.passed, c.failed, c.ignored), (12, 3, 1));
        assert!(TestCounts::parse_line("running 3 tests").is_none());
    }
}
