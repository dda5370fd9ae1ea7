// Shared by the tests of the tutorials' examples (included with `#[path]`, not a test of its
// own): the example program `square` (`docs/writing-a-program.md`) and the example law
// `platoon` (`docs/writing-a-law.md`) in their experiments. Each engine's run is a test file
// of its own, so that no two runs share a process (the checks look for leftover QEMUs).
#![allow(dead_code)]

#[path = "arena_common.rs"]
mod common;

use arena::world::EngineKind;

const SQUARE: &str = include_str!("../../experiments/program-square.toml");

/// Side of the square in the experiment, mm (160 units).
const SIDE_MM: f64 = 400.0;

pub fn run_square(engine: &str) {
    let text = SQUARE.replace("seed = 1", &format!("seed = 1\nengine = \"{engine}\""));
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

const PLATOON: &str = include_str!("../../experiments/platoon-four.toml");

/// The experiment's gap, mm (120 units).
const GAP_MM: f64 = 300.0;

pub fn run_platoon(engine: &str) {
    let text = PLATOON.replace("seed = 1", &format!("seed = 1\nengine = \"{engine}\""));
    let exp = arena::experiment::Experiment::parse(&text).unwrap();
    assert_eq!(exp.phases[0].kind.name(), "platoon");
    let o = common::run_full(&text, &format!("platoon-{engine}"));
    let doc = &o.doc;
    assert!(o.summary.collisions.is_empty(), "{doc:#}");
    // Every car drove under the law.
    for r in &o.summary.cars {
        assert!(r.distance_mm > 200.0, "car {} did not drive: {doc:#}", r.id);
    }
    // QEMU runs in real time: when the machine stalls for longer than the firmware's stream
    // timeout, cars stop for safety (and say so), and the platoon is then not judged; on the
    // soft core's model (virtual time) that cannot happen.
    let stalls = o.stalls();
    if engine == "qemu" && !stalls.is_empty() {
        eprintln!("the machine stalled: cars stopped at {stalls:?} s; the platoon is not judged");
        return;
    }
    assert!(o.summary.completed, "{doc:#}");
    let phase = &o.summary.phases[0];
    assert_eq!(phase.waypoints_sent, 2, "{doc:#}");
    assert!(phase.reported_converged_s.is_some(), "{doc:#}");
    let end: Vec<(f64, f64)> = o
        .tracks
        .iter()
        .map(|t| {
            let &(_, x, y) = t.last().unwrap();
            (x, y)
        })
        .collect();
    // The leader at its last waypoint (460, 700) units.
    let (lx, ly) = end[0];
    assert!(
        (lx - 1150.0).hypot(ly - 1750.0) < 60.0,
        "leader at ({lx}, {ly})"
    );
    for k in 1..end.len() {
        let ((ax, ay), (x, y)) = (end[k - 1], end[k]);
        let gap = (ax - x).hypot(ay - y);
        assert!(
            (gap - GAP_MM).abs() < 60.0,
            "car {} is {gap:.0} mm behind the car ahead",
            k + 1
        );
        // Behind, not beside: the platoon ends heading north.
        assert!(ay - y > 0.8 * GAP_MM, "car {} at ({x:.0}, {y:.0})", k + 1);
    }
    assert!(o.summary.min_separation_mm.unwrap() > 150.0, "{doc:#}");
}
