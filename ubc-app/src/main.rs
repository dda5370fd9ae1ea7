//! UBC firmware. Brings the board up, logs a banner over defmt and runs the UBC program
//! (`run`, on top of the library's `program`), or with the `echo-test` feature the UART echo
//! test mode (`test_mode`) that the QEMU driver acceptance tests check.
//!
//! Built once per board, selected by a cargo feature (`qemu_virt` or `softcore`); `cargo xtask fw` builds it.

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

#[cfg(not(feature = "echo-test"))]
mod run;
#[cfg(feature = "echo-test")]
mod test_mode;

#[cfg(feature = "qemu_virt")]
use ubc_hal::boards::qemu_virt as board;

#[cfg(feature = "softcore")]
use ubc_hal::boards::softcore as board;

#[cfg(not(any(feature = "qemu_virt", feature = "softcore")))]
compile_error!("select a board with a cargo feature, e.g. `--features qemu_virt`");

use core::sync::atomic::{AtomicBool, Ordering};

/// Firmware version (the crate version).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// Exit status reported when the firmware panics.
pub const EXIT_PANIC: u16 = 1;
/// Exit status reported when the board cannot be brought up.
pub const EXIT_BOARD: u16 = 4;

#[riscv_rt::entry]
fn main() -> ! {
    let board = match board::Board::take() {
        Ok(board) => board,
        Err(e) => {
            defmt::error!("board bring-up failed: {}", e);
            board::exit_device().fail(EXIT_BOARD)
        }
    };
    defmt::info!(
        "ubc-app {=str} board={=str} timebase={=u32} Hz",
        VERSION,
        board::NAME,
        board.clock.hz()
    );
    #[cfg(feature = "qemu_virt")]
    match (&board.radio, &board.radio_info) {
        (Ok(_), Some(info)) => defmt::info!(
            "radio uart: pci-serial at {=usize:#x} (slot {=u8}, pin {}, PLIC source {=u32})",
            info.device.cpu_address,
            info.device.bdf.device,
            info.device.pin,
            info.plic_source
        ),
        (Err(e), _) => defmt::warn!("radio uart unavailable: {}", e),
        _ => {}
    }
    #[cfg(feature = "softcore")]
    if let Err(e) = &board.radio {
        defmt::warn!("radio uart unavailable: {}", e);
    }
    #[cfg(feature = "echo-test")]
    {
        test_mode::run(board)
    }
    #[cfg(not(feature = "echo-test"))]
    {
        run::run(board)
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    static PANICKING: AtomicBool = AtomicBool::new(false);
    // A panic while reporting a panic (e.g. inside the logger) must not recurse.
    if !PANICKING.swap(true, Ordering::AcqRel) {
        log_panic(info);
    }
    board::exit_device().fail(EXIT_PANIC)
}

/// The echo test mode reports the full message (the harness checks it).
#[cfg(feature = "echo-test")]
fn log_panic(info: &core::panic::PanicInfo) {
    defmt::error!("panic: {}", defmt::Display2Format(info));
}

/// The program reports the message when it is plain text, and the location; formatting a
/// message with arguments would pull `core::fmt` (several KiB) into the image.
#[cfg(not(feature = "echo-test"))]
fn log_panic(info: &core::panic::PanicInfo) {
    let message = info.message().as_str().unwrap_or("(formatted message)");
    match info.location() {
        Some(l) => defmt::error!(
            "panic: {=str} at {=str}:{=u32}",
            message,
            l.file(),
            l.line()
        ),
        None => defmt::error!("panic: {=str}", message),
    }
}
