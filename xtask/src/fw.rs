//! `cargo xtask fw`: builds the `ubc-app` firmware for one board and reports its size.
//!
//! Toolchain choice: when the active rustup toolchain has the `riscv32imac-unknown-none-elf`
//! target installed, plain `cargo build --target ...` is used. Otherwise Debian's Rust
//! (`rustc-web`, `cargo-web`, `rust-web-src`: `/usr/bin/cargo`, `/usr/bin/rustc`, library
//! sources under `/usr/lib/rustlib/src/rust/library`) builds `core` itself with
//! `RUSTC_BOOTSTRAP=1 -Zbuild-std=core,compiler_builtins` and links with the rustup
//! toolchain's own lld (`rust-lld`, see [`debian_linker`]), or with Debian's `ld.lld-16` on a
//! machine without one. The
//! child cargo gets an environment cleaned of everything the outer `cargo xtask` set
//! (`CARGO*`, `RUSTC*`, `RUSTUP_*`, ...), so the rustup proxies cannot leak into that build.
//!
//! With the Debian toolchain the firmware is built with linker relaxation (see
//! [`relaxed_target_spec`]): the linker turns most two-instruction calls into one, 3 KB of a
//! 88 KB image. With `rust-lld` the linker also relaxes accesses near the global pointer
//! (`--relax-gp`; the boards' `memory.x` put `__global_pointer$` in the read-only data): a
//! constant's address in one instruction instead of two, 512 bytes of a 70 KB image. A rustup
//! target builds without either. The same target specification turns on the shared
//! prologue and epilogue routines (`+save-restore`) and, for the `softcore` board, whose cores
//! have it, the Zcb extension ([`EXTRA_FEATURES`], [`board_features`]).
//!
//! With the Debian toolchain the firmware's paths are also trimmed (cargo's `trim-paths`, see
//! [`TRIM_PATHS`]): the image names its sources relative to their packages, so the same
//! sources give the same loaded program wherever they are checked out (symbol names can still
//! differ: cargo hashes a path dependency's absolute path into its crate hash).
//!
//! Each board builds into its own target dir, `ubc-app/target/<board>/`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use object::{Object, ObjectSection, SectionKind};

