//! `almc`: the ALMC user's command-line tool.
//!
//! Each subcommand group lives in its own module; this file only dispatches.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod lbc;
mod lbc_emu;

#[derive(Debug, Parser)]
#[command(name = "almc", version, about = "ALMC micro-car testbed tool")]
struct Cli {
    #[command(subcommand)]
    command: Group,
}

#[derive(Debug, Subcommand)]
enum Group {
    /// UBC<->LBC protocol: decode and encode messages.
    #[command(subcommand)]
    Lbc(lbc::LbcCommand),
    /// Run an emulated lower board (LBC) behind a socket.
    LbcEmu(lbc_emu::Args),
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Group::Lbc(cmd) => lbc::run(cmd),
        Group::LbcEmu(args) => lbc_emu::run(args),
    }
}
