//! Runs yosys, nextpnr-ice40 and icepack for one [`Target`].

use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::board::{Design, Sources, Target};
use crate::report::{self, Cells, Timing, Usage};

/// The programs the flow runs (Debian: `yosys`, `nextpnr-ice40`, `fpga-icestorm`).
pub const TOOLS: [&str; 3] = ["yosys", "nextpnr-ice40", "icepack"];

/// The Debian packages that provide [`TOOLS`].
pub const DEBIAN_PACKAGES: [&str; 3] = ["yosys", "nextpnr-ice40", "fpga-icestorm"];

/// How long one tool may run.
const TOOL_TIMEOUT: Duration = Duration::from_secs(30 * 60);

/// The tools of [`TOOLS`] that are not on `PATH`.
pub fn missing_tools() -> Vec<&'static str> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    TOOLS
        .into_iter()
        .filter(|t| !std::env::split_paths(&path).any(|d| d.join(t).is_file()))
        .collect()
}

/// Why a build could not be made.
#[derive(Debug, thiserror::Error)]
pub enum FlowError {
    /// A tool is not installed.
    #[error("`{0}` is not on PATH (Debian packages: yosys, nextpnr-ice40, fpga-icestorm)")]
    ToolMissing(&'static str),
    /// A tool failed; its log says why.
    #[error("{tool} failed ({status}); see {}", log.display())]
    Tool {
        /// The program.
        tool: &'static str,
        /// Its exit status, or "timed out".
        status: String,
        /// Its log.
        log: PathBuf,
    },
    /// Another core's Verilog cannot be wrapped (`crate::reference`).
    #[error("{0}")]
    Reference(String),
    /// Synthesis printed no cell counts.
    #[error("yosys printed no cell statistics; see {}", .0.display())]
    NoStat(PathBuf),
    /// Reading or writing the build's files.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The error.
        source: io::Error,
    },
}

pub(crate) fn io_err(what: impl Into<String>) -> impl FnOnce(io::Error) -> FlowError {
    let what = what.into();
    move |source| FlowError::Io { what, source }
}

/// A placed and routed design.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    /// nextpnr's utilization table.
    pub utilization: std::collections::BTreeMap<String, Usage>,
    /// nextpnr's timing.
    pub timing: Timing,
    /// The clock net the design is timed on.
    pub clock: String,
    /// The bitstream (icepack's output).
    pub bitstream: PathBuf,
}

/// What one build produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// What was built.
    pub target: Target,
    /// Its directory (scripts, logs, netlist, report, bitstream).
    pub dir: PathBuf,
    /// Cells after synthesis.
    pub cells: Cells,
    /// Logic cells after packing (also known when placement fails).
    pub logic_cells: Option<Usage>,
    /// The routed design, or `None` when placement or routing failed.
    pub placed: Option<Placed>,
    /// nextpnr's error when it failed (the design does not fit, most often).
    pub failure: Option<String>,
}

impl Outcome {
    /// The clock the design is held against, MHz.
    pub fn target_mhz(&self) -> f64 {
        self.target.clock_mhz()
    }

    /// The design's Fmax on its clock (nextpnr's, or lower through DSP blocks), MHz.
    pub fn fmax_mhz(&self) -> Option<f64> {
        let p = self.placed.as_ref()?;
        p.timing.fmax_of(&p.clock)
    }

    /// Placed, routed, and fast enough for its clock.
    pub fn timing_met(&self) -> bool {
        self.fmax_mhz().is_some_and(|f| f >= self.target_mhz())
    }
}

/// Synthesises, places, routes and packs `target`; outputs go to `out/<target dir>/`.
/// A design that does not fit or misses timing is an [`Outcome`], not an error: the caller
/// decides (see [`Outcome::timing_met`]).
pub fn build(target: &Target, sources: &Sources, out: &Path) -> Result<Outcome, FlowError> {
    build_in(
        target,
        &target.verilog(sources),
        &target.pcf(sources),
        out.join(target.dir_name()),
    )
}

