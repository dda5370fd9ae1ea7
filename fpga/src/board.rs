//! The boards and what is built for them.

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

/// The SoC clock the firmware is written for (115200 baud is divisor 8).
pub const SOC_CLOCK_NOMINAL_MHZ: f64 = 14.7456;
/// The SoC clock the boards make from their 12 MHz oscillators: the PLL's VCO at 12 MHz x 79
/// = 948 MHz, divided by 32 (29.625 MHz) and halved by its second output.
pub const SOC_CLOCK_MHZ: f64 = 12.0 * 79.0 / 64.0;

/// An FPGA board the SoC is built for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Board {
    /// iCEBreaker: iCE40 UltraPlus UP5K in the SG48 package (SPRAM, DSP blocks).
    Up5k,
    /// The iCE40-HX8K breakout board: HX8K in the CT256 package (no SPRAM, no DSP blocks).
    Hx8k,
}

/// What is placed and routed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Design {
    /// The whole SoC with its board glue (`fpga_soc.v` in the board's top).
    Soc,
    /// The core alone, its buses ending in flip-flops (`core_top.v`).
    Core,
    /// The vision unit alone, its bus and camera port driven from flip-flops (`vision_top.v`),
    /// with the run buffers of the board's SoC.
    Vision,
    /// A timing probe: one pipeline stage of a planned core alone between flip-flops
    /// (`fpga/probe/`, docs/fpga.md), fed by an LFSR.
    Probe(Stage),
    /// Another core, as published, in a generated wrapper that feeds its inputs from an LFSR
    /// and takes its outputs into a signature register on two pins (`fpga::reference`): what
    /// the same flow makes of the cores our goals were set against. Its Verilog is the
    /// caller's.
    Reference,
}

/// The pipeline stages the timing probes hold (`verilator-tb/fpga/probe/<stage>_stage.v`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Next fetch address from the fetched word's length, a branch target buffer and a
    /// registered redirect, into the memories' address pins.
    Fetch,
    /// Compressed expansion, register-file read, forwarding decisions and the class flags.
    Decode,
    /// Forwarded operands, adder, comparisons, logic unit, shifter, result selection.
    Execute,
}

impl Stage {
    /// Every probe, in pipeline order.
    pub const ALL: [Stage; 3] = [Stage::Fetch, Stage::Decode, Stage::Execute];

    /// The name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Fetch => "fetch",
            Stage::Decode => "decode",
            Stage::Execute => "execute",
        }
    }

    /// The probe's top module (and, with `.v`, its file in `fpga/probe/`).
    pub fn top(self) -> &'static str {
        match self {
            Stage::Fetch => "fetch_stage",
            Stage::Decode => "decode_stage",
            Stage::Execute => "execute_stage",
        }
    }
}

impl std::str::FromStr for Stage {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Stage::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown stage `{s}` (expected fetch, decode or execute)"))
    }
}

impl Board {
    /// Every board, in report order.
    pub const ALL: [Board; 2] = [Board::Up5k, Board::Hx8k];