/// The firmware's target triple (RV32IMAC: the soft core, its model and QEMU's `virt` board
/// all have the C extension; machine mode, no OS).
pub const TARGET: &str = "riscv32imac-unknown-none-elf";
/// Boards the firmware can be built for (cargo features of `ubc-app`).
pub const BOARDS: &[&str] = &["qemu_virt", "softcore"];
/// Debian packages of the fallback toolchain.
const DEBIAN_TOOLCHAIN: &[&str] = &["rustc-web", "cargo-web", "rust-web-src", "lld-16"];
const DEBIAN_CARGO: &str = "/usr/bin/cargo";
const DEBIAN_CARGO_CLIPPY: &str = "/usr/bin/cargo-clippy";
const DEBIAN_CLIPPY_PACKAGE: &str = "rust-web-clippy";
/// Flags that build `core` from source for the target (Debian toolchain). `core`'s
/// `optimize_for_size` picks its smaller algorithms where it has two; in this image that is
/// the integer formatting of panic messages (308 bytes less, no change in the firmware's
/// cycles: the firmware formats no number itself).
const BUILD_STD: [&str; 2] = [
    "-Zbuild-std=core,compiler_builtins",
    "-Zbuild-std-features=compiler-builtins-mem,optimize_for_size",
];
const DEBIAN_RUSTC: &str = "/usr/bin/rustc";
/// Cargo's flag that lets `--target` name a target specification file.
const JSON_TARGET_SPEC: &str = "-Zjson-target-spec";
/// Cargo's flags that trim the build's paths in panic locations, log locations and debug
/// information: the package's own sources as `src/...`, other packages as
/// `name-version/...`, the standard library as `/rustc/HASH/library/...`. Without them an
/// image would hold the absolute paths of its checkout and of `CARGO_HOME`, and two clones
/// of the same commit in different directories would build different code and data. (The
/// symbol table and debug information can still differ between them, in crate hashes.)
const TRIM_PATHS: [&str; 5] = [
    "-Ztrim-paths",
    "--config",
    "profile.release.trim-paths=\"all\"",
    "--config",
    "profile.dev.trim-paths=\"all\"",
];
const DEBIAN_LINKER: &str = "ld.lld-16";
/// LLVM options of the Debian-toolchain build (in the target specification), each measured on
/// the firmware's size and on the awake cycles of both soft cores (`docs/benchmarks.md`
/// section 1):
/// - a `match` gets a jump table from 10 cases on instead of 5: with fewer cases a chain of
///   compares is smaller than the table, its address computation and its bounds check
///   (244 bytes less, cycles unchanged);
/// - no tail duplication during block placement, no speculation of instructions above a
///   branch and no two-way `select`s built from small branches (164 bytes less together, and
///   0.2 % fewer awake cycles on the reference core and 0.3 % on the pipelined one);
/// - an inlining threshold of 33 instead of the size level's default (412 bytes less, 1 % more
///   awake cycles; 20 / 25 / 30 / 36 / 40 gave more bytes): with the shared prologue and
///   epilogue routines a call costs less than it did;
/// - the machine outliner, for repeated sequences that save at least 4 bytes (a further 432
///   bytes, cycles unchanged within 0.1 %).
const LLVM_ARGS: [&str; 7] = [
    "-riscv-min-jump-table-entries=10",
    "-tail-dup-placement=false",
    "-max-speculation-depth=0",
    "-two-entry-phi-node-folding-threshold=0",
    "-inline-threshold=33",
    "-enable-machine-outliner",
    "-outliner-benefit-threshold=4",
];
/// Environment variable cargo reads the target's linker from.
const LINKER_VAR: &str = "CARGO_TARGET_RISCV32IMAC_UNKNOWN_NONE_ELF_LINKER";
/// Name of the firmware binary.
pub const BIN: &str = "ubc-app";

/// Section sizes of a firmware image, in bytes, as `size` (Berkeley format) counts them:
/// `text` is code plus read-only data, `data` initialised writable data, `bss` zeroed data
/// (the stack and heap reservations of the linker script are not counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sizes {
    /// Code and read-only data.
    pub text: u64,
    /// Initialised data (stored in the image and copied to RAM at boot).
    pub data: u64,
    /// Zero-initialised data.
    pub bss: u64,
}

/// Which compiler builds the firmware.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Toolchain {
    /// The active rustup toolchain has the target.
    Rustup,
    /// Debian's rustc/cargo with `-Zbuild-std`.
    Debian,
}

/// The firmware crate's directory.
pub fn app_dir() -> PathBuf {
    crate::workspace_root().join("ubc-app")
}

/// The target dir of a build: one per board and extra feature set, so that switching between
/// the program and a test or benchmark variant never rebuilds the other.
fn target_dir(board: &str, features: &[&str]) -> PathBuf {
    let mut name = board.to_string();
    for f in features {
        name.push('+');
        name.push_str(f);
    }
    app_dir().join("target").join(name)
}

/// Where `build_features` leaves the ELF of `bin` built with extra `features` (`build`:
/// `bin` = `ubc-app`, no extra features).
fn features_elf_path(board: &str, bin: &str, features: &[&str], release: bool) -> PathBuf {
    target_dir(board, features)
        .join(TARGET)
        .join(if release { "release" } else { "debug" })
        .join(bin)
}

/// Builds the firmware for `board`, prints its section sizes and, as the last line, the
/// absolute path of the ELF, which it returns.
pub fn build(board: &str, release: bool) -> Result<PathBuf> {
    build_bin(board, BIN, release)
}

