//! Even spacing on a circle, rotating at a given speed.
//!
//! Each car knows only its angle about the centre and its fresh neighbours' angles. Along the
//! circle it moves at the commanded speed plus a correction proportional to the difference of
//! the gaps to the next car ahead and the next car behind (the cyclic-pursuit balance law), so
//! the gaps converge to `2 pi / n` without any assignment of places (`n` counts the cars within
//! a quarter radius of the circle). Across the circle a proportional term pulls it onto the
//! radius.

use core::f32::consts::TAU;

use crate::geom::{clampf, wrap, Vec2};
use crate::law::{error_units, Guidance, Law, LawInput, Me, Plan, Waypoint};
use crate::param::{Param, Values};
use crate::{Neighbour, Phase, MM_PER_UNIT};

/// Gain of the gap balance, 1/s (mm/s of extra speed per mm of gap difference).
const GAP_GAIN: f32 = 0.6;
/// Gain onto the radius, 1/s.
const RADIAL_GAIN: f32 = 1.0;
/// Neighbours farther than this fraction of the radius from the circle are not spaced
/// against: a car still on its way in must not hold up the cars already on the circle.
const NEAR_FRACTION: f32 = 0.25;
/// Spacing and radius error below which the car counts as in place, tracking units (50 mm).
pub const TOLERANCE_UNITS: f32 = 20.0;

/// The circle law.
#[derive(Debug, Clone, PartialEq)]
pub struct Circle {
    centre: Vec2,
    radius: f32,
    speed: f32,
}

/// Angular gaps around one car.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gaps {
    /// Angle to the next car in the direction of rotation, rad, in (0, 2 pi].
    pub ahead: f32,
    /// Angle to the next car against the direction of rotation, rad.
    pub behind: f32,
    /// Cars near the circle, this one included.
    pub count: usize,
}

impl Law for Circle {
    const NAME: &'static str = "circle";
    const SUMMARY: &'static str = "Even spacing on a rotating circle (cyclic-pursuit balance of the gaps ahead and behind); a waypoint moves the centre.";
    const PARAMS: &'static [Param] = &[
        Param::int("cx", "units", 0, 1023).doc("centre X"),
        Param::int("cy", "units", 0, 1023).doc("centre Y"),
        Param::int("radius_units", "units", 1, 511)
            .doc("radius; at least 100 (the turning radius is 56 units)"),
        Param::int("speed_mm_s", "mm/s", -2048, 2047)
            .default(100)
            .doc("speed along the circle, positive counter-clockwise; 0 holds once spread"),
    ];

    fn new(p: &Values) -> Self {
        Self::with(p.u16(0), p.u16(1), p.u16(2), p.i16(3))
    }

    fn step(&mut self, input: &LawInput<'_>) -> Plan {
        self.plan(&input.me(), input.neighbours, input.waypoint)
    }
}

impl Circle {
    /// Centre and radius in tracking units, speed in mm/s (positive counter-clockwise).
    pub fn with(cx: u16, cy: u16, radius_units: u16, speed_mm_s: i16) -> Self {
        Self {
            centre: Vec2::new(f32::from(cx), f32::from(cy)),
            radius: f32::from(radius_units),
            speed: f32::from(speed_mm_s),
        }
    }

    fn direction(&self) -> f32 {
        if self.speed < 0.0 {
            -1.0
        } else {
            1.0
        }
    }

    /// Gaps between this car and its neighbours on the circle.
    pub fn gaps(&self, pos: Vec2, fresh: &[Neighbour]) -> Gaps {
        let s = self.direction();
        let phi = (pos - self.centre).angle();
        let mut ahead = TAU;
        let mut behind = TAU;
        let mut count = 1;
        for n in fresh {
            let q = Vec2::new(f32::from(n.pose.x), f32::from(n.pose.y)) - self.centre;
            if (q.norm() - self.radius).abs() > NEAR_FRACTION * self.radius {
                continue;
            }
            count += 1;
            let d = wrap(s * (q.angle() - phi));
            let a = if d <= 0.0 { d + TAU } else { d };
            let b = TAU - a;
            ahead = ahead.min(a);
            behind = behind.min(if b <= 0.0 { TAU } else { b });
        }
        Gaps {
            ahead,
            behind,
            count,
        }
    }
}

