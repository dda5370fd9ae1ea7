//! Shared start-up for the end-to-end tests against the real firmware.

// Each test binary compiles this module and uses only part of it.
#![allow(dead_code)]

use std::time::Duration;

use std::path::PathBuf;

use qemu_harness::{echo_test_elf, firmware_elf, skip_qemu_tests, Error, Level, LogLine, Qemu};

/// Bound on boot: QEMU start plus the firmware's banner.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(20);

/// Which firmware build a test boots.
#[derive(Debug, Clone, Copy)]
pub enum Firmware {
    /// The UBC program (`UBC_FW_ELF`).
    Program,
    /// The UART echo test mode (`UBC_FW_ECHO_ELF`): echo, one-second ticks, panic on request.
    EchoTest,
}

/// Boots `firmware` with both UARTs attached to the harness and waits for the banner;
/// `None` when `UBC_SKIP_QEMU=1`. A missing QEMU or firmware fails the test.
pub fn boot(test: &str, firmware: Firmware) -> Option<(Qemu, LogLine)> {
    if skip_qemu_tests(test) {
        return None;
    }
    let elf: Result<PathBuf, Error> = match firmware {
        Firmware::Program => firmware_elf(),
        Firmware::EchoTest => echo_test_elf(),
    };
    let elf = elf.unwrap_or_else(|e| panic!("{test}: no firmware: {e}"));
    let qemu = Qemu::builder(&elf)
        .spawn()
        .unwrap_or_else(|e| panic!("{test}: cannot start QEMU: {e}"));
    let banner = qemu
        .wait_for_log(is_banner, BOOT_TIMEOUT)
        .unwrap_or_else(|e| {
            panic!(
                "{test}: no boot banner: {e}\nQEMU stderr:\n{}",
                qemu.stderr_text()
            )
        });
    Some((qemu, banner))
}

/// `INFO ubc-app {version} board={board} timebase={hz} Hz`
pub fn is_banner(line: &LogLine) -> bool {
    line.level == Some(Level::Info)
        && line.message.starts_with("ubc-app ")
        && line.field("board").is_some()
        && line.field("timebase").is_some()
}