/// Builds binary `bin` of `ubc-app` (the firmware or a benchmark program such as
/// `bench_lbc_decode`) for `board`, like [`build`].
pub fn build_bin(board: &str, bin: &str, release: bool) -> Result<PathBuf> {
    build_features(board, bin, &[], release)
}

/// Builds binary `bin` for `board` with extra cargo `features` of `ubc-app` (for example
/// `echo-test`, the UART echo test mode the QEMU acceptance tests use), like [`build`].
pub fn build_features(board: &str, bin: &str, features: &[&str], release: bool) -> Result<PathBuf> {
    if !BOARDS.contains(&board) {
        bail!(
            "unknown board `{board}`; known boards: {}",
            BOARDS.join(", ")
        );
    }
    let toolchain = pick_toolchain()?;
    let app = app_dir();
    let target_dir = target_dir(board, features);
    let mut feature_list = board.to_string();
    for f in features {
        feature_list.push(',');
        feature_list.push_str(f);
    }
    let mut cmd = match toolchain {
        Toolchain::Rustup => {
            let mut cmd = clean_command("cargo", false);
            cmd.arg("build");
            cmd
        }
        Toolchain::Debian => {
            let mut cmd = clean_command(DEBIAN_CARGO, true);
            cmd.arg("build")
                .args(BUILD_STD)
                .arg(JSON_TARGET_SPEC)
                .args(TRIM_PATHS)
                .env("RUSTC", DEBIAN_RUSTC)
                .env("RUSTC_BOOTSTRAP", "1")
                .env(LINKER_VAR, debian_linker().path());
            cmd
        }
    };
    let target = target_arg(toolchain, board)?;
    cmd.current_dir(&app)
        .arg("--target")
        .arg(&target)
        .args(["--features", &feature_list, "--bin", bin, "--target-dir"])
        .arg(&target_dir);
    if release {
        cmd.arg("--release");
    }
    eprintln!(
        "xtask: building {bin} for {feature_list} ({}, {:?} toolchain)",
        if release { "release" } else { "debug" },
        toolchain
    );
    let status = cmd
        .status()
        .with_context(|| format!("running {:?}", cmd.get_program()))?;
    if !status.success() {
        bail!("{bin} build for {board} failed ({status})");
    }
    let elf = features_elf_path(board, bin, features, release);
    let elf = elf
        .canonicalize()
        .with_context(|| format!("firmware ELF missing at {}", elf.display()))?;
    let s = sizes(&elf)?;
    println!("text {} data {} bss {}", s.text, s.data, s.bss);
    println!("{}", elf.display());
    Ok(elf)
}

/// Runs clippy (`-D warnings`) over the firmware for `board` on the riscv32 target:
/// `ubc-app` (its own workspace) and `ubc-hal` with the features the firmware enables, so the
/// target-only code (trap handlers, logger) is linted too. Host-side lints of `ubc-hal` are
/// the ordinary `cargo clippy -p ubc-hal --all-targets`. Returns a one-line summary.
pub fn clippy(board: &str) -> Result<String> {
    if !BOARDS.contains(&board) {
        bail!(
            "unknown board `{board}`; known boards: {}",
            BOARDS.join(", ")
        );
    }
    let toolchain = pick_toolchain()?;
    if toolchain == Toolchain::Debian {
        crate::install::ensure_debian_packages(&[DEBIAN_CLIPPY_PACKAGE])?;
    }
    let app = app_dir();
    let target_dir = app.join("target").join("clippy");
    // Each board has its own defmt transport: semihosting on QEMU, the simulation console on
    // the soft core.
    let logger = if board == "softcore" {
        "console-logger"
    } else {
        "logger"
    };
    let hal_features = format!("{board},{logger},rt");
    let runs: [(PathBuf, Vec<&str>); 2] = [
        (app.clone(), vec!["--features", board]),
        (
            crate::workspace_root(),
            vec!["-p", "ubc-hal", "--features", &hal_features],
        ),
    ];
    let target = target_arg(toolchain, board)?;
    for (dir, args) in &runs {
        let mut cmd = match toolchain {
            Toolchain::Rustup => clean_command("cargo", false),
            Toolchain::Debian => {
                let mut cmd = clean_command(DEBIAN_CARGO_CLIPPY, true);
                cmd.env("CARGO", DEBIAN_CARGO)
                    .env("RUSTC", DEBIAN_RUSTC)
                    .env("RUSTC_BOOTSTRAP", "1");
                cmd
            }
        };
        cmd.arg("clippy");
        if toolchain == Toolchain::Debian {
            cmd.args(BUILD_STD).arg(JSON_TARGET_SPEC);
        }
        cmd.current_dir(dir)
            .args(["--release", "--target"])
            .arg(&target)
            .arg("--target-dir")
            .arg(&target_dir)
            .args(args)
            .args(["--", "-D", "warnings"]);
        eprintln!("xtask: firmware clippy in {} {:?}", dir.display(), args);
        let status = cmd
            .status()
            .with_context(|| format!("running {:?}", cmd.get_program()))?;
        if !status.success() {
            bail!("firmware clippy failed in {} ({status})", dir.display());
        }
    }
    Ok(format!(
        "firmware clippy clean for {board} on {TARGET}: ubc-app, ubc-hal ({hal_features})"
    ))
}

