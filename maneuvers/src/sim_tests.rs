//! Multi-car scenarios in the simulation of `sim.rs`; the bounds asserted here are the ones
//! documented in `docs/maneuvers.md`.

use core::f32::consts::TAU;

use crate::geom::Vec2;
use crate::laws::formation::Shape;
use crate::sim::{Radio, World};
use crate::{Circle, ControllerConfig, Formation, GoTo, Phase, Rendezvous};

const SAFETY: f32 = 60.0;
const LOSSY: Radio = Radio {
    loss: 0.2,
    delay_periods: 2,
};

fn check_safe(w: &World, what: &str) {
    eprintln!(
        "{what}: t {:.2} s, min body distance {:.1} units, wall excursion {:.1}",
        w.t, w.min_distance, w.wall_excursion
    );
    assert!(
        w.min_distance > SAFETY,
        "{what}: cars came to {}",
        w.min_distance
    );
    assert!(
        w.wall_excursion <= 0.0,
        "{what}: wall excursion {}",
        w.wall_excursion
    );
}

fn rendezvous(radio: Radio, seed: u64) -> f32 {
    let p = Rendezvous::params(60, 250).unwrap();
    let mut w = World::new(radio, seed);
    w.add(1, 80.0, 100.0, 0.0, p);
    w.add(2, 520.0, 160.0, 90.0, p);
    w.add(3, 300.0, 720.0, 180.0, p);
    // A car that has heard nobody yet is trivially at its own rendezvous: judge after 0.5 s.
    let t = w.run_until(30.0, |w| {
        w.t > 0.5 && w.all_converged() && w.cars.iter().all(|c| c.speed.abs() < 1.0)
    });
    let t = t.expect("rendezvous within 30 s");
    // Stays converged and still.
    w.run_for(3.0, |_| {});
    assert!(w.all_converged());
    check_safe(&w, "rendezvous");
    let mean = w.cars.iter().fold(Vec2::ZERO, |s, c| s + c.pos) * (1.0 / 3.0);
    for c in &w.cars {
        assert!((c.pos - mean).norm() < 60.0 + crate::laws::rendezvous::BLOCK_UNITS as f32 + 5.0);
    }
    t
}

#[test]
fn rendezvous_three_cars() {
    let t = rendezvous(Radio::PERFECT, 1);
    eprintln!("rendezvous converged at {t:.2} s");
    assert!(t < 8.0);
}

#[test]
fn rendezvous_with_loss_and_delay() {
    for seed in 1..=3 {
        let t = rendezvous(LOSSY, seed);
        eprintln!("rendezvous (20% loss, 67 ms delay) converged at {t:.2} s");
        assert!(t < 8.0);
    }
}

/// Largest distance of a follower (cars 2..=4, slots by rank) from its slot behind car 1,
/// from the true poses, tracking units.
fn slot_error(w: &World, shape: Shape, spacing: f32) -> f32 {
    let offset = |k: u8| -> Vec2 {
        match shape {
            Shape::Line => Vec2::new(-(f32::from(k) + 1.0) * spacing, 0.0),
            Shape::Wedge => {
                let row = f32::from(k / 2 + 1) * spacing * core::f32::consts::FRAC_1_SQRT_2;
                Vec2::new(-row, if k.is_multiple_of(2) { row } else { -row })
            }
        }
    };
    let l = w.car(1);
    let fwd = Vec2::from_angle(l.heading);
    (2..=4u8)
        .map(|id| {
            let o = offset(id - 2);
            let target = l.pos + fwd * o.x + fwd.perp() * o.y;
            (w.car(id).pos - target).norm()
        })
        .fold(0.0, f32::max)
}

