//! Puts the selected board's `memory.x` on the linker search path of firmware images, so the
//! board module stays the only place that knows addresses.

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let boards: &[(&str, &str)] = &[
        ("CARGO_FEATURE_QEMU_VIRT", "boards/qemu_virt/memory.x"),
        ("CARGO_FEATURE_SOFTCORE", "boards/softcore/memory.x"),
    ];
    let target_arch = env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    if target_arch != "riscv32" {
        return;
    }
    let Some(out_dir) = env::var_os("OUT_DIR").map(PathBuf::from) else {
        return;
    };
    for (feature, script) in boards {
        println!("cargo:rerun-if-changed={script}");
        if env::var_os(feature).is_some() {
            let text = fs::read(script).expect("board memory.x is part of the crate");
            fs::write(out_dir.join("memory.x"), text).expect("OUT_DIR is writable");
            println!("cargo:rustc-link-search={}", out_dir.display());
        }
    }
}
