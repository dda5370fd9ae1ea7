//! `cargo xtask`: the project's commands.
//!
//! `demo` runs the main job, `test` runs every test, `fw` builds the firmware (or a program,
//! `--bin`), `new-program` makes a program from the template, `qemu` boots the firmware,
//! `bench` measures, `fpga` builds the SoC's bitstreams, `size` says where the firmware's text
//! goes. Each installs what it needs first (see `install`).

mod bench;
mod bench_fpga;
mod bench_vision;
mod demo;
mod fpga;
mod fw;
mod install;
mod program;
mod qemu;
mod size;
mod test;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

#[derive(Debug, Parser)]
#[command(name = "cargo xtask", about = "ALMC UBC project commands")]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Debug, Subcommand)]
enum Cmd {
    /// Run the main demonstration: four cars in QEMU form a wedge, break up and rendezvous.
    Demo,
    /// Run every test: lint, host tests, firmware build, QEMU end-to-end tests, fuzz smoke runs.
    Test(test::TestArgs),
    /// Build the firmware; the last line of output is the ELF path.
    Fw {
        /// Board to build for.
        #[arg(long, default_value = "qemu_virt")]
        board: String,
        /// The firmware binary: `ubc-app` (the stock program) or a program made with
        /// `new-program`.
        #[arg(long, default_value = fw::BIN)]
        bin: String,
        /// Debug build instead of release.
        #[arg(long)]
        debug: bool,
        /// Build the UART echo test mode (used by the QEMU acceptance tests) instead of the
        /// program.
        #[arg(long)]
        echo_test: bool,
    },
    /// Make a new upper-board program from the template: `ubc-app/src/bin/NAME.rs`.
    NewProgram {
        /// The program's name: lowercase letters, digits and `_`.
        name: String,
    },
    /// Boot the firmware in QEMU with its UARTs attached to sockets.
    Qemu(qemu::QemuArgs),
    /// Run the benchmarks and print their figures.
    Bench(bench::BenchArgs),
    /// Synthesise, place, route and time the SoC for the iCE40 boards; write bitstreams.
    Fpga(fpga::FpgaArgs),
    /// Where a firmware image's text goes, by source crate and by symbol group.
    Size {
        /// The ELF (default: the stock firmware, built for `softcore`).
        #[arg(long)]
        elf: Option<PathBuf>,
        /// Instead, the code of this crate (e.g. `maneuvers`, `core`) by source file.
        #[arg(long, value_name = "CRATE")]
        files: Option<String>,
    },
}

fn main() {
    let cli = Cli::parse();
    let result = match cli.command {
        Cmd::Demo => demo::run(),
        Cmd::Test(args) => test::run(args),
        Cmd::Fw {
            board,
            bin,
            debug,
            echo_test,
        } => {
            let features: &[&str] = if echo_test { &["echo-test"] } else { &[] };
            fw::build_features(&board, &bin, features, !debug).map(|_| ())
        }
        Cmd::NewProgram { name } => program::create(&fw::app_dir(), &name),
        Cmd::Qemu(args) => qemu::run(args),
        Cmd::Bench(args) => bench::run(args),
        Cmd::Fpga(args) => fpga::run(args),
        Cmd::Size { elf, files } => size::run(elf.as_deref(), files.as_deref()),
    };
    if let Err(err) = result {
        eprintln!("xtask: error: {err:#}");
        std::process::exit(1);
    }
}

/// The workspace root (the parent of xtask/).
pub fn workspace_root() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().map(PathBuf::from).unwrap_or(manifest)
}

/// Prints a stage heading.
pub fn stage(name: &str) {
    println!("\n==> {name}");
}
