//! The stock UBC firmware: the program of [`ubc_app::program`] on the board layer of
//! [`ubc_app::firmware`], or with the `echo-test` feature the UART echo test mode
//! (`test_mode`) that the QEMU driver acceptance tests check.
//!
//! Built once per board, selected by a cargo feature (`qemu_virt` or `softcore`); `cargo xtask
//! fw` builds it. A researcher's own program is a binary like this one in `src/bin/`
//! (`cargo xtask new-program NAME`).

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

#[cfg(feature = "echo-test")]
mod test_mode;

#[riscv_rt::entry]
fn main() -> ! {
    #[cfg(feature = "echo-test")]
    {
        test_mode::run(ubc_app::firmware::take_board())
    }
    #[cfg(not(feature = "echo-test"))]
    {
        ubc_app::firmware::start(ubc_app::program::user::NoProgram)
    }
}

/// The echo test mode reports the full message (the harness checks it).
#[cfg(feature = "echo-test")]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    use core::sync::atomic::{AtomicBool, Ordering};
    static PANICKING: AtomicBool = AtomicBool::new(false);
    if !PANICKING.swap(true, Ordering::AcqRel) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
    }
    ubc_app::firmware::board::exit_device().fail(ubc_app::firmware::EXIT_PANIC)
}

#[cfg(not(feature = "echo-test"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ubc_app::firmware::panic(info)
}
