//! `almc sweep run|check|merge|slurm`: parameter studies over an experiment (see
//! `docs/sweeps.md`). `run` plays every point of a sweep file with every seed on all cores,
//! with a progress bar, and writes `runs.csv`, `aggregate.csv` and plots; `--shard I/N` runs one
//! share of the runs, `merge` joins shares, `slurm` writes a job-array submission script.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use clap::{Args, Subcommand};

/// `println!` that ignores a closed standard output (`almc sweep run ... | head`).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

/// `eprintln!` that ignores a closed standard error.
macro_rules! esay {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}
use indicatif::{ProgressBar, ProgressStyle};
use sweep::{Event, Options, Outputs, RunState, Shard, Sweep};

/// `almc sweep ...`
#[derive(Debug, Subcommand)]
pub enum SweepCommand {
    /// Run a sweep: every point with every seed, on every core. Runs an earlier run of the same
    /// sweep into the same directory finished are kept. Exit code 0: every run complete; 2:
    /// some run failed; 130: stopped by Ctrl-C (run the same command again to go on); 1: error.
    Run(RunArgs),
    /// Check a sweep file (every point is applied to the base experiment and checked) and
    /// list its points.
    Check {
        /// The sweep (TOML).
        file: PathBuf,
    },
    /// Join the output directories of a sweep's shares and write its outputs over all runs.
    /// Exit code 0: every run complete; 2: some run failed or is in no share; 1: error.
    Merge(MergeArgs),
    /// Write a Slurm script that submits the sweep as a job array of N shares and a merge job.
    Slurm(SlurmArgs),
}

/// `almc sweep run`
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The sweep (TOML).
    file: PathBuf,
    /// Output directory (default: the file's `out`, else `sweep-out/<name>`; with `--shard
    /// I/N`, its `shards/I`).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Runs at the same time (default: every core).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=1024))]
    workers: Option<u16>,
    /// Run only share I of N: the runs k with k mod N = I, in plan order.
    #[arg(long, value_name = "I/N")]
    shard: Option<String>,
    /// Firmware ELF (default: `VTB_FIRMWARE`, else `cargo xtask fw --board softcore`).
    #[arg(long, value_name = "ELF")]
    firmware: Option<PathBuf>,
}

/// `almc sweep merge`
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The shares' output directories.
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Where the merged runs and outputs go (default: the first directory).
    #[arg(long, value_name = "DIR")]
    into: Option<PathBuf>,
}

/// `almc sweep slurm`
#[derive(Debug, Args)]
pub struct SlurmArgs {
    /// The sweep (TOML).
    file: PathBuf,
    /// Number of shares, one array task each.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=10000))]
    shards: u16,
    /// Merged output directory (default as for `run`); shares go to its `shards/I`.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Where to write the script (default: `OUT/slurm.sh`).
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// CPUs per array task (its workers).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=1024))]
    cpus_per_task: u16,
    /// Time limit of each array task (`sbatch --time`).
    #[arg(long)]
    time: Option<String>,
    /// Another `sbatch` option for both jobs, e.g. `--sbatch-arg=--partition=short`.
    #[arg(long = "sbatch-arg", value_name = "OPTION", allow_hyphen_values = true)]
    sbatch_args: Vec<String>,
    /// Firmware ELF (default: `VTB_FIRMWARE`, else `cargo xtask fw --board softcore`).
    #[arg(long, value_name = "ELF")]
    firmware: Option<PathBuf>,
}

pub fn run(cmd: SweepCommand) -> ExitCode {
    let result = match cmd {
        SweepCommand::Run(args) => run_cmd(&args),
        SweepCommand::Check { file } => check_cmd(&file),
        SweepCommand::Merge(args) => merge_cmd(&args),
        SweepCommand::Slurm(args) => slurm_cmd(&args),
    };
    result.unwrap_or_else(|e| {
        esay!("error: {e:#}");
        ExitCode::FAILURE
    })
}

fn load(file: &Path) -> anyhow::Result<Sweep> {
    Sweep::load(file).map_err(|e| anyhow::anyhow!("{}: {e}", file.display()))
}

