//! The UBC firmware as a library: the board-independent pieces, tested on the host (`cargo
//! test` in `ubc-app/`), and the board layer the firmware binaries (`main.rs`, `src/bin/`)
//! start.
//!
//! - [`program`]: the UBC demo program (LBC bring-up, console over the radio, safety), sans-IO.
//! - [`magic`]: byte-sequence detection used by the echo test mode.
//! - `firmware` (feature `firmware`, riscv32 only): the board layer every firmware binary
//!   runs on.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

#[cfg(all(feature = "firmware", target_arch = "riscv32"))]
pub mod firmware;
pub mod magic;
pub mod program;
