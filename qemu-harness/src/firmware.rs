//! Finding the pieces a QEMU run needs: the emulator binary and the firmware ELF, plus
//! the environment switches the end-to-end tests obey.

use std::env;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::Error;

/// Path of a prebuilt firmware ELF; when unset, [`firmware_elf`] builds one.
pub const FW_ELF_ENV: &str = "UBC_FW_ELF";
/// Path of a prebuilt firmware ELF in UART echo test mode (the `echo-test` feature); when
/// unset, [`echo_test_elf`] builds one.
pub const FW_ECHO_ELF_ENV: &str = "UBC_FW_ECHO_ELF";
/// Set to `1` to make QEMU tests skip (with a message) instead of running.
pub const SKIP_ENV: &str = "UBC_SKIP_QEMU";
/// Overrides the `qemu-system-riscv32` binary.
pub const QEMU_ENV: &str = "UBC_QEMU";

/// Searches `PATH` for an executable called `name`.
pub(crate) fn which(name: impl AsRef<OsStr>) -> Option<PathBuf> {
    let path = env::var_os("PATH")?;
    env::split_paths(&path)
        .map(|dir| dir.join(name.as_ref()))
        .find(|candidate| candidate.is_file())
}

/// The `qemu-system-riscv32` binary: `UBC_QEMU` if set, else the one on `PATH`.
pub fn find_qemu() -> Result<PathBuf, Error> {
    if let Some(path) = env::var_os(QEMU_ENV) {
        let path = PathBuf::from(path);
        return if path.is_file() {
            Ok(path)
        } else {
            Err(Error::QemuNotFound)
        };
    }
    which("qemu-system-riscv32").ok_or(Error::QemuNotFound)
}

/// The workspace root (the directory holding this crate).
pub fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest).to_path_buf()
}

/// The firmware ELF for the `qemu_virt` board: `UBC_FW_ELF` if set, else the path printed
/// on the last line of `cargo xtask fw --board qemu_virt`, run from the workspace root.
pub fn firmware_elf() -> Result<PathBuf, Error> {
    elf_from(FW_ELF_ENV, &["fw", "--board", "qemu_virt"])
}

/// Path of a prebuilt firmware ELF for the `softcore` board (the soft core's SoC, its
/// Verilated RTL and its model); when unset, [`softcore_elf`] builds one.
pub const SOFTCORE_ELF_ENV: &str = "VTB_FIRMWARE";

/// The firmware ELF for the `softcore` board: `VTB_FIRMWARE` if set, else the path printed on
/// the last line of `cargo xtask fw --board softcore`, run from the workspace root.
pub fn softcore_elf() -> Result<PathBuf, Error> {
    elf_from(SOFTCORE_ELF_ENV, &["fw", "--board", "softcore"])
}

/// The firmware ELF for `qemu_virt` in UART echo test mode, which the driver acceptance
/// tests need: `UBC_FW_ECHO_ELF` if set, else the last line printed by
/// `cargo xtask fw --board qemu_virt --echo-test`.
pub fn echo_test_elf() -> Result<PathBuf, Error> {
    elf_from(
        FW_ECHO_ELF_ENV,
        &["fw", "--board", "qemu_virt", "--echo-test"],
    )
}

/// The ELF of program `bin` (a firmware binary of `ubc-app`, e.g. one made by `cargo xtask
/// new-program`) for `board`: the last line printed by `cargo xtask fw --board BOARD --bin
/// BIN`, run from the workspace root (cargo rebuilds only what changed).
pub fn program_elf(board: &str, bin: &str) -> Result<PathBuf, Error> {
    elf_from("", &["fw", "--board", board, "--bin", bin])
}

fn elf_from(env_var: &str, xtask_args: &[&str]) -> Result<PathBuf, Error> {
    let root = workspace_root();
    let preset = if env_var.is_empty() {
        None
    } else {
        env::var_os(env_var)
    };
    let path = match preset {
        Some(path) => PathBuf::from(path),
        None => {
            let command = format!("cargo xtask {}", xtask_args.join(" "));
            let cargo = env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
            let output = Command::new(cargo)
                .arg("xtask")
                .args(xtask_args)
                .current_dir(&root)
                .stdin(Stdio::null())
                .stderr(Stdio::inherit())
                .output()
                .map_err(|source| Error::Io {
                    action: "running cargo xtask fw",
                    source,
                })?;
            if !output.status.success() {
                return Err(Error::FirmwareBuild {
                    command,
                    status: output.status.to_string(),
                });
            }
            let stdout = String::from_utf8_lossy(&output.stdout);
            let last = last_line(&stdout).ok_or_else(|| Error::FirmwareBuild {
                command,
                status: "succeeded but printed no ELF path".to_owned(),
            })?;
            PathBuf::from(last)
        }
    };
    let path = if path.is_relative() {
        root.join(path)
    } else {
        path
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(Error::FirmwareMissing { path })
    }
}

fn last_line(text: &str) -> Option<&str> {
    text.lines().map(str::trim).rfind(|l| !l.is_empty())
}

/// True (after printing why to stderr) when `UBC_SKIP_QEMU=1`: the caller, a QEMU test
/// named `test`, should return without doing anything. Any other value runs the test.
pub fn skip_qemu_tests(test: &str) -> bool {
    let skip = env::var_os(SKIP_ENV).is_some_and(|v| v == "1");
    if skip {
        eprintln!("skipping QEMU test `{test}`: {SKIP_ENV}=1");
    }
    skip
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn last_nonempty_line_is_the_elf() {
        let out = "   Compiling ubc-app\nbuilt\n/work/target/riscv/ubc-app\n\n";
        assert_eq!(last_line(out), Some("/work/target/riscv/ubc-app"));
        assert_eq!(last_line("\n  \n"), None);
    }

    #[test]
    fn which_finds_sh_but_not_nonsense() {
        assert!(which("sh").is_some());
        assert!(which("no-such-binary-ubc-xyz").is_none());
    }

    #[test]
    fn workspace_root_holds_this_crate() {
        assert!(workspace_root()
            .join("qemu-harness")
            .join("Cargo.toml")
            .is_file());
    }
}
