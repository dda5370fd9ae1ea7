//! The example program of `docs/writing-a-program.md` in QEMU (`program_square.rs` runs it on
//! the soft core's model).

#[path = "examples_common.rs"]
mod examples;

/// In QEMU, in real time.
#[test]
fn square_program_in_qemu() {
    if qemu_harness::skip_qemu_tests("square_program_in_qemu") {
        return;
    }
    examples::run_square("qemu");
}