/// Section sizes of the ELF at `elf` (see [`Sizes`]).
pub fn sizes(elf: &Path) -> Result<Sizes> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let mut s = Sizes::default();
    for section in file.sections() {
        let name = section.name().unwrap_or("");
        let size = section.size();
        match section.kind() {
            SectionKind::Text
            | SectionKind::ReadOnlyData
            | SectionKind::ReadOnlyDataWithRel
            | SectionKind::ReadOnlyString => s.text += size,
            SectionKind::Data | SectionKind::Tls => s.data += size,
            SectionKind::UninitializedData | SectionKind::UninitializedTls
                if !is_reservation(name) =>
            {
                s.bss += size
            }
            _ => {}
        }
    }
    Ok(s)
}

/// Linker-script reservations that `size` would count as bss but hold no program data.
fn is_reservation(name: &str) -> bool {
    matches!(name, ".stack" | ".heap")
}

/// What `--target` names for `toolchain`: the built-in target (rustup), or the relaxed
/// specification of it ([`relaxed_target_spec`], Debian).
fn target_arg(toolchain: Toolchain, board: &str) -> Result<OsString> {
    Ok(match toolchain {
        Toolchain::Rustup => TARGET.into(),
        Toolchain::Debian => {
            relaxed_target_spec(debian_linker().relaxes_gp(), board)?.into_os_string()
        }
    })
}

