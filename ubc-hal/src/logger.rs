//! The defmt global logger. Encoded frames leave byte by byte through the board's transport:
//! on `qemu_virt` (feature `logger`) semihosting `SYS_WRITEC`, which QEMU sends to the chardev
//! named in `-semihosting-config enable=on,target=native,chardev=ID` (QEMU 7.2 sends `SYS_WRITE`
//! on the `:tt` handle to its own stdout instead, whatever the chardev; `SYS_WRITE0` cannot carry
//! the zero bytes that delimit defmt frames); on `softcore` (feature `console-logger`) the
//! simulation-control console register. A critical section covers each frame, so frames from
//! interrupt handlers and the program never interleave.

use core::cell::UnsafeCell;
use core::sync::atomic::{AtomicBool, Ordering};

#[cfg(feature = "logger")]
fn emit(bytes: &[u8]) {
    for &b in bytes {
        semihosting::sys::arm_compat::sys_writec(b);
    }
}

#[cfg(all(feature = "console-logger", not(feature = "logger")))]
use crate::boards::softcore::console_emit as emit;

struct State {
    encoder: defmt::Encoder,
    restore: critical_section::RestoreState,
}

struct Shared(UnsafeCell<State>);

// SAFETY: `State` is only touched between `acquire` and `release`, which hold a critical
// section (single hart: interrupts off) and the `TAKEN` flag.
unsafe impl Sync for Shared {}

static TAKEN: AtomicBool = AtomicBool::new(false);
static STATE: Shared = Shared(UnsafeCell::new(State {
    encoder: defmt::Encoder::new(),
    restore: critical_section::RestoreState::invalid(),
}));

#[defmt::global_logger]
struct Logger;

// SAFETY: frames are serialised by the critical section taken in `acquire` and released in
// `release`; `write`/`flush`/`release` are only called by defmt between those two.
unsafe impl defmt::Logger for Logger {
    fn acquire() {
        // SAFETY: paired with the `critical_section::release` in `release`.
        let restore = unsafe { critical_section::acquire() };
        if TAKEN.swap(true, Ordering::Acquire) {
            panic!("defmt logger re-entered");
        }
        // SAFETY: we hold the critical section and the `TAKEN` flag.
        let state = unsafe { &mut *STATE.0.get() };
        state.restore = restore;
        state.encoder.start_frame(emit);
    }

    unsafe fn flush() {
        // Every byte is handed to the host as soon as it is encoded.
    }

    unsafe fn release() {
        // SAFETY: called after `acquire`, which took the critical section and the flag.
        let state = unsafe { &mut *STATE.0.get() };
        state.encoder.end_frame(emit);
        let restore = state.restore;
        TAKEN.store(false, Ordering::Release);
        // SAFETY: releases the critical section `acquire` took, exactly once.
        unsafe { critical_section::release(restore) };
    }

    unsafe fn write(bytes: &[u8]) {
        // SAFETY: called between `acquire` and `release`.
        let state = unsafe { &mut *STATE.0.get() };
        state.encoder.write(bytes, emit);
    }
}
