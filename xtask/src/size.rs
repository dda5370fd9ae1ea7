//! `cargo xtask bench --only size`: the firmware's sections against the size goals, and where
//! its text goes, in two views:
//!
//! - **by source crate**: every byte of code attributed, through the DWARF line table, to the
//!   crate of the source line it was compiled from. Inlined code counts for the crate it
//!   comes from (the `maneuvers` controller inlined into `ubc-app`'s main loop counts for
//!   `maneuvers`), so this is the view to judge a crate's cost by.
//! - **by symbol group**: every function and read-only object by the crate its symbol names
//!   (the path a demangled name starts with, or the trait's crate for `<u8 as Trait>::f`), with
//!   `compiler_builtins` split into soft-float arithmetic and the rest, unnamed constants
//!   (`.Lanon.*`), the shared prologue and epilogue routines and the machine outliner's
//!   sequences on rows of their own, and the bytes no symbol covers (alignment, jump tables).
//!   Inlined code counts for the function it was inlined into.
//!
//! Both views add up to the text size of [`crate::fw::sizes`].

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use object::{Object, ObjectSection, ObjectSymbol, SectionKind, SymbolKind};

use crate::fw;

/// Goal for code and read-only data of the firmware.
pub const TEXT_GOAL: u64 = 64 * 1024;
/// Goal for static RAM (data + bss) without the buffers.
const STATIC_RAM_GOAL: u64 = 16 * 1024;
/// Static objects at least this large count as buffers (UART rings, frame buffers).
const BUFFER_MIN: u64 = 1024;
/// How many of the largest functions the size report lists.
const TOP_FUNCTIONS: usize = 8;

/// Row of code the line table does not cover.
const NO_LINES: &str = "(no line information)";
/// Row of text no symbol covers.
const NO_SYMBOL: &str = "(no symbol: jump tables, alignment)";
/// Row of unnamed read-only constants.
const ANON: &str = "read-only constants without a name (`.Lanon.*`)";
/// Row of soft-float routines.
const SOFT_FLOAT: &str = "compiler_builtins: soft float";

/// Where the text of one image goes.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Breakdown {
    /// Code bytes by the crate of their source line (plus [`NO_LINES`]), and read-only data
    /// as one row.
    pub by_source: BTreeMap<String, u64>,
    /// Text bytes by symbol group.
    pub by_symbol: BTreeMap<String, u64>,
    /// Code bytes by source file (path relative to the workspace, the registry or the
    /// standard library's sources).
    pub by_file: BTreeMap<String, u64>,
}

fn kib(bytes: u64) -> String {
    format!("{:.1} KiB", bytes as f64 / 1024.0)
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "**missed**"
    }
}

/// The crate a source file belongs to, from its path: a registry crate's name without its
/// version, a standard-library crate (`core`, `compiler_builtins`), or the workspace member
/// directory under `root`.
pub fn crate_of_path(path: &str, root: &str) -> String {
    if let Some(rest) = path.split("/registry/src/").nth(1) {
        let dir = rest.split('/').nth(1).unwrap_or(rest);
        let name = match dir.rsplit_once('-') {
            Some((name, version)) if version.starts_with(|c: char| c.is_ascii_digit()) => name,
            _ => dir,
        };
        return name.replace('-', "_");
    }
    if let Some(rest) = path.split("/library/").nth(1) {
        return rest.split('/').next().unwrap_or(rest).replace('-', "_");
    }
    if let Some(rest) = path.strip_prefix(root) {
        let rest = rest.trim_start_matches('/');
        if let Some((member, _)) = rest.split_once('/') {
            return member.replace('-', "_");
        }
    }
    "(other sources)".to_owned()
}

/// The firmware's own package (the only package whose sources a trimmed path names without
/// a package directory).
const APP_DIR: &str = "ubc-app";