    /// The name used on the command line and in file names.
    pub fn name(self) -> &'static str {
        match self {
            Board::Up5k => "up5k",
            Board::Hx8k => "hx8k",
        }
    }

    /// The board's name for people.
    pub fn title(self) -> &'static str {
        match self {
            Board::Up5k => "iCEBreaker (iCE40UP5K-SG48)",
            Board::Hx8k => "iCE40-HX8K breakout (iCE40HX8K-CT256)",
        }
    }

    /// Device and package arguments of `nextpnr-ice40`.
    pub fn nextpnr_device(self) -> [&'static str; 3] {
        match self {
            Board::Up5k => ["--up5k", "--package", "sg48"],
            Board::Hx8k => ["--hx8k", "--package", "ct256"],
        }
    }

    /// The clock the SoC is to reach on this board (the FPGA goals: 24 MHz on the UP5K, 60 on
    /// the HX8K); a timing probe is held to it.
    pub fn fmax_goal_mhz(self) -> f64 {
        match self {
            Board::Up5k => 24.0,
            Board::Hx8k => 60.0,
        }
    }

    /// Whether the multiplier goes into DSP blocks (`synth_ice40 -dsp`).
    pub fn has_dsp(self) -> bool {
        matches!(self, Board::Up5k)
    }

    /// `MUL_SEQ` of the board's core: without DSP blocks it multiplies in its divider's loop
    /// (34 cycles a product) rather than on a 32x32 multiplier of about 2 800 LUT4.
    pub fn mul_seq(self) -> u32 {
        u32::from(!self.has_dsp())
    }

    /// `PIPE` of the board's SoC: the pipelined core (`rv_pipe`) where it fits (the HX8K; the
    /// UP5K's SoC is 124 % of the part with it).
    pub fn pipe(self) -> u32 {
        u32::from(matches!(self, Board::Hx8k))
    }

    /// Bytes of program RAM in the board's SoC.
    pub fn ram_bytes(self) -> u32 {
        4 << self.ram_aw()
    }

    /// RAM word-address bits (`RAM_AW` of `fpga_soc`).
    pub fn ram_aw(self) -> u32 {
        match self {
            Board::Up5k => 14,
            Board::Hx8k => 10,
        }
    }

    /// Bytes of the frame-grabber window on the board (`FMEM_AW` of its top: on the HX8K two
    /// block RAMs, so that the SoC with its vision unit fits the part's 32).
    pub fn frame_window_bytes(self) -> u32 {
        4 << self.frame_window_aw()
    }

    /// Frame-window word-address bits (`FMEM_AW` of `fpga_soc`).
    pub fn frame_window_aw(self) -> u32 {
        match self {
            Board::Up5k => 9,
            Board::Hx8k => 8,
        }
    }

    /// Word-address bits of each of the vision unit's run buffers (`VIS_CAP_AW` of the board's
    /// top): what block RAM is left after the program RAM, the frame window and the register
    /// file.
    pub fn vision_cap_aw(self) -> u32 {
        match self {
            Board::Up5k => 9,
            Board::Hx8k => 8,
        }
    }

    fn top(self, design: Design) -> &'static str {
        match (self, design) {
            (Board::Up5k, Design::Soc) => "top_icebreaker",
            (Board::Hx8k, Design::Soc) => "top_hx8k",
            (_, Design::Core) => "core_top",
            (_, Design::Vision) => "vision_top",
            (_, Design::Probe(stage)) => stage.top(),
            (_, Design::Reference) => crate::reference::WRAPPER_TOP,
        }
    }

    fn pcf(self, design: Design) -> &'static str {
        match (self, design) {
            (Board::Up5k, Design::Soc) => "icebreaker.pcf",
            (Board::Hx8k, Design::Soc) => "hx8k.pcf",
            // the unit alone, the probes and other cores have the core alone's pins
            (Board::Up5k, _) => "core_up5k.pcf",
            (Board::Hx8k, _) => "core_hx8k.pcf",
        }
    }
}

impl fmt::Display for Board {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A board name that is not one of [`Board::ALL`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown board `{0}` (expected up5k or hx8k)")]
pub struct UnknownBoard(pub String);

impl FromStr for Board {
    type Err = UnknownBoard;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Board::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| UnknownBoard(s.to_owned()))
    }
}

impl Design {
    /// The name used in file names and reports.
    pub fn name(self) -> &'static str {
        match self {
            Design::Soc => "soc",
            Design::Core => "core",
            Design::Vision => "vision",
            Design::Probe(Stage::Fetch) => "probe-fetch",
            Design::Probe(Stage::Decode) => "probe-decode",
            Design::Probe(Stage::Execute) => "probe-execute",
            Design::Reference => "reference",
        }
    }
}

/// One build: a design on a board, its placer seed, and the clock it is timed at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Target {
    /// The board.
    pub board: Board,
    /// The SoC, or the core alone.
    pub design: Design,
    /// nextpnr's seed (fixed, so runs are reproducible).
    pub seed: u64,
    /// The SoC clock is [`SOC_CLOCK_MHZ`] / 2^`clock_div_log2` (0 in every figure; more for
    /// bring-up at a clock the design meets). The core alone ignores it.
    pub clock_div_log2: u32,
    /// The SoC with its vision unit (the SoC only; off by default: the UP5K SoC with it does
    /// not fit, docs/fpga.md).
    pub vision_unit: bool,
}

