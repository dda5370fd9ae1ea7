//! Drivers and board support for the ALMC upper board (UBC), a RISC-V soft core in machine
//! mode. This is the only crate of the project with `unsafe` code: register access, CSRs,
//! the interrupt handlers and the semihosting logger.
//!
//! Drivers reach their registers through [`mmio::RegisterBus`], so their logic (register
//! layouts, ring buffers, PCI decoding, divisor and time arithmetic) is tested on the host
//! against device models. A board module (`boards::qemu_virt`, feature `qemu_virt`) is the
//! only code that knows addresses; it brings the machine up and hands out the drivers.
//!
//! Features: `qemu_virt` (board), `defmt` (`defmt::Format` on driver types), `logger` (defmt
//! global logger over semihosting, riscv32 only), `rt` (riscv-rt interrupt and exception
//! handlers and the prologue/epilogue register save routines, riscv32 only).

#![cfg_attr(not(test), no_std)]

pub mod boards;
pub mod clint;
pub mod cpu;
pub mod exit;
pub mod framegrabber;
#[cfg(all(
    any(feature = "logger", feature = "console-logger"),
    target_arch = "riscv32"
))]
mod logger;
pub mod mmio;
pub mod pci;
pub mod plic;
pub mod ring;
#[cfg(all(feature = "rt", target_arch = "riscv32"))]
mod save_restore;
pub mod serial;
pub mod uart;
pub mod vision_unit;

pub use embedded_hal_nb;
pub use embedded_io;