/// A source path as an untrimmed build names it, from the form cargo's `trim-paths` gives it
/// (`crate::fw::TRIM_PATHS`): the firmware package's `src/...` becomes
/// `ROOT/ubc-app/src/...`, a workspace package's `name-version/...` becomes `ROOT/name/...`,
/// a registry package's `REGISTRY/name-version/...` becomes `/registry/src/REGISTRY/...`.
/// A trimmed path may come joined to the compilation unit's directory, itself trimmed
/// (`radio-mac-0.1.0/index.crates.io-HASH/siphasher-1.0.4/src/sip.rs` for code of a registry
/// package inlined into a workspace package): the last package directory in it decides.
/// Absolute paths (the standard library's `/rustc/HASH/library/...`, or an untrimmed build)
/// are returned as they are.
pub fn untrimmed(path: &str, root: &str) -> String {
    if path.starts_with('/') {
        return path.to_owned();
    }
    let parts: Vec<&str> = path
        .split('/')
        .filter(|p| !p.is_empty() && *p != ".")
        .collect();
    let package = parts.iter().rposition(|p| package_name(p).is_some());
    match package {
        Some(i) if i > 0 && parts[i - 1].starts_with("index.") => {
            format!("/registry/src/{}", parts[i - 1..].join("/"))
        }
        Some(i) => {
            let name = package_name(parts[i]).unwrap_or(parts[i]);
            format!("{root}/{name}/{}", parts[i + 1..].join("/"))
        }
        None => match parts.iter().position(|p| *p == "src") {
            Some(i) => format!("{root}/{APP_DIR}/{}", parts[i..].join("/")),
            None => path.to_owned(),
        },
    }
}

/// The name of a `name-version` directory (`heapless-0.9.3`), `None` for any other name.
fn package_name(dir: &str) -> Option<&str> {
    let (name, version) = dir.rsplit_once('-')?;
    let semver =
        version.split('.').count() >= 3 && version.starts_with(|c: char| c.is_ascii_digit());
    (semver && !name.is_empty()).then_some(name)
}

/// The shared prologue and epilogue routines (`ubc-hal`'s `save_restore` module).
const SAVE_RESTORE: &str = "prologue and epilogue routines (`__riscv_save_*`, `__riscv_restore_*`)";
/// Sequences the machine outliner moved out of the functions that repeat them.
const OUTLINED: &str = "outlined sequences (`OUTLINED_FUNCTION_*`)";

/// The group of a demangled symbol name (see the module documentation).
pub fn group_of_symbol(name: &str) -> String {
    const MEM: [&str; 5] = ["memcpy", "memmove", "memset", "memcmp", "bcmp"];
    if name.starts_with(".Lanon") || name.starts_with(".L__unnamed") {
        return ANON.to_owned();
    }
    if name.starts_with("__riscv_save_") || name.starts_with("__riscv_restore_") {
        return SAVE_RESTORE.to_owned();
    }
    if name.starts_with("OUTLINED_FUNCTION_") {
        return OUTLINED.to_owned();
    }
    let last = name.rsplit("::").next().unwrap_or(name);
    let float_builtin = last.starts_with("__")
        && [
            "sf3", "df3", "sf2", "df2", "sfsi", "sfdi", "sisf", "sidf", "disf", "didf",
        ]
        .iter()
        .any(|end| last.ends_with(end));
    if name.contains("compiler_builtins::float") || float_builtin {
        return SOFT_FLOAT.to_owned();
    }
    if name.starts_with("compiler_builtins") || last.starts_with("__") || MEM.contains(&last) {
        return "compiler_builtins: memory, integer division".to_owned();
    }
    if name.starts_with("__rustc") {
        return "core".to_owned();
    }
    if name.starts_with("_defmt") || name.starts_with("__defmt") {
        return "defmt".to_owned();
    }
    // `<Type as Trait>::f` and `<Type>::f`: the type's crate, or the trait's for a primitive.
    let path = name.trim_start_matches('<').trim_start_matches('&');
    let first = path.split([':', '<', ' ', '>']).next().unwrap_or(path);
    let primitive = first.is_empty()
        || matches!(
            first,
            "u8" | "u16"
                | "u32"
                | "u64"
                | "u128"
                | "usize"
                | "i8"
                | "i16"
                | "i32"
                | "i64"
                | "i128"
                | "isize"
                | "f32"
                | "f64"
                | "bool"
                | "char"
                | "str"
                | "mut"
                | "["
        )
        || first.starts_with('[');
    if primitive {
        if let Some((_, tr)) = name.split_once(" as ") {
            return tr.split("::").next().unwrap_or(tr).to_owned();
        }
        return "core".to_owned();
    }
    if !name.contains("::") {
        // An unmangled symbol of the runtime or linker script (`_start`, `DefaultHandler`).
        return "runtime symbols (riscv-rt, linker script)".to_owned();
    }
    first.to_owned()
}

