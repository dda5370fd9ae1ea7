//! Stand-alone emulated LBC; the same as `almc lbc-emu`.
#![forbid(unsafe_code)]

use clap::Parser;

#[derive(Debug, Parser)]
#[command(name = "lbc-emu", version)]
struct Cli {
    #[command(flatten)]
    args: lbc_emu::cli::LbcEmuArgs,
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = lbc_emu::cli::run(cli.args) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
