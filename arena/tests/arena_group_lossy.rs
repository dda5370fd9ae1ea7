//! The demo's sequence (wedge formation, break-up to the corners, rendezvous) with four cars
//! in QEMU through 20 % radio loss, noisy and lossy tracking and a noisy LBC line: every
//! phase still completes, without collision.

#[path = "arena_common.rs"]
mod common;

const LOSSY: &str = r#"
name = "test-group-lossy"
duration_s = 100
seed = 5
[[cars]]
id = 1
x = 300
y = 330
heading_mrad = 1571
[[cars]]
id = 2
x = 130
y = 240
heading_mrad = 0
[[cars]]
id = 3
x = 470
y = 240
heading_mrad = 3142
[[cars]]
id = 4
x = 300
y = 110
heading_mrad = 1571

[[phases]]
kind = "formation"
shape = "wedge"
leader = 1
spacing_units = 150
speed_mm_s = 100
waypoints = [[300, 480], [300, 620]]
timeout_s = 40

[[phases]]
kind = "goto"
speed_mm_s = 200
timeout_s = 30
[[phases.cars]]
id = 1
points = [[300, 730]]
[[phases.cars]]
id = 2
points = [[80, 620]]
[[phases.cars]]
id = 3
points = [[520, 620]]
[[phases.cars]]
id = 4
points = [[300, 180]]

[[phases]]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
timeout_s = 30

[faults]
radio_loss = 0.2
tracking_noise_mm = 2.0
tracking_drop = 0.03
[faults.lbc]
drop = 0.0002
"#;

#[test]
fn group_maneuvers_complete_through_radio_loss() {
    if qemu_harness::skip_qemu_tests("group_maneuvers_complete_through_radio_loss") {
        return;
    }
    let o = common::run_full(LOSSY, "group-lossy");
    let (s, doc) = (&o.summary, &o.doc);
    for p in &s.phases {
        eprintln!(
            "phase {} {}: completed {} converged {:?} s, final error {:?} mm, retries {}",
            p.phase, p.kind, p.completed, p.converged_s, p.final_error_mm, p.command_retries
        );
    }
    eprintln!("min separation {:?} mm", s.min_separation_mm);
    assert_eq!(s.phases.len(), 3, "{doc:#}");
    for p in &s.phases {
        assert!(p.completed, "phase {} did not complete: {doc:#}", p.phase);
    }
    assert!(s.completed && s.all_arrived, "{doc:#}");
    assert!(s.collisions.is_empty(), "{doc:#}");
    assert!(doc["radio"]["medium"]["random_losses"].as_u64().unwrap() > 100);
    for car in &s.cars {
        assert!(car.wall_violations.is_empty(), "{doc:#}");
        assert!(car.tracking["dropped"].as_u64().unwrap() > 0);
    }
}
