//! UBC firmware. Brings the board up, logs a banner over defmt and, until the real program
//! exists, runs the test mode (see [`test_mode`]) that the QEMU harness checks.
//!
//! Built once per board, selected by a cargo feature (`qemu_virt`); `cargo xtask fw` builds it.

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

mod test_mode;

#[cfg(feature = "qemu_virt")]
use ubc_hal::boards::qemu_virt as board;

#[cfg(not(feature = "qemu_virt"))]
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
    test_mode::run(board)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    static PANICKING: AtomicBool = AtomicBool::new(false);
    // A panic while reporting a panic (e.g. inside the logger) must not recurse.
    if !PANICKING.swap(true, Ordering::AcqRel) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    board::exit_device().fail(EXIT_PANIC)
}