impl Target {
    /// The SoC at the SoC clock with seed 1.
    pub fn soc(board: Board) -> Self {
        Target {
            board,
            design: Design::Soc,
            seed: 1,
            clock_div_log2: 0,
            vision_unit: false,
        }
    }

    /// The core alone with seed 1.
    pub fn core(board: Board) -> Self {
        Target {
            design: Design::Core,
            ..Target::soc(board)
        }
    }

    /// The vision unit alone with seed 1.
    pub fn vision(board: Board) -> Self {
        Target {
            design: Design::Vision,
            ..Target::soc(board)
        }
    }

    /// The clock the design is held to, in MHz (nextpnr weighs every design's paths against
    /// the SoC clock; a probe is then held to the board's goal).
    pub fn clock_mhz(&self) -> f64 {
        match self.design {
            Design::Soc => SOC_CLOCK_MHZ / f64::from(1u32 << self.clock_div_log2.min(16)),
            Design::Core | Design::Vision => SOC_CLOCK_MHZ,
            // a stage of the planned core must leave the SoC its goal; another core is held
            // to the goal too
            Design::Probe(_) | Design::Reference => self.board.fmax_goal_mhz(),
        }
    }

    /// A directory name for this build's outputs.
    pub fn dir_name(&self) -> String {
        let div = match (self.design, self.clock_div_log2) {
            (Design::Soc, n) if n > 0 => format!("-div{}", 1u32 << n.min(16)),
            _ => String::new(),
        };
        let vision = if self.design == Design::Soc && self.vision_unit {
            "-vision"
        } else {
            ""
        };
        format!(
            "{}-{}{}{}-seed{}",
            self.board.name(),
            self.design.name(),
            vision,
            div,
            self.seed
        )
    }

    /// The top module.
    pub fn top(&self) -> &'static str {
        self.board.top(self.design)
    }

    /// The pin constraints file.
    pub fn pcf(&self, sources: &Sources) -> PathBuf {
        sources.fpga.join(self.board.pcf(self.design))
    }

    /// The Verilog files of the design, in reading order.
    pub fn verilog(&self, sources: &Sources) -> Vec<PathBuf> {
        let rtl = |f: &str| sources.rtl.join(f);
        let fpga = |f: &str| sources.fpga.join(f);
        match self.design {
            Design::Core => vec![
                rtl("rv_expand.v"),
                rtl("rv_core.v"),
                rtl("rv_pipe.v"),
                fpga("core_top.v"),
            ],
            Design::Vision => vec![rtl("vision_unit.v"), fpga("vision_top.v")],
            // the caller's files and the wrapper generated for them (`fpga::reference`)
            Design::Reference => Vec::new(),
            // (the decode stage expands with the cores' own module)
            Design::Probe(stage) => vec![
                rtl("rv_expand.v"),
                fpga(&format!("probe/{}.v", stage.top())),
            ],
            Design::Soc => {
                let ram = match self.board {
                    Board::Up5k => fpga("soc_ram_spram.v"),
                    Board::Hx8k => rtl("soc_ram.v"),
                };
                let mut files = vec![
                    rtl("soc.v"),
                    ram,
                    rtl("rv_expand.v"),
                    rtl("rv_core.v"),
                    rtl("rv_pipe.v"),
                    rtl("uart16550.v"),
                    rtl("clint.v"),
                    rtl("plic.v"),
                    rtl("vision_unit.v"),
                ];
                for f in [
                    "fpga_soc.v",
                    "spi_flash_loader.v",
                    "uart_rx_line.v",
                    "frame_capture.v",
                ] {
                    files.push(fpga(f));
                }
                files.push(fpga(&format!("{}.v", self.top())));
                files
            }
        }
    }
}

/// Where the Verilog lives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Sources {
    /// The SoC and core (`verilator-tb/rtl`).
    pub rtl: PathBuf,
    /// Board tops, FPGA-only modules and pin files (`verilator-tb/fpga`).
    pub fpga: PathBuf,
}

