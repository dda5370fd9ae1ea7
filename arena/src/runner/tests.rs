//! Unit tests of the runner.

use super::judge::phase_error;
use super::*;

fn at(x: f64, y: f64, heading_mrad: f64, v: f64) -> Sample {
    Sample {
        t: 0.0,
        x_mm: x,
        y_mm: y,
        heading_mrad,
        v_mm_s: v,
    }
}

const FORMATION: &str = r#"
name = "f"
duration_s = 60
[[cars]]
id = 1
x = 300
y = 400
heading_mrad = 1571
[[cars]]
id = 2
x = 300
y = 300
[[cars]]
id = 3
x = 300
y = 200
[[phases]]
kind = "formation"
shape = "line"
leader = 1
spacing_units = 100
speed_mm_s = 100
[[phases]]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
[[phases]]
kind = "circle"
centre = [300, 400]
radius_units = 100
speed_mm_s = 0
"#;

#[test]
fn phase_errors_from_true_poses() {
    let exp = Experiment::parse(FORMATION).unwrap();
    let ids = [1, 2, 3];
    // Leader at (750, 1000) mm facing +Y; slots 250 and 500 mm behind it.
    let now = [
        at(750.0, 1000.0, 1570.796, 0.0),
        at(750.0, 750.0, 0.0, 0.0),
        at(780.0, 460.0, 0.0, 0.0),
    ];
    let e = phase_error(&exp.phases[0], &ids, &now).unwrap();
    assert!((e - 50.0).abs() < 0.01, "{e}");
    // Rendezvous: spread from the centroid (750, 736.7).
    let e = phase_error(&exp.phases[1], &ids, &now).unwrap();
    assert!((e - metrics::spread(&now)).abs() < 1e-9);
    // Circle of 250 mm about (750, 1000): the leader sits on the centre.
    let e = phase_error(&exp.phases[2], &ids, &now).unwrap();
    assert!(e >= 250.0, "{e}");
}

#[test]
fn progress_line() {
    let p = Progress {
        t: 3.0,
        phase: 1,
        phases: 2,
        kind: "formation",
        error_mm: Some(48.4),
        failed: Vec::new(),
        cars: vec![
            CarProgress {
                id: 1,
                x: 300.2,
                y: 512.0,
                v_mm_s: 99.6,
                status: Some(Status {
                    group_kind: 1,
                    group_phase: 2,
                    group_converged: true,
                    ..Status::default()
                }),
            },
            CarProgress {
                id: 2,
                x: 300.0,
                y: 400.0,
                v_mm_s: 0.0,
                status: None,
            },
            CarProgress {
                id: 3,
                x: 100.0,
                y: 100.0,
                v_mm_s: 250.0,
                status: Some(Status {
                    flags: flags::MANEUVER,
                    maneuver_index: 1,
                    maneuver_len: 2,
                    ..Status::default()
                }),
            },
        ],
    };
    assert_eq!(
        p.to_string(),
        "t=  3.0s 1/2 formation  err   48 mm | car1 (300,512) v  100 track* | car2 (300,400) v    0 ? | car3 (100,100) v  250 moving 1/2"
    );
}