impl Circle {
    /// The group command for this circle.
    pub fn params(
        cx: u16,
        cy: u16,
        radius_units: u16,
        speed_mm_s: i16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[
                i32::from(cx),
                i32::from(cy),
                i32::from(radius_units),
                i32::from(speed_mm_s),
            ],
        )
    }

    /// One period for car `me` with its fresh neighbours; the latest waypoint, if any, is
    /// the centre.
    fn plan(&mut self, me: &Me, fresh: &[Neighbour], waypoint: Option<Waypoint>) -> Plan {
        if let Some(w) = waypoint {
            self.centre = Vec2::new(f32::from(w.x), f32::from(w.y));
        }
        let rel = me.pos - self.centre;
        let rho = rel.norm();
        let radial = if rho > 1e-3 {
            rel.unit()
        } else {
            Vec2::from_angle(me.heading)
        };
        let tangent = radial.perp() * self.direction();
        let g = self.gaps(me.pos, fresh);
        let ideal = TAU / g.count as f32;
        let spacing_err = (g.ahead - ideal).abs().max((g.behind - ideal).abs()) * self.radius;
        let radial_err = self.radius - rho;
        // Full balance only once near the circle: far away the neighbours' angles mean little.
        let near = clampf(1.0 - radial_err.abs() / self.radius, 0.0, 1.0);
        let speed = self.speed.abs();
        let balance = GAP_GAIN * (g.ahead - g.behind) * 0.5 * self.radius * MM_PER_UNIT;
        let v_t = clampf((speed + balance) * near, 0.0, 2.0 * speed + 150.0);
        let v_r = radial_err * RADIAL_GAIN * MM_PER_UNIT;
        let v = (tangent * v_t + radial * v_r).clamp_norm(2.0 * speed + 300.0);
        let err = spacing_err.max(radial_err.abs());
        let converged = err < TOLERANCE_UNITS;
        Plan {
            guidance: if converged && speed < 1.0 {
                Guidance::Hold
            } else {
                Guidance::VelocityF(v)
            },
            phase: if converged {
                Phase::Track
            } else {
                Phase::Approach
            },
            converged,
            error_units: error_units(err),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CarPose;
    use core::f32::consts::PI;

    fn n(id: u8, x: u16, y: u16) -> Neighbour {
        Neighbour {
            id,
            pose: CarPose {
                x,
                y,
                ..CarPose::default()
            },
            age_us: 0,
        }
    }

    fn me(x: f32, y: f32) -> Me {
        Me {
            id: 1,
            pos: Vec2::new(x, y),
            heading: 0.0,
            speed: 0.0,
        }
    }

    #[test]
    fn gaps_to_neighbours() {
        let c = Circle::with(300, 400, 100, 100);
        // Me at angle 0; a neighbour at 90 degrees (ahead counter-clockwise), one at 180.
        let g = c.gaps(Vec2::new(400.0, 400.0), &[n(2, 300, 500), n(3, 200, 400)]);
        assert!((g.ahead - PI / 2.0).abs() < 1e-3, "{g:?}");
        assert!((g.behind - PI).abs() < 1e-3, "{g:?}");
        assert_eq!(g.count, 3);
        // Clockwise rotation swaps them.
        let c = Circle::with(300, 400, 100, -100);
        let g = c.gaps(Vec2::new(400.0, 400.0), &[n(2, 300, 500), n(3, 200, 400)]);
        assert!((g.ahead - PI).abs() < 1e-3 && (g.behind - PI / 2.0).abs() < 1e-3);
    }

    #[test]
    fn cars_far_off_the_circle_are_not_spaced_against() {
        let c = Circle::with(300, 400, 100, 100);
        let g = c.gaps(Vec2::new(400.0, 400.0), &[n(2, 330, 410), n(3, 200, 400)]);
        assert_eq!(g.count, 2);
        assert!((g.ahead - PI).abs() < 1e-3);
    }

    #[test]
    fn on_circle_evenly_spaced_moves_tangentially() {
        let mut c = Circle::with(300, 400, 100, 100);
        let p = c.plan(&me(400.0, 400.0), &[n(2, 200, 400)], None);
        assert!(p.converged);
        match p.guidance {
            Guidance::VelocityF(v) => assert!((v.y - 100.0).abs() < 0.5 && v.x.abs() < 0.5),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn car_with_small_gap_ahead_slows_down() {
        let mut c = Circle::with(300, 400, 100, 100);
        // Neighbour 45 degrees ahead: gap ahead pi/4, behind 7pi/4 -> slow to zero.
        let p = c.plan(&me(400.0, 400.0), &[n(2, 371, 471)], None);
        assert!(!p.converged);
        match p.guidance {
            Guidance::VelocityF(v) => assert!(v.norm() < 1.0, "{v:?}"),
            other => panic!("{other:?}"),
        }
        // The other car sees the big gap ahead and speeds up.
        let p = c.plan(&me(371.0, 471.0), &[n(1, 400, 400)], None);
        match p.guidance {
            Guidance::VelocityF(v) => assert!(v.norm() > 150.0, "{v:?}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn pulled_onto_radius() {
        let mut c = Circle::with(300, 400, 100, 0);
        let p = c.plan(&me(350.0, 400.0), &[], None);
        match p.guidance {
            Guidance::VelocityF(v) => assert!(v.x > 100.0 && v.y.abs() < 1.0, "{v:?}"),
            other => panic!("{other:?}"),
        }
        // On the radius, alone and not rotating: hold.
        assert_eq!(c.plan(&me(400.0, 400.0), &[], None).guidance, Guidance::Hold);
    }
}
