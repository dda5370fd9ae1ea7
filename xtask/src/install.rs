//! Installs what the project needs on a fresh Debian machine.
//!
//! Every command calls these before it uses a tool: when a Debian package is missing and we run as
//! root it is installed with apt-get; otherwise the exact install line is printed and the command
//! fails, so nothing half-works.

use std::path::PathBuf;
use std::process::Command;
use std::sync::Once;

use anyhow::{bail, Context, Result};

/// Finds `name` on `PATH`.
pub fn find_command(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|candidate| candidate.is_file())
}

/// True when `name` is an executable on `PATH`.
pub fn have_command(name: &str) -> bool {
    find_command(name).is_some()
}

/// True when the Debian package is installed (dpkg reports "install ok installed").
pub fn debian_package_installed(pkg: &str) -> bool {
    Command::new("dpkg-query")
        .args(["-W", "-f=${Status}", pkg])
        .output()
        .map(|out| {
            out.status.success() && String::from_utf8_lossy(&out.stdout).ends_with("installed")
        })
        .unwrap_or(false)
}

fn running_as_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|out| String::from_utf8_lossy(&out.stdout).trim() == "0")
        .unwrap_or(false)
}

/// Makes sure every package in `pkgs` is installed, installing the missing ones when root.
pub fn ensure_debian_packages(pkgs: &[&str]) -> Result<()> {
    let missing: Vec<&str> = pkgs
        .iter()
        .copied()
        .filter(|p| !debian_package_installed(p))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    let line = format!(
        "apt-get install -y --no-install-recommends {}",
        missing.join(" ")
    );
    if !have_command("apt-get") {
        bail!(
            "missing packages {:?} and no apt-get on this machine; install them with your package manager",
            missing
        );
    }
    if !running_as_root() {
        bail!("missing Debian packages {missing:?}; install them with:\n    sudo apt-get update && sudo {line}");
    }
    eprintln!(
        "xtask: installing missing Debian packages: {}",
        missing.join(" ")
    );
    apt_update_once()?;
    let status = Command::new("apt-get")
        .args(["install", "-y", "--no-install-recommends"])
        .args(&missing)
        .env("DEBIAN_FRONTEND", "noninteractive")
        .status()
        .context("running apt-get install")?;
    if !status.success() {
        bail!("`{line}` failed ({status})");
    }
    Ok(())
}

fn apt_update_once() -> Result<()> {
    static UPDATE: Once = Once::new();
    let mut result = Ok(());
    UPDATE.call_once(|| {
        let status = Command::new("apt-get")
            .args(["update", "-q"])
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status();
        result = match status {
            Ok(s) if s.success() => Ok(()),
            Ok(s) => Err(anyhow::anyhow!("apt-get update failed ({s})")),
            Err(e) => Err(anyhow::Error::new(e).context("running apt-get update")),
        };
    });
    result
}

/// QEMU for the firmware's board.
pub fn ensure_qemu() -> Result<()> {
    ensure_debian_packages(&["qemu-system-misc"])?;
    if !have_command("qemu-system-riscv32") {
        bail!("qemu-system-riscv32 not found on PATH although qemu-system-misc is installed");
    }
    Ok(())
}

/// Verilator, for the soft core's test bench (`verilator-tb`).
pub fn ensure_verilator() -> Result<()> {
    ensure_debian_packages(&["verilator"])?;
    if !have_command("verilator") {
        bail!("verilator not found on PATH although the verilator package is installed");
    }
    Ok(())
}

/// yosys, nextpnr-ice40 and icepack, for the FPGA flow (`cargo xtask fpga`, the soft core's
/// area figures and the bitstream tests).
pub fn ensure_fpga_tools() -> Result<()> {
    ensure_debian_packages(&fpga::DEBIAN_PACKAGES)?;
    if let Some(tool) = fpga::missing_tools().first() {
        bail!("{tool} not found on PATH although its Debian package is installed");
    }
    Ok(())
}
