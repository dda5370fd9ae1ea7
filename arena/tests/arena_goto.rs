//! Two cars in QEMU drive a go-to experiment to the end: all arrive, none collide, every
//! output parses and nothing is left running.

#[path = "arena_common.rs"]
mod common;

const TWO_CARS: &str = r#"
name = "test-two-cars"
duration_s = 30
[[cars]]
id = 1
x = 150
y = 150
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 150
heading_mrad = 1571
[maneuver]
kind = "goto"
[[maneuver.cars]]
id = 1
points = [[150, 400], [250, 500]]
[[maneuver.cars]]
id = 2
points = [[450, 400], [350, 500]]
"#;

#[test]
fn two_cars_arrive_without_collision() {
    if qemu_harness::skip_qemu_tests("two_cars_arrive_without_collision") {
        return;
    }
    let (summary, doc) = common::run_and_check(TWO_CARS, "goto");
    assert!(summary.all_arrived, "{doc:#}");
    assert!(summary.collisions.is_empty(), "{doc:#}");
    for car in &summary.cars {
        assert!(car.arrived, "car {} did not arrive", car.id);
        let err = car.final_error_mm.unwrap();
        assert!(err < 60.0, "car {}: {err} mm from the target", car.id);
        assert!(
            car.distance_mm > 600.0,
            "car {}: {} mm",
            car.id,
            car.distance_mm
        );
        assert!(car.wall_violations.is_empty());
        assert!(car.stats["lbc_line"]["stream_frames"].as_u64().unwrap() > 30);
    }
    assert!(summary.min_separation_mm.unwrap() > 200.0);
    assert_eq!(doc["cars"].as_array().unwrap().len(), 2);
    assert!(doc["radio"]["medium"]["packets_sent"].as_u64().unwrap() > 0);
}
