//! Another core in the generated wrapper (`fpga::reference`) elaborates as the flow reads it:
//! our own `rv_core` stands in for a published core here, its ports read by yosys, every
//! input driven and every output used. The published cores' figures come from
//! `cargo xtask fpga --reference` (docs/fpga.md). Skipped, with a message, when yosys is not
//! installed.

use std::path::PathBuf;
use std::process::Command;

use fpga::reference::{self, Reference, WRAPPER_TOP};
use fpga::Sources;

#[test]
fn a_core_in_the_generated_wrapper_elaborates_cleanly() {
    if Command::new("yosys").arg("-V").output().is_err() {
        println!("SKIPPED: yosys not installed (Debian package yosys)");
        return;
    }
    let sources = Sources::in_workspace();
    let r = Reference {
        files: vec![
            sources.rtl.join("rv_expand.v"),
            sources.rtl.join("rv_core.v"),
        ],
        top: "rv_core".into(),
        clock: None,
        reset: None,
    };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("reference-wrapper");
    let ports = reference::ports(&r.files, &r.top, &dir).expect("yosys reads the ports");
    assert!(ports
        .iter()
        .any(|p| p.name == "imem_addr" && !p.input && p.width == 32));
    assert!(ports
        .iter()
        .any(|p| p.name == "irq_timer" && p.input && p.width == 1));
    let text = reference::wrapper(&r.top, &ports, None, None).expect("a wrapper");
    assert!(
        text.contains(".clk(clk)") && text.contains(".rst(rst)"),
        "{text}"
    );
    let wrap = dir.join("ref_top.v");
    std::fs::write(&wrap, &text).expect("writing the wrapper");
    let files: Vec<String> = r
        .files
        .iter()
        .chain([&wrap])
        .map(|f| format!("\"{}\"", f.display()))
        .collect();
    let script = format!(
        "read_verilog {}; hierarchy -check -top {WRAPPER_TOP}; proc; check -assert",
        files.join(" ")
    );
    let out = Command::new("yosys")
        .args(["-q", "-p", &script])
        .output()
        .expect("yosys runs");
    assert!(
        out.status.success(),
        "the wrapped core does not elaborate:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn a_missing_top_is_a_clear_error() {
    if Command::new("yosys").arg("-V").output().is_err() {
        println!("SKIPPED: yosys not installed (Debian package yosys)");
        return;
    }
    let sources = Sources::in_workspace();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("reference-missing-top");
    let err = reference::ports(&[sources.rtl.join("rv_expand.v")], "no_such_core", &dir)
        .unwrap_err()
        .to_string();
    assert!(err.contains("yosys failed"), "{err}");
}
