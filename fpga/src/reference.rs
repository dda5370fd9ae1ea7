//! Another core through the same flow: a published core's Verilog (VexRiscv's generated
//! netlists, say) is placed and routed on a board exactly as our core alone is, so that its
//! figures and ours come from the same tools and options.
//!
//! The core's ports are read with yosys (`write_json` after `hierarchy` and `proc`), and a
//! wrapper is generated around it ([`wrapper`]): one clock, a registered reset, every other
//! input bit driven from its own register loaded with the XOR of three bits of a 32-bit LFSR,
//! every output registered and taken, four bits to a register, into a 32-bit signature
//! register (an LFSR with inputs) whose two bits are the pins, so nothing is constant and
//! nothing is removed. The wrapper has the core alone's pins (`core_up5k.pcf`,
//! `core_hx8k.pcf`), and the design is held to the board's Fmax goal, as the probes are.
//! Every path of the core from and to a register is timed as in the core's own system;
//! paths from an input straight to an output of the core (none in a registered core) end at
//! the wrapper's registers.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::board::{Board, Design, Sources, Target};
use crate::flow::{self, io_err, FlowError, Outcome};

/// The generated wrapper's module name.
pub const WRAPPER_TOP: &str = "ref_top";

/// A port of the wrapped core.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Port {
    /// Its name as the Verilog spells it.
    pub name: String,
    /// An input (else an output).
    pub input: bool,
    /// Its width in bits.
    pub width: usize,
}

/// What to wrap.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Reference {
    /// The core's Verilog files, in reading order.
    pub files: Vec<PathBuf>,
    /// Its top module.
    pub top: String,
    /// Its clock input; found by name when `None` ([`CLOCK_NAMES`]).
    pub clock: Option<String>,
    /// Its reset input, if it has one; found by name when `None` ([`RESET_NAMES`]). A name
    /// ending in `n` or `_b` is taken as active low.
    pub reset: Option<String>,
}

/// Clock port names tried in order when none is given.
pub const CLOCK_NAMES: [&str; 5] = ["clk", "clock", "io_clk", "io_mainClk", "CLK"];
/// Reset port names tried in order when none is given.
pub const RESET_NAMES: [&str; 6] = [
    "reset",
    "rst",
    "io_reset",
    "resetn",
    "rst_n",
    "io_asyncReset",
];

/// The ports of `top` from yosys's JSON netlist (`modules.<top>.ports`).
pub fn ports_from_json(json: &serde_json::Value, top: &str) -> Result<Vec<Port>, FlowError> {
    let ports = json
        .get("modules")
        .and_then(|m| m.get(top))
        .and_then(|m| m.get("ports"))
        .and_then(serde_json::Value::as_object)
        .ok_or_else(|| FlowError::Reference(format!("no module `{top}` in the Verilog")))?;
    let mut out = Vec::with_capacity(ports.len());
    for (name, p) in ports {
        let width = p
            .get("bits")
            .and_then(serde_json::Value::as_array)
            .map_or(0, Vec::len);
        let input = match p.get("direction").and_then(serde_json::Value::as_str) {
            Some("input") => true,
            Some("output") => false,
            other => {
                return Err(FlowError::Reference(format!(
                    "port `{name}` of `{top}` is {} (only inputs and outputs can be wrapped)",
                    other.unwrap_or("of no direction")
                )))
            }
        };
        if width == 0 {
            return Err(FlowError::Reference(format!(
                "port `{name}` of `{top}` has no bits"
            )));
        }
        out.push(Port {
            name: name.clone(),
            input,
            width,
        });
    }
    Ok(out)
}

