//! Board-independent pieces of the UBC firmware, kept in a library so they are unit-tested on
//! the host (`cargo test --lib` in `ubc-app/`); the binary (`main.rs`) wires them to a board.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod magic;