/// Line or wedge of four behind a leader driving up the arena; returns the largest slot error
/// (tracking units) over the steady part.
fn formation(shape: Shape, radio: Radio, seed: u64) -> f32 {
    let p = Formation::params(shape, 1, None, 100, 80).unwrap();
    let mut w = World::new(radio, seed);
    w.add(1, 300.0, 340.0, 90.0, p);
    w.add(2, 150.0, 120.0, 0.0, p);
    w.add(3, 450.0, 100.0, 180.0, p);
    w.add(4, 320.0, 60.0, 45.0, p);
    w.car_mut(1).ctrl.set_waypoint(300, 760);
    // Settling: 8 s; then measure while the leader cruises (it stops at about 13 s).
    w.run_for(8.0, |_| {});
    let mut worst: f32 = 0.0;
    w.run_for(4.0, |w| worst = worst.max(slot_error(w, shape, 100.0)));
    check_safe(&w, "formation");
    // Leader arrives and stops; followers settle into their slots and hold.
    let t = w.run_until(40.0, |w| {
        w.all_converged() && w.cars.iter().all(|c| c.speed.abs() < 1.0)
    });
    assert!(t.is_some(), "formation settles after the leader stops");
    assert!(slot_error(&w, shape, 100.0) < crate::laws::formation::TOLERANCE_UNITS as f32 + 2.0);
    check_safe(&w, "formation at rest");
    worst
}

#[test]
fn line_formation() {
    let e = formation(Shape::Line, Radio::PERFECT, 1);
    eprintln!("line: worst slot error while cruising {e:.1} units");
    assert!(e < 8.0);
}

#[test]
fn wedge_formation() {
    let e = formation(Shape::Wedge, Radio::PERFECT, 1);
    eprintln!("wedge: worst slot error while cruising {e:.1} units");
    assert!(e < 8.0);
}

#[test]
fn formations_with_loss_and_delay() {
    for shape in [Shape::Line, Shape::Wedge] {
        let e = formation(shape, LOSSY, 7);
        eprintln!("{shape:?} (20% loss, 67 ms delay): worst slot error {e:.1} units");
        assert!(e < 12.0);
    }
}

/// Four cars onto a circle; returns (time when all first report convergence, worst spacing
/// error afterwards in tracking units along the circle).
fn circle(radio: Radio, seed: u64) -> (f32, f32) {
    let (cx, cy, r) = (300.0, 400.0, 150.0);
    let p = Circle::params(300, 400, 150, 120).unwrap();
    let mut w = World::new(radio, seed);
    w.add(1, 100.0, 100.0, 90.0, p);
    w.add(2, 200.0, 150.0, 0.0, p);
    w.add(3, 500.0, 650.0, 270.0, p);
    w.add(4, 420.0, 420.0, 180.0, p);
    let t = w
        .run_until(40.0, |w| w.all_converged())
        .expect("circle within 40 s");
    let mut worst: f32 = 0.0;
    w.run_for(15.0, |w| {
        let mut angles: Vec<f32> = w
            .cars
            .iter()
            .map(|c| (c.pos - Vec2::new(cx, cy)).angle().rem_euclid(TAU))
            .collect();
        angles.sort_by(f32::total_cmp);
        for i in 0..angles.len() {
            let next = if i + 1 < angles.len() {
                angles[i + 1]
            } else {
                angles[0] + TAU
            };
            worst = worst.max(((next - angles[i]) - TAU / 4.0).abs() * r);
        }
        for c in &w.cars {
            worst = worst.max(((c.pos - Vec2::new(cx, cy)).norm() - r).abs());
        }
    });
    check_safe(&w, "circle");
    (t, worst)
}

#[test]
fn circle_four_cars() {
    let (t, e) = circle(Radio::PERFECT, 1);
    eprintln!("circle: converged at {t:.2} s, worst spacing/radius error {e:.1} units");
    assert!(t < 15.0);
    assert!(e < 25.0);
}

#[test]
fn circle_with_loss_and_delay() {
    let (t, e) = circle(LOSSY, 3);
    eprintln!("circle (20% loss, 67 ms delay): converged at {t:.2} s, worst error {e:.1} units");
    assert!(t < 15.0);
    assert!(e < 25.0);
}

