//! Measures of an experiment's trajectories: distance travelled, final error to a target,
//! closest approach between cars, collisions and wall violations.
//!
//! Every car is sampled at the same instants, so sample `k` of each trajectory is one moment.
//! Distances are in mm; the arena is 1500 mm (X) by 2000 mm (Y) with its origin at a corner.

use serde::Serialize;

/// Cars closer than this (centre to centre, mm) have collided.
pub const COLLISION_MM: f64 = 100.0;
/// The arena's inside, mm.
pub const ARENA_MM: (f64, f64) = (1500.0, 2000.0);

/// One sample of one car's true state.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sample {
    /// Seconds since the maneuver started.
    pub t: f64,
    /// X, mm.
    pub x_mm: f64,
    /// Y, mm.
    pub y_mm: f64,
    /// Heading, mrad counter-clockwise from +X.
    pub heading_mrad: f64,
    /// Speed, mm/s.
    pub v_mm_s: f64,
}

/// Path length, mm.
pub fn distance_travelled(track: &[Sample]) -> f64 {
    track
        .windows(2)
        .map(|w| (w[1].x_mm - w[0].x_mm).hypot(w[1].y_mm - w[0].y_mm))
        .sum()
}

/// Distance from the last sample to `target` (mm), if there is a sample.
pub fn final_error(track: &[Sample], target: (f64, f64)) -> Option<f64> {
    track
        .last()
        .map(|s| (s.x_mm - target.0).hypot(s.y_mm - target.1))
}

/// A close approach between two cars.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Encounter {
    /// The two cars, by index in the track list.
    pub cars: (usize, usize),
    /// When, seconds.
    pub t: f64,
    /// Centre distance, mm.
    pub distance_mm: f64,
}

/// The closest approach of any two cars over the run (`None` with fewer than two cars).
pub fn min_separation(tracks: &[Vec<Sample>]) -> Option<Encounter> {
    let mut best: Option<Encounter> = None;
    for i in 0..tracks.len() {
        for j in i + 1..tracks.len() {
            for (a, b) in tracks[i].iter().zip(&tracks[j]) {
                let d = (a.x_mm - b.x_mm).hypot(a.y_mm - b.y_mm);
                if best.is_none_or(|e| d < e.distance_mm) {
                    best = Some(Encounter {
                        cars: (i, j),
                        t: a.t,
                        distance_mm: d,
                    });
                }
            }
        }
    }
    best
}

/// Collisions: each time a pair of cars comes closer than [`COLLISION_MM`] (one entry per
/// approach, at its first sample).
pub fn collisions(tracks: &[Vec<Sample>]) -> Vec<Encounter> {
    let mut out = Vec::new();
    for i in 0..tracks.len() {
        for j in i + 1..tracks.len() {
            let mut inside = false;
            for (a, b) in tracks[i].iter().zip(&tracks[j]) {
                let d = (a.x_mm - b.x_mm).hypot(a.y_mm - b.y_mm);
                if d < COLLISION_MM && !inside {
                    out.push(Encounter {
                        cars: (i, j),
                        t: a.t,
                        distance_mm: d,
                    });
                }
                inside = d < COLLISION_MM;
            }
        }
    }
    out
}

/// Whether a point (mm) lies outside the arena.
pub fn outside(x_mm: f64, y_mm: f64) -> bool {
    !(0.0..=ARENA_MM.0).contains(&x_mm) || !(0.0..=ARENA_MM.1).contains(&y_mm)
}

/// Times (seconds) at which the car left the arena (one per excursion).
pub fn wall_violations(track: &[Sample]) -> Vec<f64> {
    let mut out = Vec::new();
    let mut was_out = false;
    for s in track {
        let o = outside(s.x_mm, s.y_mm);
        if o && !was_out {
            out.push(s.t);
        }
        was_out = o;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn s(t: f64, x: f64, y: f64) -> Sample {
        Sample {
            t,
            x_mm: x,
            y_mm: y,
            heading_mrad: 0.0,
            v_mm_s: 0.0,
        }
    }

    #[test]
    fn distance_and_error() {
        let track = [s(0.0, 0.0, 0.0), s(1.0, 300.0, 400.0), s(2.0, 300.0, 500.0)];
        assert!((distance_travelled(&track) - 600.0).abs() < 1e-9);
        assert_eq!(final_error(&track, (300.0, 520.0)), Some(20.0));
        assert_eq!(final_error(&[], (0.0, 0.0)), None);
    }

    #[test]
    fn separation_and_collisions() {
        let a = vec![
            s(0.0, 0.0, 0.0),
            s(1.0, 0.0, 0.0),
            s(2.0, 0.0, 0.0),
            s(3.0, 0.0, 0.0),
        ];
        let b = vec![
            s(0.0, 500.0, 0.0),
            s(1.0, 50.0, 0.0),
            s(2.0, 500.0, 0.0),
            s(3.0, 80.0, 0.0),
        ];
        let m = min_separation(&[a.clone(), b.clone()]).unwrap();
        assert_eq!((m.cars, m.t, m.distance_mm), ((0, 1), 1.0, 50.0));
        let c = collisions(&[a.clone(), b]);
        assert_eq!(c.len(), 2);
        assert_eq!(c[1].t, 3.0);
        assert!(min_separation(&[a]).is_none());
    }

    #[test]
    fn walls() {
        let track = [
            s(0.0, 10.0, 10.0),
            s(1.0, -1.0, 10.0),
            s(2.0, -2.0, 10.0),
            s(3.0, 10.0, 10.0),
            s(4.0, 10.0, 2001.0),
        ];
        assert_eq!(wall_violations(&track), vec![1.0, 4.0]);
    }

    proptest! {
        #[test]
        fn distance_is_at_least_the_displacement(pts in proptest::collection::vec((0.0..1500.0f64, 0.0..2000.0f64), 1..40)) {
            let track: Vec<Sample> = pts.iter().enumerate().map(|(i, &(x, y))| s(i as f64, x, y)).collect();
            let first = track[0];
            let last = track[track.len() - 1];
            let disp = (last.x_mm - first.x_mm).hypot(last.y_mm - first.y_mm);
            prop_assert!(distance_travelled(&track) + 1e-6 >= disp);
            prop_assert!(wall_violations(&track).is_empty());
        }
    }
}