/// Writes (when it changed) and returns the path of a target specification for the Debian
/// rustc: the built-in `riscv32imac-unknown-none-elf` as that rustc prints it, with linker
/// relaxation (`+relax`) added to its features, so that the compiler marks calls and the
/// linker shortens `auipc`+`jalr` to `jal` (or `c.jal`) where the callee is in reach. Passing
/// `-C target-feature=+relax` instead would do the same, but rustc warns about it in every
/// crate (the feature is not stable). The file is named after the built-in target, so cargo
/// puts the output under the same `riscv32imac-unknown-none-elf` directory and applies the
/// same `[target.riscv32imac-unknown-none-elf]` settings and linker variable; each board has
/// its own, under `ubc-app/target/spec/<board>/`, with the rest of [`EXTRA_FEATURES`] and the
/// board's [`board_features`].
/// With `relax_gp` the linker is also told to relax accesses within 2 KiB of
/// `__global_pointer$` into `gp`-relative ones (`--relax-gp`, which lld does only when asked
/// and lld 16 does not know). riscv-rt loads `gp` in `_start`, before any Rust code, and
/// nothing writes it afterwards (LLVM reserves the register).
fn relaxed_target_spec(relax_gp: bool, board: &str) -> Result<PathBuf> {
    let out = clean_command(DEBIAN_RUSTC, true)
        .env("RUSTC_BOOTSTRAP", "1")
        .args([
            "-Z",
            "unstable-options",
            "--print",
            "target-spec-json",
            "--target",
            TARGET,
        ])
        .output()
        .with_context(|| format!("running {DEBIAN_RUSTC}"))?;
    if !out.status.success() {
        bail!(
            "{DEBIAN_RUSTC} could not print the {TARGET} specification: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let mut spec: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("parsing the {TARGET} specification {DEBIAN_RUSTC} printed"))?;
    let Some(fields) = spec.as_object_mut() else {
        bail!("the {TARGET} specification {DEBIAN_RUSTC} printed is not a JSON object");
    };
    let extra: Vec<&str> = EXTRA_FEATURES
        .iter()
        .chain(board_features(board))
        .copied()
        .collect();
    let features = with_features(fields.get("features").and_then(|f| f.as_str()), &extra);
    fields.insert("features".into(), serde_json::Value::String(features));
    fields.insert("llvm-args".into(), serde_json::json!(LLVM_ARGS));
    if relax_gp {
        fields.insert(
            "pre-link-args".into(),
            serde_json::json!({ "gnu-lld": ["--relax-gp"] }),
        );
    }
    let text = serde_json::to_string_pretty(&spec)?;
    let dir = app_dir().join("target").join("spec").join(board);
    let path = dir.join(format!("{TARGET}.json"));
    if std::fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
        // Written beside and renamed into place, so a build started meanwhile never reads
        // half a file.
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let part = dir.join(format!("{TARGET}.json.{}", std::process::id()));
        std::fs::write(&part, text).with_context(|| format!("writing {}", part.display()))?;
        std::fs::rename(&part, &path).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(path)
}

/// Target features the Debian-toolchain build adds to the built-in target's:
/// - `+relax`: linker relaxation (see [`relaxed_target_spec`]);
/// - `+save-restore`: a function that keeps callee-saved registers calls one shared routine
///   in its prologue and jumps to another in its epilogue (`ubc-hal`'s `save_restore`
///   module) instead of storing and loading each register itself: 2 316 bytes less on a
///   68 710-byte image, for 3.5 % more awake cycles on the idle firmware (`docs/benchmarks.md`
///   section 1).
const EXTRA_FEATURES: [&str; 2] = ["+relax", "+save-restore"];

/// Target features of one board's cores on top of [`EXTRA_FEATURES`]: the soft cores
/// (`rv_core`, `rv_pipe`) and their model have Zcb, the 16-bit forms of byte and halfword
/// loads and stores, `andi 255`, `xori -1` and `mul` (920 bytes less, the same instructions
/// and cycles); QEMU 7.2's `virt` board has not.
fn board_features(board: &str) -> &'static [&'static str] {
    match board {
        "softcore" => &["+zcb"],
        _ => &[],
    }
}

/// A target's feature list with each of `extra` in it once.
fn with_features(features: Option<&str>, extra: &[&str]) -> String {
    let mut list: Vec<&str> = features
        .map(|f| {
            f.split(',')
                .map(str::trim)
                .filter(|x| !x.is_empty())
                .collect()
        })
        .unwrap_or_default();
    for x in extra {
        if !list.contains(x) {
            list.push(x);
        }
    }
    list.join(",")
}

/// The linker of a Debian-toolchain build.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Linker {
    /// The rustup toolchain's `rust-lld` through its `gcc-ld/ld.lld` wrapper (which adds
    /// `-flavor gnu`); it knows `--relax-gp`.
    RustLld(PathBuf),
    /// Debian's `ld.lld-16`.
    Debian,
}

impl Linker {
    fn path(&self) -> OsString {
        match self {
            Linker::RustLld(p) => p.clone().into_os_string(),
            Linker::Debian => DEBIAN_LINKER.into(),
        }
    }