fn firmware(given: &Option<PathBuf>, sweep: &Sweep) -> anyhow::Result<PathBuf> {
    if let Some(p) = given {
        return Ok(std::path::absolute(p)?);
    }
    let exp = arena::experiment::Experiment::parse(&sweep.experiment_text(0))?;
    let elf = exp
        .engine
        .default_firmware()
        .map_err(|e| anyhow::anyhow!("no firmware: {e}"))?;
    Ok(std::path::absolute(elf)?)
}

fn check_cmd(file: &Path) -> anyhow::Result<ExitCode> {
    let s = load(file)?;
    let p = &s.plan;
    say!(
        "{}: {} points x {} seeds = {} runs of {}; metrics {}; plots against {}: ok",
        p.name,
        p.points.len(),
        p.seeds.len(),
        p.len(),
        s.base.display(),
        p.metrics.join(", "),
        p.plot_x
    );
    for i in 0..p.points.len() {
        let values: Vec<String> = p
            .parameters
            .iter()
            .zip(p.point_labels(i))
            .map(|(n, v)| format!("{n} = {v}"))
            .collect();
        say!("  point {i}: {}", values.join(", "));
    }
    Ok(ExitCode::SUCCESS)
}

fn run_cmd(args: &RunArgs) -> anyhow::Result<ExitCode> {
    let sweep = load(&args.file)?;
    let shard = match &args.shard {
        Some(s) => Shard::parse(s)?,
        None => Shard::ALL,
    };
    let out = match (&args.out, args.shard.is_some()) {
        (Some(o), _) => o.clone(),
        (None, true) => sweep.out.join("shards").join(shard.index.to_string()),
        (None, false) => sweep.out.clone(),
    };
    let workers = args.workers.map(usize::from).unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let opts = Options {
        workers,
        shard,
        firmware: firmware(&args.firmware, &sweep)?,
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let c = cancel.clone();
    if let Err(e) = ctrlc::set_handler(move || {
        if c.swap(true, Ordering::Relaxed) {
            std::process::exit(130);
        }
    }) {
        esay!("warning: Ctrl-C will not stop the sweep cleanly: {e}");
    }
    let mut progress = Progress::new();
    let started = std::time::Instant::now();
    let report = sweep::run_sweep(&sweep, &out, &opts, &mut |ev| progress.event(ev), &cancel);
    let wall = started.elapsed().as_secs_f64();
    progress.finish();
    let report = report?;
    say!(
        "sweep {}{}: {} runs: {} complete, {} failed, {} still to do ({} kept from an earlier run, {} run now){}",
        sweep.plan.name,
        if shard == Shard::ALL {
            String::new()
        } else {
            format!(" share {}/{}", shard.index, shard.count)
        },
        report.scope,
        report.complete(),
        report.failed(),
        report.unfinished(),
        report.skipped,
        report.ran,
        if report.ran > 0 {
            format!(
                "; {:.1} s on {} workers, {:.0} runs per hour",
                wall,
                opts.workers.min(report.ran + report.interrupted),
                report.ran as f64 * 3600.0 / wall.max(1e-9)
            )
        } else {
            String::new()
        },
    );
    print_outputs(&sweep.plan, &report.outputs);
    if report.stopped {
        say!(
            "stopped{}: run the same command again to do the rest",
            match report.interrupted {
                0 => String::new(),
                n => format!(" ({n} runs cut short, to be done again)"),
            }
        );
        return Ok(ExitCode::from(130));
    }
    Ok(if report.failed() + report.unfinished() == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    })
}

fn merge_cmd(args: &MergeArgs) -> anyhow::Result<ExitCode> {
    let into = args.into.clone().unwrap_or_else(|| args.dirs[0].clone());
    let report = sweep::merge(&args.dirs, &into)?;
    let o = &report.outputs;
    let plan = sweep::Plan::read(&into)?;
    say!(
        "merged {} shares into {}: {} runs: {} complete, {} failed, {} missing ({} copied)",
        args.dirs.len(),
        into.display(),
        o.rows.len(),
        o.count(RunState::is_complete),
        o.count(|s| !s.is_complete()) - report.missing.len(),
        report.missing.len(),
        report.copied
    );
    if !report.missing.is_empty() {
        say!("  missing: {}", report.missing.join(" "));
    }
    print_outputs(&plan, o);
    Ok(if o.count(|s| !s.is_complete()) == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    })
}