/// Reads `top`'s ports with yosys (its log and JSON in `dir`).
pub fn ports(files: &[PathBuf], top: &str, dir: &Path) -> Result<Vec<Port>, FlowError> {
    if let Some(t) = flow::missing_tools().first() {
        return Err(FlowError::ToolMissing(t));
    }
    fs::create_dir_all(dir).map_err(io_err(format!("creating {}", dir.display())))?;
    let json = dir.join("ports.json");
    let mut script = String::from("read_verilog -defer");
    for f in files {
        let _ = write!(script, " \"{}\"", f.display());
    }
    let _ = write!(
        script,
        "\nhierarchy -top {top}\nproc\nwrite_json \"{}\"\n",
        json.display()
    );
    let ys = dir.join("ports.ys");
    fs::write(&ys, script).map_err(io_err(format!("writing {}", ys.display())))?;
    flow::run_logged(
        "yosys",
        Command::new("yosys").arg("-q").arg("-s").arg(&ys),
        &dir.join("ports.log"),
    )?;
    let text = fs::read_to_string(&json).map_err(io_err(format!("reading {}", json.display())))?;
    let value: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| FlowError::Reference(format!("{}: {e}", json.display())))?;
    ports_from_json(&value, top)
}

/// A port name as a Verilog identifier (escaped when it is not a simple one).
fn ident(name: &str) -> String {
    let simple = name
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '$');
    if simple {
        name.to_owned()
    } else {
        format!("\\{name} ")
    }
}

fn active_low(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n.ends_with('n') && (n.ends_with("_n") || n.ends_with("resetn") || n.ends_with("rstn"))
        || n.ends_with("_b")
}

fn find<'a>(ports: &'a [Port], given: Option<&str>, names: &[&str]) -> Option<&'a Port> {
    match given {
        Some(g) => ports.iter().find(|p| p.name == g),
        None => names
            .iter()
            .find_map(|n| ports.iter().find(|p| p.name == *n)),
    }
}

/// The clock and reset inputs the wrapper drives (see [`Reference`]).
fn pick<'a>(
    top: &str,
    ports: &'a [Port],
    clock: Option<&str>,
    reset: Option<&str>,
) -> Result<(&'a Port, Option<&'a Port>), FlowError> {
    let clk = find(ports, clock, &CLOCK_NAMES)
        .filter(|p| p.input && p.width == 1)
        .ok_or_else(|| {
            FlowError::Reference(format!(
                "`{top}` has no one-bit clock input {}",
                clock.map_or_else(
                    || format!("named one of {CLOCK_NAMES:?} (give its name)"),
                    |c| format!("`{c}`")
                )
            ))
        })?;
    let rst = match find(ports, reset, &RESET_NAMES) {
        Some(p) if p.input && p.width == 1 && p.name != clk.name => Some(p),
        Some(_) | None if reset.is_some() => {
            return Err(FlowError::Reference(format!(
                "`{top}` has no one-bit reset input `{}`",
                reset.unwrap_or_default()
            )))
        }
        _ => None,
    };
    Ok((clk, rst))
}

/// The wrapper's Verilog for `top` with `ports` (see the module's documentation).
pub fn wrapper(
    top: &str,
    ports: &[Port],
    clock: Option<&str>,
    reset: Option<&str>,
) -> Result<String, FlowError> {
    let (clk, rst) = pick(top, ports, clock, reset)?;
    Ok(wrapper_for(top, ports, clk, rst))
}