/// A source path shortened for the report: from the crate directory on.
fn short_path(path: &str, root: &str) -> String {
    for marker in ["/registry/src/", "/library/"] {
        if let Some(rest) = path.split(marker).nth(1) {
            let rest = if marker == "/registry/src/" {
                rest.split_once('/').map_or(rest, |(_, r)| r)
            } else {
                rest
            };
            return rest.to_owned();
        }
    }
    path.strip_prefix(root)
        .map_or(path, |r| r.trim_start_matches('/'))
        .to_owned()
}

/// Text bytes by the crate of their source line, from the DWARF line table (read-only data has
/// no lines: it is one row), and code bytes by source file.
type BySource = (BTreeMap<String, u64>, BTreeMap<String, u64>);

fn by_source(file: &object::File<'_>, root: &str) -> Result<BySource> {
    let endian = if file.is_little_endian() {
        gimli::RunTimeEndian::Little
    } else {
        gimli::RunTimeEndian::Big
    };
    let load = |id: gimli::SectionId| -> Result<Cow<'_, [u8]>, gimli::Error> {
        Ok(file
            .section_by_name(id.name())
            .and_then(|s| s.uncompressed_data().ok())
            .unwrap_or(Cow::Borrowed(&[])))
    };
    let sections = gimli::DwarfSections::load(load)?;
    let dwarf = sections.borrow(|s| gimli::EndianSlice::new(s, endian));
    // Code ranges: bytes of each executable section, attributed below.
    let mut code: Vec<(u64, u64)> = file
        .sections()
        .filter(|s| s.kind() == SectionKind::Text && s.size() > 0)
        .map(|s| (s.address(), s.address() + s.size()))
        .collect();
    code.sort_unstable();
    let in_code = |a: u64| code.iter().any(|&(lo, hi)| a >= lo && a < hi);
    // (start, end, source path) of every line-table row in the code.
    let mut spans: Vec<(u64, u64, String)> = Vec::new();
    let mut units = dwarf.units();
    while let Some(header) = units.next()? {
        let unit = dwarf.unit(header)?;
        let Some(program) = unit.line_program.clone() else {
            continue;
        };
        let mut rows = program.rows();
        let mut prev: Option<(u64, String)> = None;
        while let Some((header, row)) = rows.next_row()? {
            if let Some((start, krate)) = prev.take() {
                if row.address() > start && in_code(start) {
                    spans.push((start, row.address(), krate));
                }
            }
            if row.end_sequence() {
                continue;
            }
            let mut path = String::new();
            if let Some(f) = row.file(header) {
                if let Some(dir) = f.directory(header) {
                    path.push_str(&dwarf.attr_string(&unit, dir)?.to_string_lossy());
                    path.push('/');
                }
                path.push_str(&dwarf.attr_string(&unit, f.path_name())?.to_string_lossy());
                if !path.starts_with('/') {
                    if let Some(comp) = unit.comp_dir {
                        path = format!("{}/{path}", comp.to_string_lossy());
                    }
                }
            }
            prev = Some((row.address(), untrimmed(&path, root)));
        }
    }
    // Each byte once: overlapping rows (rare, from merged sequences) count for the first.
    spans.sort_by_key(|s| (s.0, s.1));
    let mut out: BTreeMap<String, u64> = BTreeMap::new();
    let mut files: BTreeMap<String, u64> = BTreeMap::new();
    let mut covered = 0u64;
    let mut end = 0u64;
    for (lo, hi, path) in spans {
        let lo = lo.max(end);
        if hi > lo {
            *out.entry(crate_of_path(&path, root)).or_default() += hi - lo;
            *files.entry(short_path(&path, root)).or_default() += hi - lo;
            covered += hi - lo;
            end = hi;
        }
    }
    let code_bytes: u64 = code.iter().map(|(lo, hi)| hi - lo).sum();
    if code_bytes > covered {
        out.insert(NO_LINES.to_owned(), code_bytes - covered);
    }
    let rodata: u64 = file
        .sections()
        .filter(|s| is_read_only(s.kind()))
        .map(|s| s.size())
        .sum();
    if rodata > 0 {
        out.insert("read-only data (all crates)".to_owned(), rodata);
    }
    Ok((out, files))
}

fn is_read_only(kind: SectionKind) -> bool {
    matches!(
        kind,
        SectionKind::ReadOnlyData | SectionKind::ReadOnlyDataWithRel | SectionKind::ReadOnlyString
    )
}