    fn relaxes_gp(&self) -> bool {
        matches!(self, Linker::RustLld(_))
    }
}

/// The linker for the Debian toolchain: the lld that ships with the machine's rustup
/// toolchain when it has one that knows `--relax-gp` (a newer lld than Debian's, and the one a
/// rustup target would use), else `ld.lld-16`.
fn debian_linker() -> Linker {
    static LINKER: std::sync::OnceLock<Linker> = std::sync::OnceLock::new();
    LINKER.get_or_init(find_rust_lld).clone()
}

fn find_rust_lld() -> Linker {
    let Ok(out) = clean_command("rustc", false)
        .current_dir(app_dir())
        .args(["--print", "sysroot"])
        .output()
    else {
        return Linker::Debian;
    };
    if !out.status.success() {
        return Linker::Debian;
    }
    let sysroot = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    let Ok(hosts) = std::fs::read_dir(sysroot.join("lib").join("rustlib")) else {
        return Linker::Debian;
    };
    for host in hosts.flatten() {
        let bin = host.path().join("bin");
        let (lld, wrapper) = (bin.join("rust-lld"), bin.join("gcc-ld").join("ld.lld"));
        if !(lld.is_file() && wrapper.is_file()) {
            continue;
        }
        let knows_gp = Command::new(&lld)
            .args(["-flavor", "gnu", "--help"])
            .output()
            .map(|o| {
                o.status.success() && String::from_utf8_lossy(&o.stdout).contains("--relax-gp")
            })
            .unwrap_or(false);
        if knows_gp {
            return Linker::RustLld(wrapper);
        }
    }
    Linker::Debian
}

fn pick_toolchain() -> Result<Toolchain> {
    if rustup_has_target() {
        return Ok(Toolchain::Rustup);
    }
    crate::install::ensure_debian_packages(DEBIAN_TOOLCHAIN)?;
    for tool in [DEBIAN_CARGO, DEBIAN_RUSTC] {
        if !Path::new(tool).is_file() {
            bail!("{tool} is missing although the Debian Rust packages are installed");
        }
    }
    if !crate::install::have_command(DEBIAN_LINKER) {
        bail!("{DEBIAN_LINKER} is not on PATH although lld-16 is installed");
    }
    Ok(Toolchain::Debian)
}

/// Whether the active rustup toolchain has the firmware target installed.
fn rustup_has_target() -> bool {
    if !crate::install::have_command("rustup") {
        return false;
    }
    clean_command("rustup", false)
        .current_dir(app_dir())
        .args(["target", "list", "--installed"])
        .output()
        .map(|out| {
            out.status.success()
                && String::from_utf8_lossy(&out.stdout)
                    .lines()
                    .any(|l| l.trim() == TARGET)
        })
        .unwrap_or(false)
}

/// True for variables the outer cargo/rustup set that must not reach the firmware build.
fn inherited_build_var(name: &str, drop_rustup: bool) -> bool {
    const KEEP: &[&str] = &[
        "CARGO_HOME",
        "CARGO_NET_",
        "CARGO_HTTP_",
        "CARGO_REGISTRIES_",
        "CARGO_REGISTRY_",
        "CARGO_TERM_",
    ];
    if name.starts_with("CARGO") || name.starts_with("__CARGO") {
        return !KEEP.iter().any(|keep| name.starts_with(keep));
    }
    if name.starts_with("RUSTUP_") {
        return drop_rustup;
    }
    matches!(
        name,
        "RUSTC"
            | "RUSTC_WRAPPER"
            | "RUSTC_WORKSPACE_WRAPPER"
            | "RUSTC_BOOTSTRAP"
            | "RUSTDOC"
            | "RUSTDOCFLAGS"
            | "RUSTFLAGS"
            | "RUST_TOOLCHAIN"
    ) || name.starts_with("RUSTC_")
}