impl Sources {
    /// The directories of this checkout.
    pub fn in_workspace() -> Self {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let tb = root.join("verilator-tb");
        Sources {
            rtl: tb.join("rtl"),
            fpga: tb.join("fpga"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value a board top gives parameter `name` of `fpga_soc`, or `fpga_soc`'s default.
    fn soc_parameter(top: &str, soc: &str, name: &str) -> u32 {
        let given = format!(".{name}(");
        if let Some(at) = top.find(&given) {
            let rest = &top[at + given.len()..];
            let value = &rest[..rest.find(')').expect("a closing parenthesis")];
            return value
                .trim()
                .parse()
                .unwrap_or_else(|_| panic!("{name} = {value}"));
        }
        let default = format!("parameter integer {name} = ");
        let at = soc
            .find(&default)
            .unwrap_or_else(|| panic!("no {name} in fpga_soc.v"));
        let rest = &soc[at + default.len()..];
        let end = rest
            .find(|c: char| !c.is_ascii_digit())
            .unwrap_or(rest.len());
        rest[..end].parse().expect("a decimal default")
    }

    /// What the flow and the board simulation assume of each board (`Board`'s figures) is what
    /// the board's top gives its SoC.
    #[test]
    fn board_figures_match_the_board_tops() {
        let s = Sources::in_workspace();
        let soc = std::fs::read_to_string(s.fpga.join("fpga_soc.v")).expect("fpga_soc.v");
        for b in Board::ALL {
            let file = s.fpga.join(format!("{}.v", b.top(Design::Soc)));
            let top = std::fs::read_to_string(&file).expect("the board top");
            let p = |name| soc_parameter(&top, &soc, name);
            assert_eq!(p("RAM_AW"), b.ram_aw(), "{b}: RAM_AW");
            assert_eq!(p("FMEM_AW"), b.frame_window_aw(), "{b}: FMEM_AW");
            assert_eq!(p("VIS_CAP_AW"), b.vision_cap_aw(), "{b}: VIS_CAP_AW");
            assert_eq!(p("MUL_SEQ"), b.mul_seq(), "{b}: MUL_SEQ");
            assert_eq!(p("PIPE"), b.pipe(), "{b}: PIPE");
        }
    }

    #[test]
    fn board_names_round_trip_and_bad_names_are_refused() {
        for b in Board::ALL {
            assert_eq!(b.name().parse::<Board>(), Ok(b));
        }
        assert_eq!(
            "ecp5".parse::<Board>(),
            Err(UnknownBoard("ecp5".to_owned()))
        );
    }

    #[test]
    fn clock_is_the_pll_rate_divided() {
        let mut t = Target::soc(Board::Up5k);
        assert!((t.clock_mhz() - 14.8125).abs() < 1e-9);
        t.clock_div_log2 = 2;
        assert!((t.clock_mhz() - 3.703125).abs() < 1e-9);
        assert_eq!(t.dir_name(), "up5k-soc-div4-seed1");
        assert_eq!(Target::core(Board::Hx8k).dir_name(), "hx8k-core-seed1");
        let probe = Target {
            design: Design::Probe(Stage::Decode),
            ..Target::core(Board::Up5k)
        };
        assert!((probe.clock_mhz() - 24.0).abs() < 1e-9);
        assert_eq!(probe.dir_name(), "up5k-probe-decode-seed1");
        let v = Target {
            vision_unit: true,
            ..Target::soc(Board::Up5k)
        };
        assert_eq!(v.dir_name(), "up5k-soc-vision-seed1");
        // 0.45 % above the nominal clock
        let err = SOC_CLOCK_MHZ / SOC_CLOCK_NOMINAL_MHZ - 1.0;
        assert!((err - 0.004527).abs() < 1e-5, "{err}");
    }

    #[test]
    fn every_source_file_exists() {
        let s = Sources::in_workspace();
        for b in Board::ALL {
            for t in [Target::soc(b), Target::core(b), Target::vision(b)] {
                for f in t.verilog(&s).iter().chain([t.pcf(&s)].iter()) {
                    assert!(f.is_file(), "{} is missing", f.display());
                }
            }
        }
    }
}
