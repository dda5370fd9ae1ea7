//! Measures of an experiment's trajectories: distance travelled, final error to a target,
//! closest approach between cars, collisions, wall violations and the errors of the group
//! maneuvers (formation slot error, rendezvous spread, circle radius and spacing errors).
//!
//! Every car is sampled at the same instants, so sample `k` of each trajectory is one moment.
//! Distances are in mm; the arena is 1500 mm (X) by 2000 mm (Y) with its origin at a corner.
//! A sample is the car's true pose: the midpoint of its rear axle, as the LBC and the tracking
//! system report it. Distances between cars are taken between body centres,
//! [`BODY_OFFSET_MM`] ahead of the rear axle (the car is 4 x 2 in, about 100 x 50 mm).

use serde::Serialize;

/// Cars whose body centres are closer than this (mm, about one car length) have collided.
pub const COLLISION_MM: f64 = 100.0;
/// Body centre ahead of the rear axle, mm (the `maneuvers` crate's body offset, 16 units).
pub const BODY_OFFSET_MM: f64 = 40.0;
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

impl Sample {
    /// The body centre, mm.
    pub fn body(&self) -> (f64, f64) {
        let h = self.heading_mrad / 1000.0;
        (
            self.x_mm + BODY_OFFSET_MM * h.cos(),
            self.y_mm + BODY_OFFSET_MM * h.sin(),
        )
    }
}

