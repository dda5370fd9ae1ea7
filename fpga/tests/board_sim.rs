//! The board-level SoC (`verilator-tb/fpga/fpga_soc.v`) simulated with Verilator, as the
//! FPGA runs it: the loader reads the program image from a SPI flash model, the UARTs talk
//! over their serial lines (decoded and driven by the test bench, `board_tb.cpp`), and a
//! parallel camera sends a frame. Two RAMs: block RAM (`rtl/soc_ram.v`, 4 KiB as on the HX8K)
//! and the UltraPlus SPRAMs (`fpga/soc_ram_spram.v` with yosys's model of SB_SPRAM256KA, 64
//! KiB). The program (`fpga::demo`) must print the greeting with the self-test checksum
//! computed in Rust, echo on both UARTs, print the camera's bytes and write the pass value.
//!
//! Skipped, with a message, when Verilator (or, for the SPRAM case, yosys's cell models) is
//! not installed.

use std::path::{Path, PathBuf};
use std::process::Command;

use fpga::{demo, Board, Sources};

const FRAME: [u8; 8] = [0x3c, 0x00, 0xff, 0x81, 0x12, 0x34, 0x56, 0x78];
const INPUT: &str = "hi cq";
/// 16 * divisor 8 clocks per bit: 115200 baud at the SoC clock.
const BIT_CLOCKS: u32 = 128;

fn on_path(tool: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(tool))
        .find(|p| p.is_file())
}

/// yosys's simulation model of the UltraPlus SPRAM, without its timing (`specify`) block.
fn spram_model(dir: &Path) -> Option<PathBuf> {
    let yosys = on_path("yosys")?;
    let cells = yosys.parent()?.join("../share/yosys/ice40/cells_sim.v");
    let text = std::fs::read_to_string(cells).ok()?;
    let start = text.find("module SB_SPRAM256KA")?;
    let end = start + text[start..].find("endmodule")? + "endmodule".len();
    let mut module = String::new();
    let mut skip = false;
    for line in text[start..end].lines() {
        let t = line.trim();
        if t.starts_with("`ifdef ICE40_U") {
            skip = true;
        } else if skip && t.starts_with("`endif") {
            skip = false;
        } else if !skip {
            module.push_str(line);
            module.push('\n');
        }
    }
    let out = dir.join("sb_spram256ka.v");
    std::fs::write(&out, module).ok()?;
    Some(out)
}

fn hex_bytes(s: &str) -> Vec<u8> {
    if s == "-" {
        return Vec::new();
    }
    (0..s.len() / 2)
        .map(|i| u8::from_str_radix(&s[2 * i..2 * i + 2], 16).expect("the bench prints hex"))
        .collect()
}

fn run_board(board: Board) {
    if on_path("verilator").is_none() {
        println!("SKIPPED: verilator is not installed (Debian package `verilator`)");
        return;
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("board-sim-{board}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let s = Sources::in_workspace();
    let mut files: Vec<PathBuf> = vec![s.rtl.join("soc.v")];
    match board {
        Board::Hx8k => files.push(s.rtl.join("soc_ram.v")),
        Board::Up5k => {
            let Some(model) = spram_model(&dir) else {
                println!("SKIPPED: yosys's ice40 cell models are not installed (Debian `yosys`)");
                return;
            };
            files.push(s.fpga.join("soc_ram_spram.v"));
            files.push(model);
        }
    }
    for f in [
        "rv_expand.v",
        "rv_core.v",
        "rv_pipe.v",
        "uart16550.v",
        "clint.v",
        "plic.v",
        "vision_unit.v",
    ] {
        files.push(s.rtl.join(f));
    }
    for f in [
        "fpga_soc.v",
        "spi_flash_loader.v",
        "uart_rx_line.v",
        "frame_capture.v",
    ] {
        files.push(s.fpga.join(f));
    }
    let tb = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/board_tb.cpp");
    let log = dir.join("verilator.log");
    let status = Command::new("verilator")
        .args([
            "--cc",
            "--exe",
            "--build",
            "-j",
            "2",
            "-O2",
            "-Wno-fatal",
            "-Wno-lint",
        ])
        .args(["-Wno-style", "--top-module", "fpga_soc", "-CFLAGS", "-O1"])
        .arg(format!("-GRAM_AW={}", board.ram_aw()))
        .arg(format!("-GMUL_SEQ={}", board.mul_seq()))
        .arg(format!("-GPIPE={}", board.pipe()))
        .arg(format!("-GFMEM_AW={}", board.frame_window_aw()))
        .arg("--Mdir")
        .arg(&dir)
        .args(&files)
        .arg(&tb)
        .arg("-o")
        .arg("Vtb")
        .stdout(std::fs::File::create(&log).unwrap())
        .stderr(std::fs::File::create(dir.join("verilator.err")).unwrap())
        .status()
        .expect("verilator runs");
    assert!(
        status.success(),
        "verilator failed; see {}",
        dir.join("verilator.err").display()
    );

    let image = dir.join("program.bin");
    std::fs::write(&image, demo::image(board, 0)).unwrap();
    let greeting = demo::expected_greeting(board, 0);
    let frame: String = FRAME.iter().map(|b| format!("{b:02x}")).collect();
    // loading copies the whole RAM at 64 clocks a word; then the greeting, then the input
    let max_cycles = u64::from(board.ram_bytes()) / 4 * 64 + 3_000_000;
    let out = Command::new(dir.join("Vtb"))
        .arg(&image)
        .arg(BIT_CLOCKS.to_string())
        .arg(max_cycles.to_string())
        .arg(greeting.len().to_string())
        .arg(INPUT)
        .arg(&frame)
        .output()
        .expect("the bench runs");
    assert!(out.status.success(), "the bench failed: {out:?}");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    let field = |name: &str| -> String {
        text.lines()
            .find_map(|l| l.strip_prefix(name).map(|r| r.trim().to_owned()))
            .unwrap_or_else(|| panic!("no `{name}` in the bench's output:\n{text}"))
    };
    let uart0 = String::from_utf8_lossy(&hex_bytes(&field("uart0"))).into_owned();
    let uart1 = String::from_utf8_lossy(&hex_bytes(&field("uart1"))).into_owned();
    assert_eq!(
        uart0,
        format!("{greeting}hi c{}q", demo::frame_hex(&FRAME)),
        "UART0 of the {board} SoC"
    );
    assert_eq!(uart1, INPUT, "UART1 of the {board} SoC");
    assert_eq!(field("exit"), "pass", "{text}");
    println!("{board}: {}", field("cycles"));
}

#[test]
fn block_ram_soc_loads_from_flash_and_talks_on_its_serial_lines() {
    run_board(Board::Hx8k);
}

#[test]
fn spram_soc_loads_from_flash_and_talks_on_its_serial_lines() {
    run_board(Board::Up5k);
}