/// Text bytes by symbol group; bytes of text sections no symbol covers are one row.
fn by_symbol(file: &object::File<'_>) -> BTreeMap<String, u64> {
    let text_sections: Vec<object::SectionIndex> = file
        .sections()
        .filter(|s| s.kind() == SectionKind::Text || is_read_only(s.kind()))
        .map(|s| s.index())
        .collect();
    let total: u64 = file
        .sections()
        .filter(|s| text_sections.contains(&s.index()))
        .map(|s| s.size())
        .sum();
    let mut syms: Vec<(u64, u64, String)> = file
        .symbols()
        .filter(|s| s.size() > 0)
        .filter(|s| {
            s.section_index()
                .is_some_and(|i| text_sections.contains(&i))
        })
        .map(|s| {
            let name = s.name().unwrap_or("?");
            (
                s.address(),
                s.size(),
                format!("{:#}", rustc_demangle::demangle(name)),
            )
        })
        .collect();
    // Aliases (one routine under two names) and overlaps count once, for the first name.
    syms.sort_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)));
    let mut out: BTreeMap<String, u64> = BTreeMap::new();
    let mut end = 0u64;
    let mut covered = 0u64;
    for (addr, size, name) in syms {
        let lo = addr.max(end);
        let hi = addr + size;
        if hi > lo {
            *out.entry(group_of_symbol(&name)).or_default() += hi - lo;
            covered += hi - lo;
            end = hi;
        }
    }
    if total > covered {
        out.insert(NO_SYMBOL.to_owned(), total - covered);
    }
    out
}

/// Where the text of the ELF at `elf` goes (see [`Breakdown`]).
pub fn breakdown(elf: &Path) -> Result<Breakdown> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let root = crate::workspace_root();
    let (by_source, by_file) = by_source(&file, &root.to_string_lossy())
        .with_context(|| format!("reading the line table of {}", elf.display()))?;
    Ok(Breakdown {
        by_source,
        by_symbol: by_symbol(&file),
        by_file,
    })
}

/// A table of `rows` (largest first) with each row's share of `total`.
fn table(md: &mut String, head: &str, rows: &BTreeMap<String, u64>, total: u64) {
    let mut rows: Vec<(&String, &u64)> = rows.iter().collect();
    rows.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    let _ = writeln!(md, "| {head} | bytes | share |");
    let _ = writeln!(md, "|---|---:|---:|");
    for (name, bytes) in rows {
        let _ = writeln!(
            md,
            "| {name} | {bytes} | {:.1} % |",
            100.0 * *bytes as f64 / total.max(1) as f64
        );
    }
    let _ = writeln!(md, "| **total** | **{total}** | |");
}

/// The `n` largest function symbols of the ELF, largest first, demangled.
fn largest_functions(elf: &Path, n: usize) -> Result<Vec<(u64, String)>> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let mut funcs: Vec<(u64, String)> = file
        .symbols()
        .filter(|sym| sym.kind() == SymbolKind::Text && sym.size() > 0)
        .map(|sym| {
            let name = sym.name().unwrap_or("?");
            (sym.size(), format!("{:#}", rustc_demangle::demangle(name)))
        })
        .collect();
    funcs.sort_by(|a, b| b.cmp(a));
    funcs.dedup();
    funcs.truncate(n);
    Ok(funcs)
}

/// Writable static objects of at least [`BUFFER_MIN`] bytes, by demangled name.
fn buffer_objects(elf: &Path) -> Result<BTreeMap<String, u64>> {
    let bytes = std::fs::read(elf).with_context(|| format!("reading {}", elf.display()))?;
    let file = object::File::parse(&*bytes)
        .with_context(|| format!("parsing {} as an object file", elf.display()))?;
    let mut out = BTreeMap::new();
    for sym in file.symbols() {
        if sym.kind() != SymbolKind::Data || sym.size() < BUFFER_MIN {
            continue;
        }
        let Some(index) = sym.section_index() else {
            continue;
        };
        let Ok(section) = file.section_by_index(index) else {
            continue;
        };
        if !matches!(
            section.kind(),
            SectionKind::Data | SectionKind::UninitializedData
        ) || matches!(section.name(), Ok(".stack" | ".heap"))
        {
            continue;
        }
        let name = sym.name().unwrap_or("?");
        out.insert(format!("{:#}", rustc_demangle::demangle(name)), sym.size());
    }
    Ok(out)
}

