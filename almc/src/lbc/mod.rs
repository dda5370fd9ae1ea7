//! `almc lbc`: decode and encode UBC<->LBC messages (seed chapter 3).

use std::process::ExitCode;

use clap::{Args, Subcommand};

mod decode;
mod encode;
mod hex;
mod text;

pub use encode::EncodeCommand;

/// `almc lbc ...`
#[derive(Debug, Subcommand)]
pub enum LbcCommand {
    /// Decode bytes seen on the LBC UART: `e8 68 ff`, `0xE8,0x68,0xFF` or `e868ff`.
    Decode(DecodeArgs),
    /// Print the bytes of a command to the LBC.
    #[command(subcommand)]
    Encode(EncodeCommand),
}

/// Arguments of `almc lbc decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// Bytes in hex; separated by spaces or commas, or run together.
    #[arg(required = true, num_args = 1..)]
    pub bytes: Vec<String>,
    /// Print one JSON document instead of text.
    #[arg(long)]
    pub json: bool,
    /// Streaming format (28-bit, hex) used to decode STREAM messages.
    #[arg(long, value_name = "HEX")]
    pub stream_format: Option<String>,
}

/// Runs an `almc lbc` subcommand.
pub fn run(cmd: LbcCommand) -> ExitCode {
    match cmd {
        LbcCommand::Decode(args) => decode::run(&args),
        LbcCommand::Encode(cmd) => encode::run(&cmd),
    }
}
