//! The example law of `docs/writing-a-law.md` in QEMU (`platoon.rs` runs it on the soft core's
//! model).

#[path = "examples_common.rs"]
mod examples;

/// In QEMU, in real time.
#[test]
fn platoon_in_qemu() {
    if qemu_harness::skip_qemu_tests("platoon_in_qemu") {
        return;
    }
    examples::run_platoon("qemu");
}
