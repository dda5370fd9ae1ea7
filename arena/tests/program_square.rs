//! The example program of `docs/writing-a-program.md` (`ubc-app/src/bin/square.rs`) in its
//! experiment (`experiments/program-square.toml`) on the soft core's model: every car, running
//! the program instead of the stock firmware, drives its square (within 40 mm of each corner)
//! and stops back at its start. `program_square_qemu.rs` runs it in QEMU.

#[path = "examples_common.rs"]
mod examples;

/// On the soft core's model in virtual time.
#[test]
fn square_program_on_the_soft_core() {
    examples::run_square("iss");
}