/// The size benchmark: the stock firmware for `softcore` (the goal's image) against the goals,
/// where its text goes, and the `qemu_virt` build's sections.
pub fn bench() -> Result<String> {
    let elf = fw::build("softcore", true)?;
    let qemu = fw::sizes(&fw::build("qemu_virt", true)?)?;
    let mut md = String::from("## Firmware size (softcore, release)\n\n");
    md.push_str(&report(&elf)?);
    let _ = writeln!(
        md,
        "\nThe `qemu_virt` build: text {} ({}), data {}, bss {}.\n\n\
         Stack and heap reservations of the linker script are not counted.\n\
         Reproduce: `cargo xtask bench --only size` (the sections alone: `cargo xtask fw --board \
         softcore`, which prints `text N data N bss N`; the tables for any image: `cargo xtask \
         size --elf ELF`).",
        qemu.text,
        kib(qemu.text),
        qemu.data,
        qemu.bss
    );
    Ok(md)
}

/// `cargo xtask size [--elf ELF] [--files CRATE]`: the report of [`report`] for an image
/// (default: the stock firmware built for `softcore`), or the code of one crate by source
/// file.
pub fn run(elf: Option<&Path>, files_of: Option<&str>) -> Result<()> {
    let elf = match elf {
        Some(e) => e.to_path_buf(),
        None => fw::build("softcore", true)?,
    };
    match files_of {
        None => print!("{}", report(&elf)?),
        Some(krate) => {
            let root = crate::workspace_root();
            let root = root.to_string_lossy();
            let b = breakdown(&elf)?;
            let rows: BTreeMap<String, u64> = b
                .by_file
                .into_iter()
                .filter(|(path, _)| {
                    crate_of_path(&format!("{root}/{path}"), &root) == krate
                        || path.starts_with(&format!("{krate}/"))
                        || path.starts_with(&format!("{}-", krate.replace('_', "-")))
                })
                .collect();
            let total = rows.values().sum();
            let mut md = String::new();
            table(&mut md, &format!("`{krate}` source file"), &rows, total);
            print!("{md}");
        }
    }
    Ok(())
}

