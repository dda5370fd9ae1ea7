//! The example program of `docs/writing-a-program.md` (`ubc-app/src/bin/square.rs`) in its
//! experiment (`experiments/program-square.toml`), on both car engines: every car, running
//! the program instead of the stock firmware, drives its square (within 40 mm of each corner)
//! and stops back at its start.

#[path = "arena_common.rs"]
mod common;

use arena::world::EngineKind;

const EXPERIMENT: &str = include_str!("../../experiments/program-square.toml");

/// Side of the square in the experiment, mm (160 units).
const SIDE_MM: f64 = 400.0;

fn run_square(engine: &str) {
    let text = EXPERIMENT.replace("seed = 1", &format!("seed = 1\nengine = \"{engine}\""));
    let exp = arena::experiment::Experiment::parse(&text).unwrap();
    assert_eq!(
        exp.engine,
        if engine == "qemu" {
            EngineKind::Qemu
        } else {
            EngineKind::Iss
        }
    );
    let o = common::run_full(&text, &format!("square-{engine}"));
    let doc = &o.doc;
    assert!(o.summary.completed, "{doc:#}");
    assert!(o.summary.collisions.is_empty(), "{doc:#}");
    assert!(o.summary.all_arrived, "{doc:#}");
    for (car, track) in exp.cars.iter().zip(&o.tracks) {
        // Heading 0: the square goes along +X, then +Y.
        let (x0, y0) = (f64::from(car.x) * 2.5, f64::from(car.y) * 2.5);
        let corners = [
            (x0 + SIDE_MM, y0),
            (x0 + SIDE_MM, y0 + SIDE_MM),
            (x0, y0 + SIDE_MM),
        ];
        let mut last_visit = 0.0;
        for (cx, cy) in corners {
            let (closest, t) = track
                .iter()
                .map(|&(t, x, y)| ((x - cx).hypot(y - cy), t))
                .fold((f64::MAX, 0.0), |a, b| if b.0 < a.0 { b } else { a });
            assert!(
                closest < 40.0,
                "car {}: {closest:.0} mm from corner ({cx}, {cy})",
                car.id
            );
            assert!(t > last_visit, "car {}: corners out of order", car.id);
            last_visit = t;
        }
        let &(_, x, y) = track.last().unwrap();
        let home = (x - x0).hypot(y - y0);
        assert!(
            home < 40.0,
            "car {} ended {home:.0} mm from its start",
            car.id
        );
        let r = o.summary.cars.iter().find(|r| r.id == car.id).unwrap();
        assert!(r.arrived && r.distance_mm > 3.0 * SIDE_MM, "{doc:#}");
    }
    assert!(o.events.iter().any(|e| e["event"]
        .as_str()
        .is_some_and(|s| s.contains("ManeuverDone"))));
}

/// On the soft core's model in virtual time.
#[test]
fn square_program_on_the_soft_core() {
    run_square("iss");
}

/// In QEMU, in real time.
#[test]
fn square_program_in_qemu() {
    if qemu_harness::skip_qemu_tests("square_program_in_qemu") {
        return;
    }
    run_square("qemu");
}
