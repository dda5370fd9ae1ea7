//! The timing probes (`verilator-tb/fpga/probe/`, docs/fpga.md) elaborate as the flow reads
//! them: every module they use is found, no net is driven twice or left undriven. Their
//! figures come from `cargo xtask bench --only probes`; this keeps them buildable when the
//! modules they share with the cores change. Skipped, with a message, when yosys is not
//! installed.

use std::process::Command;

use fpga::{Board, Design, Sources, Stage, Target};

#[test]
fn every_probe_elaborates_cleanly() {
    if Command::new("yosys").arg("-V").output().is_err() {
        println!("SKIPPED: yosys not installed (Debian package yosys)");
        return;
    }
    let sources = Sources::in_workspace();
    for stage in Stage::ALL {
        let t = Target {
            design: Design::Probe(stage),
            ..Target::core(Board::Hx8k)
        };
        let files: Vec<String> = t
            .verilog(&sources)
            .iter()
            .map(|f| {
                assert!(f.exists(), "{} is missing", f.display());
                format!("\"{}\"", f.display())
            })
            .collect();
        let script = format!(
            "read_verilog {}; hierarchy -check -top {}; proc; check -assert",
            files.join(" "),
            t.top()
        );
        let out = Command::new("yosys")
            .args(["-q", "-p", &script])
            .output()
            .expect("yosys runs");
        assert!(
            out.status.success(),
            "the {} probe does not elaborate:\n{}{}",
            stage.name(),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn stage_names_round_trip() {
    for stage in Stage::ALL {
        assert_eq!(stage.name().parse::<Stage>(), Ok(stage));
    }
    let err = "writeback".parse::<Stage>().unwrap_err();
    assert!(err.contains("fetch, decode or execute"), "{err}");
}
