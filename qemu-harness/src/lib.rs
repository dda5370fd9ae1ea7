//! Boots the UBC firmware in `qemu-system-riscv32 -M virt` for tests and tooling.
//!
//! The LBC UART (built-in NS16550A) and the radio UART (`pci-serial`) are Unix sockets in
//! a private temp dir (or sockets the caller names); the firmware's defmt log leaves
//! through semihosting on QEMU's stdout and is decoded with the ELF's `.defmt` table.
//! Every wait has a timeout, and dropping a [`Qemu`] always kills and reaps the emulator.
//!
//! ```no_run
//! use std::time::Duration;
//! use qemu_harness::{firmware_elf, Level, Qemu};
//!
//! let mut qemu = Qemu::builder(firmware_elf()?).spawn()?;
//! qemu.wait_for_log(|l| l.is(Level::Info, "ubc-app"), Duration::from_secs(10))?;
//! let lbc = qemu.lbc().expect("harness-attached by default");
//! lbc.write_all(b"ping")?;
//! let mut back = [0u8; 4];
//! lbc.read_exact_timeout(&mut back, Duration::from_secs(5))?;
//! # Ok::<(), qemu_harness::Error>(())
//! ```

#![forbid(unsafe_code)]

mod config;
mod error;
mod firmware;
mod log;
mod qemu;
mod shared_ram;
mod spec;
mod uart;

pub use config::{QemuBuilder, QemuConfig, LBC_CHARDEV, RADIO_CHARDEV};
pub use error::Error;
pub use firmware::{
    echo_test_elf, find_qemu, firmware_elf, program_elf, skip_qemu_tests, softcore_elf,
    workspace_root, FW_ECHO_ELF_ENV, FW_ELF_ENV, QEMU_ENV, SKIP_ENV, SOFTCORE_ELF_ENV,
};
pub use log::{Level, LineDecoder, Log, LogFormat, LogLine, DEFAULT_LOG_CAPACITY};
pub use qemu::Qemu;
pub use shared_ram::{SharedRam, SharedRamSpec, FRAME_WINDOW_OFFSET, RAM_BASE, SHARED_RAM_MIB};
pub use spec::{SocketSpec, SocketSpecError, UartAttach};
pub use uart::{Uart, DEFAULT_WRITE_TIMEOUT};

/// `timeout` from now, or as far ahead as the clock goes: a caller's huge timeout (say
/// `Duration::MAX` for "forever") must not overflow `Instant` and panic.
pub(crate) fn deadline_after(timeout: std::time::Duration) -> std::time::Instant {
    let now = std::time::Instant::now();
    now.checked_add(timeout)
        .or_else(|| now.checked_add(std::time::Duration::from_secs(100 * 365 * 24 * 3600)))
        .unwrap_or(now)
}
