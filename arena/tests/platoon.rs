//! The example law of `docs/writing-a-law.md` (`maneuvers/src/laws/platoon.rs`) in its
//! experiment (`experiments/platoon-four.toml`) on the soft core's model: the leader reaches
//! its last waypoint and every other car ends in single file behind the car ahead of it, the
//! gap kept, without a collision. `platoon_qemu.rs` runs it in QEMU.

#[path = "examples_common.rs"]
mod examples;

/// On the soft core's model in virtual time.
#[test]
fn platoon_on_the_soft_core() {
    examples::run_platoon("iss");
}
