//! Hart-level primitives: global interrupt enable and the WFI idle.
//!
//! The idle closes the classic lost-wakeup window: the readiness check and the `wfi` both run
//! with `mstatus.MIE` clear, and `wfi` still returns when an interrupt that is enabled in
//! `mie` becomes pending; the handler then runs as soon as `MIE` is restored.

/// Sleeps until an interrupt is pending, unless `ready()` already reports work.
///
/// On the host (tests) this only hints a spin loop.
pub fn idle_unless(ready: impl FnOnce() -> bool) {
    #[cfg(target_arch = "riscv32")]
    riscv::interrupt::machine::free(|| {
        if !ready() {
            riscv::asm::wfi();
        }
    });
    #[cfg(not(target_arch = "riscv32"))]
    if !ready() {
        core::hint::spin_loop();
    }
}

/// Enables the machine external and timer interrupts (`mie`) and then machine-mode interrupts
/// globally (`mstatus.MIE`): the two sources every board serves.
///
/// Interrupt handlers must already be installed for both.
#[cfg(target_arch = "riscv32")]
pub(crate) fn enable_interrupts() {
    use riscv::interrupt::machine::{enable_interrupt, Interrupt};
    // SAFETY: the board installs its handlers (riscv-rt trap vector plus the `rt` dispatchers
    // for both sources) before it calls this, and every shared state they touch sits behind a
    // critical section or atomics.
    unsafe {
        enable_interrupt(Interrupt::MachineExternal);
        enable_interrupt(Interrupt::MachineTimer);
        riscv::interrupt::machine::enable();
    }
}
