//! Verilates the SoC (rtl/*.v) and links the C++ model with `csrc/sim.cpp` into the `vtb-sim`
//! executable, which the harness runs as a child process (its path reaches the crate as the
//! compile-time variable `VTB_SIM_EXE`).

use std::path::PathBuf;
use std::process::Command;

const RTL: &[&str] = &[
    "rtl/soc.v",
    "rtl/soc_ram.v",
    "rtl/rv_expand.v",
    "rtl/rv_core.v",
    "rtl/rv_pipe.v",
    "rtl/uart16550.v",
    "rtl/clint.v",
    "rtl/plic.v",
    "rtl/vision_unit.v",
];

fn verilator_root() -> PathBuf {
    if let Ok(root) = std::env::var("VERILATOR_ROOT") {
        return PathBuf::from(root);
    }
    let out = Command::new("verilator")
        .arg("--getenv")
        .arg("VERILATOR_ROOT")
        .output();
    match out {
        Ok(o) if o.status.success() => {
            PathBuf::from(String::from_utf8_lossy(&o.stdout).trim().to_string())
        }
        _ => PathBuf::from("/usr/share/verilator"),
    }
}

/// The simulators built: executable name, the environment variable that gives the crate its
/// path, and the SoC parameters it is verilated with.
const VARIANTS: &[(&str, &str, &[&str])] = &[
    // the SoC as the firmware, the model and the UP5K run it
    ("vtb-sim", "VTB_SIM_EXE", &[]),
    // the core of the parts without DSP blocks (HX8K): multiplication in the divider's loop
    ("vtb-sim-mulseq", "VTB_SIM_MULSEQ_EXE", &["-GMUL_SEQ=1"]),
    // the pipelined core (rv_pipe), with the multiplier and with multiplication in the
    // divider's loop (the HX8K's core)
    ("vtb-sim-pipe", "VTB_SIM_PIPE_EXE", &["-GPIPE=1"]),
    (
        "vtb-sim-pipe-mulseq",
        "VTB_SIM_PIPE_MULSEQ_EXE",
        &["-GPIPE=1", "-GMUL_SEQ=1"],
    ),
];

fn main() {
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    for f in RTL.iter().chain(["csrc/sim.cpp", "build.rs"].iter()) {
        println!("cargo:rerun-if-changed={f}");
    }
    println!("cargo:rerun-if-env-changed=VERILATOR_ROOT");
    for (name, var, params) in VARIANTS {
        let exe = build_sim(&out_dir, name, params);
        println!("cargo:rustc-env={var}={}", exe.display());
    }
}

/// Verilates the SoC with `params` and links the simulator `name` in `out_dir`.
fn build_sim(out_dir: &std::path::Path, name: &str, params: &[&str]) -> PathBuf {
    let mdir = out_dir.join(format!("obj_dir-{name}"));

    let _ = std::fs::remove_dir_all(&mdir);
    let status = Command::new("verilator")
        .args([
            "--cc",
            "-O2",
            "--x-assign",
            "fast",
            "--x-initial",
            "fast",
            "--noassert",
        ])
        .args([
            "-Wall",
            "-Wno-fatal",
            "-Wno-UNUSEDSIGNAL",
            "--top-module",
            "soc",
        ])
        .args(params)
        .arg("--Mdir")
        .arg(&mdir)
        .args(RTL)
        .status();
    match status {
        Ok(s) if s.success() => {}
        Ok(s) => panic!("verilator failed on the RTL ({s})"),
        Err(e) => panic!(
            "cannot run `verilator` ({e}): install it (Debian/Ubuntu package `verilator`, \
             5.006 or later) or put it on PATH"
        ),
    }

    let root = verilator_root();
    let include = root.join("include");
    let objects_dir = out_dir.join(format!("cc-{name}"));
    let _ = std::fs::create_dir_all(&objects_dir);
    let mut build = cc::Build::new();
    build
        .out_dir(&objects_dir)
        .cpp(true)
        .std("c++17")
        .opt_level(1)
        .debug(false)
        .warnings(false)
        .include(&include)
        .include(include.join("vltstd"))
        .include(&mdir)
        .file("csrc/sim.cpp")
        .file(include.join("verilated.cpp"))
        .file(include.join("verilated_threads.cpp"));
    let mut generated: Vec<PathBuf> = std::fs::read_dir(&mdir)
        .expect("verilator wrote its output directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "cpp"))
        .collect();
    generated.sort();
    for f in &generated {
        build.file(f);
    }
    let objects = build.compile_intermediates();
    let exe = out_dir.join(name);
    let status = build
        .get_compiler()
        .to_command()
        .args(&objects)
        .arg("-o")
        .arg(&exe)
        .arg("-lpthread")
        .status();
    match status {
        Ok(s) if s.success() => {}
        Ok(s) => panic!("linking {name} failed ({s})"),
        Err(e) => panic!("cannot run the C++ compiler to link {name}: {e}"),
    }
    exe
}
