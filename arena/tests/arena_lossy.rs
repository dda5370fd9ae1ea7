//! Three cars in QEMU complete a go-to experiment through 20 % radio loss, noisy tracking and
//! a noisy LBC line.

#[path = "arena_common.rs"]
mod common;

const LOSSY: &str = r#"
name = "test-lossy"
duration_s = 40
seed = 3
[[cars]]
id = 1
x = 100
y = 150
heading_mrad = 1571
[[cars]]
id = 2
x = 300
y = 150
heading_mrad = 1571
[[cars]]
id = 3
x = 500
y = 150
heading_mrad = 1571
[maneuver]
kind = "goto"
[[maneuver.cars]]
id = 1
points = [[100, 450]]
[[maneuver.cars]]
id = 2
points = [[300, 500]]
[[maneuver.cars]]
id = 3
points = [[500, 450]]
[faults]
radio_loss = 0.2
tracking_noise_mm = 3.0
tracking_drop = 0.05
[faults.lbc]
drop = 0.0002
"#;

#[test]
fn three_cars_complete_through_radio_loss() {
    if qemu_harness::skip_qemu_tests("three_cars_complete_through_radio_loss") {
        return;
    }
    let (summary, doc) = common::run_and_check(LOSSY, "lossy");
    assert!(summary.all_arrived, "{doc:#}");
    assert!(summary.collisions.is_empty(), "{doc:#}");
    assert!(doc["radio"]["medium"]["random_losses"].as_u64().unwrap() > 0);
    for car in &summary.cars {
        assert!(car.final_error_mm.unwrap() < 80.0, "{doc:#}");
        assert!(car.tracking["dropped"].as_u64().unwrap() > 0);
    }
}