fn slurm_cmd(args: &SlurmArgs) -> anyhow::Result<ExitCode> {
    let sweep = load(&args.file)?;
    let out = std::path::absolute(args.out.clone().unwrap_or_else(|| sweep.out.clone()))?;
    let cfg = sweep::slurm::SlurmConfig {
        almc: std::env::current_exe()?,
        sweep_file: std::path::absolute(&args.file)?,
        name: sweep.plan.name.clone(),
        out: out.clone(),
        shards: usize::from(args.shards),
        firmware: firmware(&args.firmware, &sweep)?,
        cpus_per_task: usize::from(args.cpus_per_task),
        time: args.time.clone(),
        sbatch_args: args.sbatch_args.clone(),
    };
    let script = args.script.clone().unwrap_or_else(|| out.join("slurm.sh"));
    if let Some(dir) = script.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(&script, sweep::slurm::script(&cfg))?;
    say!(
        "{}: {} runs in {} shares; submit with: bash {}",
        script.display(),
        sweep.plan.len(),
        args.shards,
        script.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// The output paths and, per point, the chosen metrics' means with their 95 % intervals.
fn print_outputs(plan: &sweep::Plan, o: &Outputs) {
    for p in 0..plan.points.len() {
        let values: Vec<String> = plan
            .parameters
            .iter()
            .zip(plan.point_labels(p))
            .map(|(n, v)| format!("{n} = {v}"))
            .collect();
        let stats: Vec<String> = plan
            .metrics
            .iter()
            .map(|m| {
                let s = &sweep::stats::per_point(plan, &o.rows, m)[p];
                let mean = s.mean.map_or("-".into(), sweep::stats::num);
                let ci = s
                    .ci95
                    .map_or(String::new(), |h| format!(" ± {}", sweep::stats::num(h)));
                format!("{m} {mean}{ci}")
            })
            .collect();
        say!("  point {p} ({}): {}", values.join(", "), stats.join(", "));
    }
    say!("  runs: {}", o.runs_csv.display());
    say!("  aggregate: {}", o.aggregate_csv.display());
    if let Some(first) = o.plots.first().and_then(|p| p.parent()) {
        say!("  plots: {}", first.display());
    }
}

/// The progress bar (on a terminal) or one line per run (in a log).
struct Progress {
    bar: Option<ProgressBar>,
    failed: usize,
    done: usize,
    total: usize,
}

impl Progress {
    fn new() -> Self {
        Progress {
            bar: None,
            failed: 0,
            done: 0,
            total: 0,
        }
    }

    fn event(&mut self, ev: Event<'_>) {
        match ev {
            Event::Planned {
                scope,
                skipped,
                workers,
            } => {
                self.total = scope - skipped;
                esay!(
                    "{scope} runs, {skipped} kept from an earlier run, {} to do on {workers} workers",
                    self.total
                );
                if std::io::stderr().is_terminal() && self.total > 0 {
                    let bar = ProgressBar::new(self.total as u64);
                    let style = ProgressStyle::with_template(
                        "{bar:40.cyan/blue} {pos}/{len} runs, {msg} [{elapsed_precise}, {eta_precise} left]",
                    )
                    .map(|s| s.progress_chars("=> "))
                    .unwrap_or_else(|_| ProgressStyle::default_bar());
                    bar.set_style(style);
                    bar.set_message("0 failed");
                    self.bar = Some(bar);
                }
            }
            Event::Started(_) => {}
            Event::Finished { run, state, wall } => {
                self.done += 1;
                if !state.is_complete() && *state != RunState::Interrupted {
                    self.failed += 1;
                }
                let line = format!(
                    "run {} (point {}, seed {}): {}{} in {:.1} s",
                    run.index,
                    run.point,
                    run.seed,
                    state.name(),
                    match state {
                        RunState::Error(e) => format!(" ({e})"),
                        _ => String::new(),
                    },
                    wall.as_secs_f64()
                );
                match &self.bar {
                    Some(bar) => {
                        if !state.is_complete() {
                            bar.println(line);
                        }
                        bar.set_message(format!("{} failed", self.failed));
                        bar.inc(1);
                    }
                    None => esay!("[{}/{}] {line}", self.done, self.total),
                }
            }
        }
    }

    fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