#[test]
fn goto_beyond_wall_stops_inside() {
    let p = GoTo::params(700, 900, 400).unwrap();
    let mut w = World::new(Radio::PERFECT, 1);
    w.add(1, 300.0, 400.0, 30.0, p);
    // Head straight at the corner; the goal is clamped and the wall gate holds.
    w.run_for(12.0, |_| {});
    check_safe(&w, "goto corner");
    assert!(w.car(1).speed.abs() < 1.0);
    // Arrived at the goal moved inside the walls, (542, 742).
    assert!(w.all_converged());
    assert!((w.car(1).pos - Vec2::new(542.0, 742.0)).norm() < 3.0 * 8.0);
}

#[test]
fn cars_driving_at_each_other_pass_safely() {
    // Two cars swap places head-on, with lossy radio; a third crosses.
    let mut w = World::new(LOSSY, 5);
    let go = |x, y| GoTo::params(x, y, 300).unwrap();
    w.add(1, 300.0, 150.0, 90.0, go(300, 650));
    w.add(2, 300.0, 650.0, 270.0, go(300, 150));
    w.add(3, 100.0, 400.0, 0.0, go(500, 400));
    let t = w.run_until(30.0, |w| w.all_converged());
    check_safe(&w, "head-on");
    assert!(t.is_some_and(|t| t < 20.0), "all three arrive");
    eprintln!("head-on swap done at {:.2} s", t.unwrap_or(0.0));
}

#[test]
fn follower_stops_when_leader_goes_silent() {
    let p = Formation::params(Shape::Line, 1, None, 100, 100).unwrap();
    let mut w = World::new(Radio::PERFECT, 1);
    w.add(1, 300.0, 300.0, 90.0, p);
    w.add(2, 300.0, 100.0, 90.0, p);
    w.run_for(1.0, |_| {});
    assert!(w.car(2).speed > 50.0);
    // The leader's radio dies: make every delivery fail from now on.
    w.silence(1);
    w.run_for(1.5, |_| {});
    let out = w.car(2).last.expect("stepped");
    assert_eq!(out.status.phase, Phase::NoReference);
    assert!(w.car(2).speed.abs() < 1.0);
}

/// The same swap as above with avoidance switched off collides: the check above can fail.
#[test]
fn without_avoidance_cars_collide() {
    let mut w = World::new(Radio::PERFECT, 5);
    let mut cfg = ControllerConfig::default();
    cfg.safety.safety_radius_units = 0;
    cfg.safety.guard_units = 0;
    cfg.safety.influence_units = 1;
    w.set_config(cfg);
    let go = |x, y| GoTo::params(x, y, 300).unwrap();
    w.add(1, 300.0, 150.0, 90.0, go(300, 650));
    w.add(2, 300.0, 650.0, 270.0, go(300, 150));
    w.run_for(5.0, |_| {});
    assert!(w.min_distance < 10.0, "{}", w.min_distance);
}

/// A wedge behind a leader that drives north, then turns 90 degrees east: the worst slot
/// error (true poses) during the turn, and once the leader stops.
#[test]
fn wedge_follows_a_turn() {
    let p = Formation::params(Shape::Wedge, 1, None, 100, 80).unwrap();
    let mut w = World::new(LOSSY, 11);
    w.add(1, 300.0, 330.0, 90.0, p);
    w.add(2, 230.0, 260.0, 90.0, p);
    w.add(3, 370.0, 260.0, 90.0, p);
    w.add(4, 160.0, 190.0, 90.0, p);
    w.car_mut(1).ctrl.set_waypoint(300, 480);
    let mut turned = false;
    let mut worst: f32 = 0.0;
    while w.t < 40.0 {
        w.step();
        let leader_done = w.car(1).last.is_some_and(|o| o.status.phase == Phase::Hold);
        if leader_done && !turned {
            turned = true;
            w.car_mut(1).ctrl.set_waypoint(540, 480);
        } else if leader_done && w.all_converged() && w.cars.iter().all(|c| c.speed.abs() < 1.0) {
            break;
        }
        if turned {
            worst = worst.max(slot_error(&w, Shape::Wedge, 100.0));
        }
    }
    check_safe(&w, "wedge turn");
    assert!(turned && w.t < 40.0, "the wedge settles after the turn");
    let at_rest = slot_error(&w, Shape::Wedge, 100.0);
    eprintln!(
        "wedge turn: worst slot error {worst:.1} units, at rest {at_rest:.1}, t {:.1} s",
        w.t
    );
    assert!(worst < 120.0);
    assert!(at_rest < crate::laws::formation::TOLERANCE_UNITS as f32 * 1.5 + 2.0);
}