fn body_distance(a: &Sample, b: &Sample) -> f64 {
    let (ax, ay) = a.body();
    let (bx, by) = b.body();
    (ax - bx).hypot(ay - by)
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

/// The closest approach of any two cars' body centres over the run (`None` with fewer than
/// two cars).
pub fn min_separation(tracks: &[Vec<Sample>]) -> Option<Encounter> {
    let mut best: Option<Encounter> = None;
    for i in 0..tracks.len() {
        for j in i + 1..tracks.len() {
            for (a, b) in tracks[i].iter().zip(&tracks[j]) {
                let d = body_distance(a, b);
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

/// The smallest distance between two cars' body centres at each sample time, `(t, mm)`
/// (empty with fewer than two cars).
pub fn separation_series(tracks: &[Vec<Sample>]) -> Vec<(f64, f64)> {
    let n = tracks.iter().map(Vec::len).min().unwrap_or(0);
    if tracks.len() < 2 {
        return Vec::new();
    }
    (0..n)
        .map(|s| {
            let mut best = f64::INFINITY;
            for i in 0..tracks.len() {
                for j in i + 1..tracks.len() {
                    best = best.min(body_distance(&tracks[i][s], &tracks[j][s]));
                }
            }
            (tracks[0][s].t, best)
        })
        .collect()
}

/// Collisions: each time the body centres of a pair of cars come closer than
/// [`COLLISION_MM`] (one entry per approach, at its first sample).
pub fn collisions(tracks: &[Vec<Sample>]) -> Vec<Encounter> {
    let mut out = Vec::new();
    for i in 0..tracks.len() {
        for j in i + 1..tracks.len() {
            let mut inside = false;
            for (a, b) in tracks[i].iter().zip(&tracks[j]) {
                let d = body_distance(a, b);
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

/// Where a formation slot is: the point `offset_mm` = (forward, left) in the frame of the
/// leader's pose `leader`, mm.
pub fn slot_point(leader: &Sample, offset_mm: (f64, f64)) -> (f64, f64) {
    let h = leader.heading_mrad / 1000.0;
    let (c, s) = (h.cos(), h.sin());
    (
        leader.x_mm + offset_mm.0 * c - offset_mm.1 * s,
        leader.y_mm + offset_mm.0 * s + offset_mm.1 * c,
    )
}

/// Formation error of one follower: the distance of its true pose from its slot placed on the
/// leader's true pose, mm.
pub fn slot_error(leader: &Sample, offset_mm: (f64, f64), follower: &Sample) -> f64 {
    let (x, y) = slot_point(leader, offset_mm);
    (follower.x_mm - x).hypot(follower.y_mm - y)
}

/// Rendezvous spread: the largest distance of a car from the group's centroid, mm (0 for no
/// cars).
pub fn spread(cars: &[Sample]) -> f64 {
    if cars.is_empty() {
        return 0.0;
    }
    let n = cars.len() as f64;
    let cx = cars.iter().map(|s| s.x_mm).sum::<f64>() / n;
    let cy = cars.iter().map(|s| s.y_mm).sum::<f64>() / n;
    cars.iter()
        .map(|s| (s.x_mm - cx).hypot(s.y_mm - cy))
        .fold(0.0, f64::max)
}

/// Errors of cars on a circle of `radius_mm` about `centre_mm`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CircleError {
    /// Largest difference between a car's distance from the centre and the radius, mm.
    pub radius_mm: f64,
    /// Largest difference between an angular gap to the next car and `2 pi / n`, as an arc
    /// length on the circle, mm.
    pub spacing_mm: f64,
}

/// How far `cars` are from being evenly spaced on the circle.
pub fn circle_error(cars: &[Sample], centre_mm: (f64, f64), radius_mm: f64) -> CircleError {
    use std::f64::consts::TAU;
    let radius_err = cars
        .iter()
        .map(|s| ((s.x_mm - centre_mm.0).hypot(s.y_mm - centre_mm.1) - radius_mm).abs())
        .fold(0.0, f64::max);
    let mut angles: Vec<f64> = cars
        .iter()
        .map(|s| {
            (s.y_mm - centre_mm.1)
                .atan2(s.x_mm - centre_mm.0)
                .rem_euclid(TAU)
        })
        .collect();
    angles.sort_by(f64::total_cmp);
    let n = angles.len();
    let mut spacing = 0.0f64;
    if n >= 2 {
        let even = TAU / n as f64;
        for k in 0..n {
            let next = if k + 1 < n {
                angles[k + 1]
            } else {
                angles[0] + TAU
            };
            spacing = spacing.max((next - angles[k] - even).abs() * radius_mm);
        }
    }
    CircleError {
        radius_mm: radius_err,
        spacing_mm: spacing,
    }
}

/// Summary of an error series: largest, mean and 95th percentile (nearest rank), mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Largest value.
    pub max_mm: f64,
    /// Mean.
    pub mean_mm: f64,
    /// 95th percentile.
    pub p95_mm: f64,
    /// Number of samples.
    pub samples: usize,
}

/// Statistics of `values` (`None` when empty).
pub fn error_stats(values: &[f64]) -> Option<ErrorStats> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((0.95 * v.len() as f64).ceil() as usize).clamp(1, v.len());
    Some(ErrorStats {
        max_mm: v[v.len() - 1],
        mean_mm: v.iter().sum::<f64>() / v.len() as f64,
        p95_mm: v[rank - 1],
        samples: v.len(),
    })
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

    fn posed(x: f64, y: f64, heading_mrad: f64) -> Sample {
        Sample {
            heading_mrad,
            ..s(0.0, x, y)
        }
    }

    #[test]
    fn separation_is_between_body_centres() {
        // Nose to nose along X: rear axles 180 mm apart, bodies 100 mm apart.
        let a = vec![posed(0.0, 0.0, 0.0)];
        let b = vec![posed(180.0, 0.0, 3141.59)];
        let m = min_separation(&[a.clone(), b]).unwrap();
        assert!((m.distance_mm - 100.0).abs() < 0.01, "{m:?}");
        // Tail to tail: 260 mm.
        let c = vec![posed(-100.0, 0.0, 3141.59)];
        let m = min_separation(&[a, c]).unwrap();
        assert!((m.distance_mm - 180.0).abs() < 0.01, "{m:?}");
    }

    #[test]
    fn slots_follow_the_leader_frame() {
        // Leader at (1000, 1000) facing +Y; a slot 250 mm behind and 100 mm to the left.
        let leader = posed(1000.0, 1000.0, 1570.796);
        let (x, y) = slot_point(&leader, (-250.0, 100.0));
        assert!(
            (x - 900.0).abs() < 0.01 && (y - 750.0).abs() < 0.01,
            "{x} {y}"
        );
        let follower = posed(900.0, 720.0, 0.0);
        assert!((slot_error(&leader, (-250.0, 100.0), &follower) - 30.0).abs() < 0.01);
    }

    #[test]
    fn spread_and_circle() {
        let cars = [posed(0.0, 0.0, 0.0), posed(200.0, 0.0, 0.0)];
        assert!((spread(&cars) - 100.0).abs() < 1e-9);
        assert_eq!(spread(&[]), 0.0);
        // Four cars evenly on r = 300 around (750, 1000), one of them 20 mm too far out.
        let c = (750.0, 1000.0);
        let cars = [
            posed(1070.0, 1000.0, 0.0),
            posed(750.0, 1300.0, 0.0),
            posed(450.0, 1000.0, 0.0),
            posed(750.0, 700.0, 0.0),
        ];
        let e = circle_error(&cars, c, 300.0);
        assert!(
            (e.radius_mm - 20.0).abs() < 1e-9 && e.spacing_mm < 1e-6,
            "{e:?}"
        );
        // Two cars bunched a quarter turn apart: gaps pi/2 and 3 pi/2 against pi.
        let e = circle_error(&cars[..2], c, 300.0);
        assert!(
            (e.spacing_mm - std::f64::consts::FRAC_PI_2 * 300.0).abs() < 0.2,
            "{e:?}"
        );
    }

    #[test]
    fn stats() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        let st = error_stats(&v).unwrap();
        assert_eq!((st.max_mm, st.p95_mm, st.samples), (100.0, 95.0, 100));
        assert!((st.mean_mm - 50.5).abs() < 1e-9);
        assert!(error_stats(&[]).is_none());
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