/// [`wrapper`] with the clock and reset already picked.
fn wrapper_for(top: &str, ports: &[Port], clk: &Port, rst: Option<&Port>) -> String {
    let mut v = String::new();
    let _ = writeln!(
        v,
        "// Generated by fpga::reference: `{top}` between flip-flops fed by an LFSR, its outputs\n\
         // taken into a signature register on two pins (the core alone's pins).\n\
         `default_nettype none\n\n\
         module {WRAPPER_TOP} (\n    input  wire clk,\n    input  wire rst_pin,\n    \
         input  wire seed,\n    output reg  out0,\n    output reg  out1\n);\n    \
         reg rst = 1'b1;\n    always @(posedge clk) rst <= rst_pin;\n    \
         reg [31:0] lfsr = 32'h1;\n    always @(posedge clk)\n        \
         lfsr <= {{lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed}};"
    );
    let mut conns = Vec::new();
    let mut outs = Vec::new();
    let mut next_bit = 0;
    for (i, p) in ports.iter().enumerate() {
        let id = ident(&p.name);
        if p.name == clk.name {
            conns.push(format!(".{id}(clk)"));
        } else if rst.is_some_and(|r| r.name == p.name) {
            let level = if active_low(&p.name) { "!rst" } else { "rst" };
            conns.push(format!(".{id}({level})"));
        } else if p.input {
            // each bit the XOR of its own three LFSR bits, so that no two input bits are the
            // same register (yosys merges equal flip-flops, and the core's logic would then
            // fold equal inputs together)
            let bits: Vec<String> = (0..p.width)
                .rev()
                .map(|b| {
                    let [x, y, z] = lfsr_triple(next_bit + b);
                    format!("lfsr[{x}] ^ lfsr[{y}] ^ lfsr[{z}]")
                })
                .collect();
            next_bit += p.width;
            let _ = writeln!(
                v,
                "    reg [{w}:0] i{i};\n    always @(posedge clk)\n        i{i} <= {{{}}};",
                bits.join(",\n            "),
                w = p.width - 1
            );
            conns.push(format!(".{id}(i{i})"));
        } else {
            let _ = writeln!(
                v,
                "    wire [{w}:0] o{i};\n    reg  [{w}:0] q{i};\n    always @(posedge clk) q{i} <= o{i};",
                w = p.width - 1
            );
            conns.push(format!(".{id}(o{i})"));
            outs.push((i, p.width));
        }
    }
    let _ = writeln!(
        v,
        "\n    {top} core (\n        {}\n    );",
        conns.join(",\n        ")
    );

    // the fold: every output bit into one vector, XORed 4 bits at a time into registers,
    // and those into a 32-bit signature register (an LFSR that takes them in: its state
    // depends on every bit it has taken, so no constant can be worked out through it and
    // nothing of the core is removed)
    let n: usize = outs.iter().map(|(_, w)| w).sum();
    let all = if outs.is_empty() {
        "lfsr[1:0]".to_owned()
    } else {
        outs.iter()
            .rev()
            .map(|(i, _)| format!("q{i}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let n = n.max(2);
    let g = n.div_ceil(4);
    let slots: Vec<String> = (0..32)
        .rev()
        .map(|j| {
            let terms: Vec<String> = (j..g).step_by(32).map(|k| format!("f[{k}]")).collect();
            if terms.is_empty() {
                "1'b0".to_owned()
            } else {
                terms.join(" ^ ")
            }
        })
        .collect();
    let _ = writeln!(
        v,
        "\n    wire [{p}:0] obits = {{{pad}{all}}};\n    reg  [{a}:0] f;\n    \
         reg  [31:0] sig = 32'd0;\n    integer k;\n    \
         always @(posedge clk) begin\n        \
         for (k = 0; k < {g}; k = k + 1) f[k] <= ^obits[k * 4 +: 4];\n        \
         sig <= {{sig[30:0], sig[31] ^ sig[21] ^ sig[1] ^ sig[0]}} ^ {{\n            {}\n        }};\n        \
         out0 <= sig[31];\n        out1 <= sig[15];\n    \
         end\nendmodule\n\n`default_nettype wire",
        slots.join(",\n            "),
        p = g * 4 - 1,
        pad = if g * 4 > n {
            format!("{}'d0, ", g * 4 - n)
        } else {
            String::new()
        },
        a = g - 1,
    );
    v
}

/// The three LFSR bits (a < b < c) that feed the wrapper's `j`-th input bit: the 4 960 triples
/// of 32 bits in a scrambled order, distinct for the first 4 960 bits.
fn lfsr_triple(j: usize) -> [usize; 3] {
    const N: usize = 32 * 31 * 30 / 6;
    // 1237 is prime to 4 960 = 2^5 * 5 * 31, so j -> k is a permutation
    let mut k = (j * 1237) % N;
    for a in 0..32 {
        let with_a = (31 - a) * (30 - a) / 2;
        if k < with_a {
            for b in a + 1..32 {
                let with_b = 31 - b;
                if k < with_b {
                    return [a, b, b + 1 + k];
                }
                k -= with_b;
            }
        }
        k -= with_a;
    }
    unreachable!("k < N")
}

impl Reference {
    /// A name for its builds: the top module, and the last file's stem when that is another
    /// name (netlists of one core in several configurations share a top module).
    pub fn name(&self) -> String {
        let stem = self
            .files
            .last()
            .and_then(|f| f.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let name = if stem.is_empty() || stem == self.top {
            self.top.clone()
        } else {
            format!("{}-{stem}", self.top)
        };
        name.chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect()
    }
}

/// The directory of one reference build: `<board>-ref-<name>-seed<S>` ([`Reference::name`]).
pub fn dir_name(board: Board, reference: &Reference, seed: u64) -> String {
    format!("{}-ref-{}-seed{seed}", board.name(), reference.name())
}

/// A wrapped core's build and the ports it was wrapped by.
#[derive(Debug, Clone, PartialEq)]
pub struct Built {
    /// The flow's outcome (the figures include the wrapper's registers).
    pub outcome: Outcome,
    /// The core's ports.
    pub ports: Vec<Port>,
    /// The clock and reset inputs among them (not fed by the LFSR).
    pub clock_reset: Vec<String>,
}

/// The signature register and its output pins' flip-flops.
const SIGNATURE_CELLS: usize = 32;

impl Built {
    /// The bits the wrapper registers: (into the core, out of it), clock and reset left out.
    pub fn wrapper_bits(&self) -> (usize, usize) {
        let ins = self
            .ports
            .iter()
            .filter(|p| p.input && !self.clock_reset.contains(&p.name))
            .map(|p| p.width)
            .sum();
        let outs = self
            .ports
            .iter()
            .filter(|p| !p.input)
            .map(|p| p.width)
            .sum();
        (ins, outs)
    }

    /// About how many of the build's logic cells are the wrapper's: a register per bit of
    /// [`Self::wrapper_bits`], one per four output bits folded, and the signature register.
    pub fn wrapper_cells(&self) -> usize {
        let (ins, outs) = self.wrapper_bits();
        ins + outs + outs.div_ceil(4) + SIGNATURE_CELLS
    }
}

/// Wraps `reference`, then synthesises, places and routes it on `board` with `seed`, held to
/// the board's Fmax goal; outputs in `out/<dir_name>/` (the wrapper as `ref_top.v`).
pub fn build(
    reference: &Reference,
    board: Board,
    seed: u64,
    sources: &Sources,
    out: &Path,
) -> Result<Built, FlowError> {
    let dir = out.join(dir_name(board, reference, seed));
    let ports = ports(&reference.files, &reference.top, &dir)?;
    let (clk, rst) = pick(
        &reference.top,
        &ports,
        reference.clock.as_deref(),
        reference.reset.as_deref(),
    )?;
    let wrap = dir.join("ref_top.v");
    fs::write(&wrap, wrapper_for(&reference.top, &ports, clk, rst))
        .map_err(io_err(format!("writing {}", wrap.display())))?;
    let clock_reset = [Some(clk), rst]
        .into_iter()
        .flatten()
        .map(|p| p.name.clone())
        .collect();
    let target = Target {
        board,
        design: Design::Reference,
        seed,
        clock_div_log2: 0,
        vision_unit: false,
    };
    let mut files = reference.files.clone();
    files.push(wrap);
    let outcome = flow::build_in(&target, &files, &target.pcf(sources), dir)?;
    Ok(Built {
        outcome,
        ports,
        clock_reset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn port(name: &str, input: bool, width: usize) -> Port {
        Port {
            name: name.into(),
            input,
            width,
        }
    }

    #[test]
    fn ports_are_read_from_yosys_json_and_bad_ones_refused() {
        let json: serde_json::Value = serde_json::from_str(
            r#"{"modules": {"cpu": {"ports": {
                "clk": {"direction": "input", "bits": [2]},
                "bus": {"direction": "output", "bits": [3, 4, 5]}}}}}"#,
        )
        .unwrap();
        let p = ports_from_json(&json, "cpu").unwrap();
        assert!(p.contains(&port("clk", true, 1)));
        assert!(p.contains(&port("bus", false, 3)));
        assert!(ports_from_json(&json, "gpu").is_err());
        let inout: serde_json::Value = serde_json::from_str(
            r#"{"modules": {"cpu": {"ports": {"pad": {"direction": "inout", "bits": [2]}}}}}"#,
        )
        .unwrap();
        let e = ports_from_json(&inout, "cpu").unwrap_err().to_string();
        assert!(e.contains("inout"), "{e}");
    }

    #[test]
    fn the_wrapper_drives_every_input_and_folds_every_output() {
        let ports = [
            port("io_clk", true, 1),
            port("resetn", true, 1),
            port("iBus_rsp", true, 40),
            port("irq", true, 1),
            port("dBus_cmd", false, 70),
            port("weird.name", false, 1),
        ];
        let v = wrapper("Cpu", &ports, None, None).unwrap();
        assert!(v.contains(".io_clk(clk)"), "{v}");
        assert!(v.contains(".resetn(!rst)"), "{v}");
        // 40 bits, each of its own three LFSR bits; the next input goes on from bit 40
        assert!(v.contains("reg [39:0] i2;"), "{v}");
        let [a, b, c] = lfsr_triple(0);
        assert!(
            v.contains(&format!("lfsr[{a}] ^ lfsr[{b}] ^ lfsr[{c}]}};")),
            "{v}"
        );
        let [a, b, c] = lfsr_triple(40);
        assert!(
            v.contains(&format!("i3 <= {{lfsr[{a}] ^ lfsr[{b}] ^ lfsr[{c}]}};")),
            "{v}"
        );
        assert!(v.contains(".\\weird.name (o5)"), "{v}");
        // 71 output bits: 18 groups of 4 (one bit of padding), into the signature's low slots
        assert!(v.contains("wire [71:0] obits = {1'd0, q5, q4};"), "{v}");
        assert!(v.contains("reg  [17:0] f;"), "{v}");
        assert!(v.contains("f[k] <= ^obits[k * 4 +: 4];"), "{v}");
        assert!(v.contains("            f[17],\n            f[16],"), "{v}");
        assert!(v.contains("            1'b0,\n            f[17],"), "{v}");
        assert!(v.contains("out0 <= sig[31];"), "{v}");
    }

    #[test]
    fn a_clock_or_reset_that_is_not_there_is_an_error() {
        let ports = [port("clock_in", true, 1), port("y", false, 8)];
        let e = wrapper("Cpu", &ports, None, None).unwrap_err().to_string();
        assert!(e.contains("no one-bit clock input"), "{e}");
        assert!(wrapper("Cpu", &ports, Some("clock_in"), None).is_ok());
        let e = wrapper("Cpu", &ports, Some("clock_in"), Some("rst"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no one-bit reset input `rst`"), "{e}");
        // a wide "clock" is refused too
        let wide = [port("clk", true, 2), port("y", false, 1)];
        assert!(wrapper("Cpu", &wide, None, None).is_err());
    }

    #[test]
    fn the_input_bits_have_distinct_lfsr_triples() {
        let mut seen = std::collections::HashSet::new();
        for j in 0..4960 {
            let [a, b, c] = lfsr_triple(j);
            assert!(a < b && b < c && c < 32, "{j}: {a} {b} {c}");
            assert!(seen.insert([a, b, c]), "{j} repeats {a} {b} {c}");
        }
    }

    #[test]
    fn active_low_resets_are_told_by_their_names() {
        for n in ["resetn", "rst_n", "RESET_N", "reset_b", "io_rstn"] {
            assert!(active_low(n), "{n}");
        }
        for n in ["reset", "rst", "io_reset", "io_asyncReset"] {
            assert!(!active_low(n), "{n}");
        }
    }

    #[test]
    fn directory_names() {
        let r = |files: &[&str], top: &str| Reference {
            files: files.iter().map(PathBuf::from).collect(),
            top: top.into(),
            clock: None,
            reset: None,
        };
        assert_eq!(
            dir_name(Board::Hx8k, &r(&["x/VexRiscv_Min.v"], "VexRiscv"), 2),
            "hx8k-ref-VexRiscv-VexRiscv_Min-seed2"
        );
        assert_eq!(
            dir_name(Board::Up5k, &r(&["a.v", "b/rv_core.v"], "rv_core"), 1),
            "up5k-ref-rv_core-seed1"
        );
        assert_eq!(
            dir_name(Board::Up5k, &r(&[], "a.b"), 1),
            "up5k-ref-a_b-seed1"
        );
    }
}