/// A seeded random start: rendezvous of 3 (even trials) or circle of 4 (odd trials) cars at
/// scattered poses at least 120 units apart, with a lossy radio.
fn random_world(trial: u64) -> World {
    let mut rng = 0x1234_5678_9abc_def1u64 ^ trial.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    let mut next = move |lo: f32, hi: f32| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        lo + (hi - lo) * ((rng >> 40) as f32 / (1u64 << 24) as f32)
    };
    let (params, cars) = if trial.is_multiple_of(2) {
        (Rendezvous::params(60, 300).unwrap(), 3)
    } else {
        (Circle::params(300, 400, 160, -100).unwrap(), 4)
    };
    let mut w = World::new(LOSSY, trial + 100);
    let mut placed: Vec<Vec2> = Vec::new();
    while placed.len() < cars {
        let p = Vec2::new(next(60.0, 540.0), next(60.0, 740.0));
        if placed.iter().all(|q| (*q - p).norm() > 120.0) {
            placed.push(p);
            let id = u8::try_from(placed.len()).unwrap_or(u8::MAX);
            w.add(id, p.x, p.y, next(0.0, 360.0), params);
        }
    }
    w
}

/// Random starts never collide or touch a wall, and always converge. `MANEUVER_TRIALS=3000`
/// runs a longer soak than the default 16 trials.
#[test]
fn random_starts_are_safe() {
    let mut worst_t: f32 = 0.0;
    let trials: u64 = std::env::var("MANEUVER_TRIALS").map_or(16, |s| s.parse().unwrap_or(16));
    for trial in 0..trials {
        let mut w = random_world(trial);
        let t = w.run_until(40.0, |w| w.t > 0.5 && w.all_converged());
        check_safe(&w, "random start");
        let t = t.unwrap_or_else(|| panic!("trial {trial} did not converge"));
        worst_t = worst_t.max(t);
        // Keep going: still safe afterwards.
        w.run_for(5.0, |_| {});
        check_safe(&w, "random start, afterwards");
    }
    eprintln!("random starts: slowest convergence {worst_t:.2} s");
    assert!(worst_t < 25.0);
}

/// A go-to point straight behind the car: with reverse allowed it backs all the way, with
/// `turn` it backs up only to turn round, with `never` it turns round forward; all arrive.
#[test]
fn reverse_modes_turn_round() {
    use crate::{Overrides, Reverse};
    for (mode, most_reverse_s) in [
        (Reverse::Allowed, 10.0),
        (Reverse::Turn, 2.0),
        (Reverse::Never, 0.0),
    ] {
        let p = GoTo::params(300, 200, 200)
            .unwrap()
            .with_overrides(Overrides {
                reverse: Some(mode),
                ..Overrides::default()
            });
        let mut w = World::new(Radio::PERFECT, 1);
        w.add(1, 300.0, 500.0, 90.0, p);
        let mut reversing = 0.0;
        let t = w.run_until(30.0, |w| w.all_converged() && w.car(1).speed.abs() < 1.0);
        let t = t.unwrap_or_else(|| panic!("{mode:?}: did not arrive"));
        // Replay to measure the time spent backing up.
        let mut w2 = World::new(Radio::PERFECT, 1);
        w2.add(1, 300.0, 500.0, 90.0, p);
        w2.run_for(t, |w| {
            if w.car(1).speed < -1.0 {
                reversing += 1.0 / crate::sim::CONTROL_HZ;
            }
        });
        eprintln!("{mode:?}: arrived at {t:.2} s, {reversing:.2} s in reverse");
        check_safe(&w, mode.name());
        if mode == Reverse::Allowed {
            assert!(reversing > 1.0);
        }
        assert!(
            reversing <= most_reverse_s,
            "{mode:?}: {reversing} s in reverse"
        );
    }
}
