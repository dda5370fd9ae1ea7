//! Board-independent pieces of the UBC firmware, kept in a library so they are tested on the
//! host (`cargo test` in `ubc-app/`); the binary (`main.rs`) wires them to a board.
//!
//! - [`program`]: the UBC demo program (LBC bring-up, console over the radio, safety), sans-IO.
//! - [`magic`]: byte-sequence detection used by the echo test mode.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod magic;
pub mod program;
