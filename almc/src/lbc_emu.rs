//! `almc lbc-emu`: an emulated lower board (LBC) behind a Unix or TCP socket, for developing
//! upper-board software with no car on the desk. The emulator itself is the `lbc-emu` crate.

use std::process::ExitCode;

/// Arguments of `almc lbc-emu` (see `almc lbc-emu --help`).
pub type Args = ::lbc_emu::cli::LbcEmuArgs;

/// Runs the emulator until SIGINT/SIGTERM; a bad EEPROM file or socket is a non-zero exit.
pub fn run(args: Args) -> ExitCode {
    match ::lbc_emu::cli::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
