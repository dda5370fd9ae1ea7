//! Acceptance: `!ubc-panic!` on the LBC UART makes the firmware panic, log the reason at
//! error level and end QEMU with exit status 1.

use std::time::Duration;

use qemu_harness::Level;

mod common;

const PANIC_MESSAGE: &str = "deliberate panic requested on lbc uart";

#[test]
fn panic_request_on_lbc_exits_with_status_1() {
    let Some((mut qemu, _banner)) = common::boot(
        "panic_request_on_lbc_exits_with_status_1",
        common::Firmware::EchoTest,
    ) else {
        return;
    };
    qemu.lbc()
        .expect("lbc attached")
        .write_all(b"!ubc-panic!")
        .expect("write panic request");
    let status = qemu
        .wait_exit(Duration::from_secs(15))
        .unwrap_or_else(|e| panic!("{e}; log so far: {:#?}", qemu.log().lines()));
    assert_eq!(status.code(), Some(1), "QEMU status {status}");
    let line = qemu
        .wait_for_log(
            |l| l.is(Level::Error, PANIC_MESSAGE),
            Duration::from_secs(5),
        )
        .unwrap_or_else(|e| panic!("{e}; log: {:#?}", qemu.log().lines()));
    eprintln!("panic: {line}");
}