/// A command whose environment lacks the outer build's variables. With `debian`, rustup's
/// variables go too and `/usr/bin` leads `PATH`, so `cargo`/`rustc` found by name are Debian's.
fn clean_command(program: &str, debian: bool) -> Command {
    let mut cmd = Command::new(program);
    for (name, _) in std::env::vars_os() {
        if let Some(name) = name.to_str() {
            if inherited_build_var(name, debian) {
                cmd.env_remove(name);
            }
        }
    }
    if debian {
        let mut path = OsString::from("/usr/bin");
        if let Some(old) = std::env::var_os("PATH") {
            path.push(":");
            path.push(old);
        }
        cmd.env("PATH", path);
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Zcb only where the cores have it: the soft cores and their model, not QEMU 7.2.
    #[test]
    fn zcb_only_for_the_soft_cores() {
        assert_eq!(board_features("softcore"), ["+zcb"]);
        assert!(board_features("qemu_virt").is_empty());
        for b in BOARDS {
            assert!(!board_features(b).iter().any(|f| EXTRA_FEATURES.contains(f)));
        }
    }

    #[test]
    fn extra_features_join_the_target_features_once() {
        let x = ["+relax", "+save-restore"];
        assert_eq!(
            with_features(Some("+m,+a,+c"), &x),
            "+m,+a,+c,+relax,+save-restore"
        );
        assert_eq!(
            with_features(Some("+m,+relax,+c"), &x),
            "+m,+relax,+c,+save-restore"
        );
        assert_eq!(with_features(Some(""), &x), "+relax,+save-restore");
        assert_eq!(with_features(None, &["+relax"]), "+relax");
    }

    #[test]
    fn strips_outer_build_environment() {
        for var in [
            "CARGO",
            "CARGO_MANIFEST_DIR",
            "CARGO_PKG_NAME",
            "CARGO_TARGET_DIR",
            "CARGO_BUILD_TARGET",
            "CARGO_ENCODED_RUSTFLAGS",
            "CARGO_MAKEFLAGS",
            "__CARGO_FIX_PLZ",
            "RUSTC",
            "RUSTC_WRAPPER",
            "RUSTDOC",
            "RUSTFLAGS",
        ] {
            assert!(inherited_build_var(var, false), "{var} must be stripped");
        }
        for var in ["CARGO_HOME", "CARGO_NET_OFFLINE", "PATH", "HOME", "TERM"] {
            assert!(!inherited_build_var(var, true), "{var} must be kept");
        }
        assert!(inherited_build_var("RUSTUP_TOOLCHAIN", true));
        assert!(!inherited_build_var("RUSTUP_TOOLCHAIN", false));
    }

    #[test]
    fn elf_path_layout() {
        let p = features_elf_path("qemu_virt", BIN, &[], true);
        assert!(
            p.ends_with("ubc-app/target/qemu_virt/riscv32imac-unknown-none-elf/release/ubc-app")
        );
        assert!(features_elf_path("qemu_virt", BIN, &[], false).ends_with("debug/ubc-app"));
        assert!(
            features_elf_path("qemu_virt", "bench_lbc_decode", &[], true)
                .ends_with("release/bench_lbc_decode")
        );
        assert!(features_elf_path("qemu_virt", BIN, &["echo-test"], true)
            .ends_with("target/qemu_virt+echo-test/riscv32imac-unknown-none-elf/release/ubc-app"));
    }

    /// Slow (builds `core` for the target): `cargo test -p xtask -- --ignored firmware_clippy`.
    #[test]
    #[ignore]
    fn firmware_clippy_is_clean() {
        let summary = clippy("qemu_virt").expect("firmware clippy");
        assert!(summary.contains("ubc-hal"), "{summary}");
    }

    #[test]
    fn rejects_unknown_board() {
        let err = build("no_such_board", true).unwrap_err().to_string();
        assert!(err.contains("unknown board"), "{err}");
    }
}