/// [`build`] with the Verilog files and the pin file given, outputs in `dir`.
pub(crate) fn build_in(
    target: &Target,
    files: &[PathBuf],
    pcf_in: &Path,
    dir: PathBuf,
) -> Result<Outcome, FlowError> {
    if let Some(t) = missing_tools().first() {
        return Err(FlowError::ToolMissing(t));
    }
    fs::create_dir_all(&dir).map_err(io_err(format!("creating {}", dir.display())))?;

    // ------------------------------------------------------------------ yosys
    let json = dir.join("netlist.json");
    let mut script = String::from("read_verilog -defer");
    for f in files {
        script.push_str(&format!(" \"{}\"", f.display()));
    }
    script.push('\n');
    if target.design == Design::Soc {
        script.push_str(&format!(
            "chparam -set CLK_DIV_LOG2 {} {}\n",
            target.clock_div_log2,
            target.top()
        ));
        script.push_str(&format!(
            "chparam -set VISION {} {}\n",
            u8::from(target.vision_unit),
            target.top()
        ));
    }
    if target.design == Design::Core {
        // as the board's SoC has it: without DSP blocks the core multiplies in its divider
        script.push_str(&format!(
            "chparam -set MUL_SEQ {} {}\nchparam -set PIPE {} {}\n",
            target.board.mul_seq(),
            target.top(),
            target.board.pipe(),
            target.top()
        ));
    }
    if target.design == Design::Vision {
        script.push_str(&format!(
            "chparam -set CAP_AW {} {}\n",
            target.board.vision_cap_aw(),
            target.top()
        ));
    }
    script.push_str(&format!(
        "synth_ice40 {}-abc9 -top {} -json \"{}\"\n",
        if target.board.has_dsp() { "-dsp " } else { "" },
        target.top(),
        json.display()
    ));
    let ys = dir.join("synth.ys");
    fs::write(&ys, script).map_err(io_err(format!("writing {}", ys.display())))?;
    let ylog = dir.join("yosys.log");
    run_logged(
        "yosys",
        Command::new("yosys")
            .arg("-q")
            .arg("-l")
            .arg(&ylog)
            .arg("-s")
            .arg(&ys),
        &dir.join("yosys.out"),
    )?;
    let ytext = fs::read_to_string(&ylog).map_err(io_err(format!("reading {}", ylog.display())))?;
    let cells = Cells::from_yosys_log(&ytext).ok_or_else(|| FlowError::NoStat(ylog.clone()))?;

    // ------------------------------------------------------------------ nextpnr
    let pcf = dir.join("pins.pcf");
    let mut pins =
        fs::read_to_string(pcf_in).map_err(io_err(format!("reading {}", pcf_in.display())))?;
    if target.design == Design::Soc && target.clock_div_log2 > 0 {
        pins.push_str(&format!("set_frequency soc_clk {}\n", target.clock_mhz()));
    }
    fs::write(&pcf, pins).map_err(io_err(format!("writing {}", pcf.display())))?;
    let asc = dir.join("design.asc");
    let rep = dir.join("report.json");
    let nlog = dir.join("nextpnr.log");
    let _ = fs::remove_file(&rep);
    let _ = fs::remove_file(&asc);
    let mut pnr = Command::new("nextpnr-ice40");
    pnr.args(target.board.nextpnr_device())
        .arg("--json")
        .arg(&json)
        .arg("--pcf")
        .arg(&pcf)
        .arg("--freq")
        .arg(format!("{}", crate::board::SOC_CLOCK_MHZ))
        .arg("--seed")
        .arg(target.seed.to_string())
        .arg("--report")
        .arg(&rep)
        .arg("--asc")
        .arg(&asc)
        .arg("--timing-allow-fail")
        .arg("-q")
        .arg("-l")
        .arg(&nlog);
    let pnr_result = run_logged("nextpnr-ice40", &mut pnr, &dir.join("nextpnr.out"));
    let ntext = fs::read_to_string(&nlog).unwrap_or_default();
    let logic_cells = report::logic_cells_from_log(&ntext);
    if let Err(e) = pnr_result {
        let failure = ntext
            .lines()
            .rev()
            .find(|l| l.starts_with("ERROR"))
            .map(str::to_owned)
            .unwrap_or_else(|| e.to_string());
        return Ok(Outcome {
            target: *target,
            dir,
            cells,
            logic_cells,
            placed: None,
            failure: Some(failure),
        });
    }
    let report: serde_json::Value = fs::read_to_string(&rep)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let timing = Timing::from_report(&report);
    let clock = match target.design {
        Design::Soc => timing.find_clock(&["soc_clk", "clk_pll"]),
        Design::Core | Design::Vision | Design::Probe(_) | Design::Reference => {
            timing.find_clock(&["clk"])
        }
    }
    .unwrap_or("")
    .to_owned();

    // ------------------------------------------------------------------ icepack
    let bin = dir.join("design.bin");
    run_logged(
        "icepack",
        Command::new("icepack").arg(&asc).arg(&bin),
        &dir.join("icepack.log"),
    )?;
    Ok(Outcome {
        target: *target,
        dir,
        cells,
        logic_cells,
        placed: Some(Placed {
            utilization: report::utilization(&report),
            timing,
            clock,
            bitstream: bin,
        }),
        failure: None,
    })
}

/// Runs `cmd` with its output in `log`, within [`TOOL_TIMEOUT`].
pub(crate) fn run_logged(
    tool: &'static str,
    cmd: &mut Command,
    log: &Path,
) -> Result<(), FlowError> {
    let file = fs::File::create(log).map_err(io_err(format!("creating {}", log.display())))?;
    let err = file
        .try_clone()
        .map_err(io_err(format!("opening {}", log.display())))?;
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .spawn()
        .map_err(io_err(format!("starting {tool}")))?;
    let start = Instant::now();
    loop {
        match child
            .try_wait()
            .map_err(io_err(format!("waiting for {tool}")))?
        {
            Some(status) if status.success() => return Ok(()),
            Some(status) => {
                return Err(FlowError::Tool {
                    tool,
                    status: status.to_string(),
                    log: log.to_path_buf(),
                })
            }
            None if start.elapsed() > TOOL_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(FlowError::Tool {
                    tool,
                    status: "timed out".into(),
                    log: log.to_path_buf(),
                });
            }
            None => std::thread::sleep(Duration::from_millis(200)),
        }
    }
}
