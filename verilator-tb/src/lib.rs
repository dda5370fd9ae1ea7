//! The in-house RV32IMAC soft core and its SoC (Verilog in `rtl/`), Verilated at build time and
//! driven from Rust: a cycle-level harness with UART stimulus ([`soc`]), a golden
//! instruction-set model ([`golden`]) and a lockstep checker that compares every retired
//! instruction of the RTL with the model ([`lockstep`]), and a co-simulation of the SoC with
//! the emulated lower board on its LBC UART ([`cosim`]); and an estimate of what pipelined
//! designs of the core would cost in cycles on a run's instruction stream ([`pipeline`]). See
//! `docs/soft-core.md`.
#![forbid(unsafe_code)]

pub mod cosim;
pub mod golden;
pub mod isa;
pub mod lockstep;
mod model;
pub mod pipeline;
pub mod soc;