/// The sections of the image at `elf` against the goals, where its text goes, its large
/// static objects and its largest functions, as markdown.
pub fn report(elf: &Path) -> Result<String> {
    let elf = elf.to_path_buf();
    let s = fw::sizes(&elf)?;
    let buffers = buffer_objects(&elf)?;
    // Every static object counts, the UART rings too; only camera frame buffers would be
    // left out (the frame grabber's window is outside the image).
    let static_ram = s.data + s.bss;
    let mut md = String::new();
    let _ = writeln!(md, "| section | bytes | goal | |");
    let _ = writeln!(md, "|---|---:|---:|---|");
    let _ = writeln!(
        md,
        "| text (code + read-only data) | {} ({}) | <= {} | {} |",
        s.text,
        kib(s.text),
        kib(TEXT_GOAL),
        verdict(s.text <= TEXT_GOAL)
    );
    let _ = writeln!(md, "| data | {} | | |", s.data);
    let _ = writeln!(md, "| bss | {} ({}) | | |", s.bss, kib(s.bss));
    let _ = writeln!(
        md,
        "| static RAM (data + bss) | {static_ram} ({}) | <= {} | {} |",
        kib(static_ram),
        kib(STATIC_RAM_GOAL),
        verdict(static_ram <= STATIC_RAM_GOAL)
    );
    let b = breakdown(&elf)?;
    md.push_str(
        "\n### Text by source crate (DWARF line table; inlined code counts for its crate)\n\n",
    );
    table(&mut md, "crate", &b.by_source, s.text);
    md.push_str("\n### Text by symbol group (inlined code counts for the function it is in)\n\n");
    table(&mut md, "group", &b.by_symbol, s.text);
    let _ = writeln!(
        md,
        "\nLarge static objects ({BUFFER_MIN} bytes or more), counted above:\n"
    );
    if buffers.is_empty() {
        let _ = writeln!(md, "- none");
    }
    for (name, bytes) in &buffers {
        let _ = writeln!(md, "- `{name}`: {bytes} bytes");
    }
    let _ = writeln!(md, "\nLargest functions (bytes of code):\n");
    for (bytes, name) in largest_functions(&elf, TOP_FUNCTIONS)? {
        let _ = writeln!(md, "- {bytes} `{name}`");
    }
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crates_from_source_paths() {
        let root = "/work/tree";
        for (path, krate) in [
            (
                "/root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/heapless-0.9.3/src/vec.rs",
                "heapless",
            ),
            (
                "/root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/critical-section-1.2.0/src/lib.rs",
                "critical_section",
            ),
            (
                "/usr/lib/rustlib/src/rust/library/core/src/num/mod.rs",
                "core",
            ),
            (
                "/usr/lib/rustlib/src/rust/library/compiler-builtins/compiler-builtins/src/float/add.rs",
                "compiler_builtins",
            ),
            ("/work/tree/maneuvers/src/safety.rs", "maneuvers"),
            ("/work/tree/ubc-app/src/firmware.rs", "ubc_app"),
            ("/elsewhere/x.rs", "(other sources)"),
        ] {
            assert_eq!(crate_of_path(path, root), krate, "{path}");
        }
    }

    #[test]
    fn crates_from_trimmed_paths() {
        let root = "/work/tree";
        for (path, krate) in [
            (
                "index.crates.io-1949cf8c6b5b557f/heapless-0.9.3/src/vec.rs",
                "heapless",
            ),
            (
                "index.crates.io-1949cf8c6b5b557f/critical-section-1.2.0/src/lib.rs",
                "critical_section",
            ),
            (
                "/rustc/ac68faa20c58cbccd01ee7208bf3b6e93a7d7f96/library/core/src/num/mod.rs",
                "core",
            ),
            ("maneuvers-0.1.0/src/safety.rs", "maneuvers"),
            ("radio-mac-0.1.0/src/wire.rs", "radio_mac"),
            ("./src/firmware.rs", "ubc_app"),
            ("src/program/machine.rs", "ubc_app"),
            (
                "radio-mac-0.1.0/index.crates.io-1949cf8c6b5b557f/siphasher-1.0.4/src/sip.rs",
                "siphasher",
            ),
            ("ubc-hal-0.1.0/ubc-hal-0.1.0/src/serial.rs", "ubc_hal"),
            ("elsewhere/x.rs", "(other sources)"),
        ] {
            assert_eq!(crate_of_path(&untrimmed(path, root), root), krate, "{path}");
        }
        assert_eq!(
            short_path(&untrimmed("radio-mac-0.1.0/src/wire.rs", root), root),
            "radio-mac/src/wire.rs"
        );
        assert_eq!(
            short_path(&untrimmed("./src/firmware.rs", root), root),
            "ubc-app/src/firmware.rs"
        );
    }

    #[test]
    fn groups_of_symbols() {
        for (name, group) in [
            ("compiler_builtins::float::add::__addsf3", SOFT_FLOAT),
            ("__mulsf3", SOFT_FLOAT),
            ("__fixsfsi", SOFT_FLOAT),
            ("__lesf2", SOFT_FLOAT),
            (
                "compiler_builtins::mem::memcpy",
                "compiler_builtins: memory, integer division",
            ),
            ("__udivdi3", "compiler_builtins: memory, integer division"),
            ("memset", "compiler_builtins: memory, integer division"),
            (".Lanon.8c2b.12", ANON),
            ("<radio_mac::CarMac>::poll", "radio_mac"),
            (
                "<ubc_hal::serial::PortState<ubc_hal::mmio::Mmio>>::on_interrupt",
                "ubc_hal",
            ),
            ("<usize as core::fmt::Display>::fmt", "core"),
            ("<u8 as defmt::traits::Format>::format", "defmt"),
            ("maneuvers::fixed::atan2", "maneuvers"),
            ("_defmt_acquire", "defmt"),
            ("__rustc::rust_begin_unwind", "core"),
            ("_start", "runtime symbols (riscv-rt, linker script)"),
            ("__riscv_save_3", SAVE_RESTORE),
            ("__riscv_restore_12", SAVE_RESTORE),
            ("OUTLINED_FUNCTION_44", OUTLINED),
        ] {
            assert_eq!(group_of_symbol(name), group, "{name}");
        }
    }

    /// Slow (builds the firmware): `cargo test -p xtask -- --ignored size_breakdown`.
    #[test]
    #[ignore]
    fn size_breakdown_adds_up_to_the_text() {
        let elf = fw::build("softcore", true).expect("firmware");
        let text = fw::sizes(&elf).expect("sizes").text;
        let b = breakdown(&elf).expect("breakdown");
        assert_eq!(b.by_source.values().sum::<u64>(), text, "{:?}", b.by_source);
        assert_eq!(b.by_symbol.values().sum::<u64>(), text, "{:?}", b.by_symbol);
        assert!(b.by_source.contains_key("maneuvers"), "{:?}", b.by_source);
    }
}
