//! Even spacing on a circle, rotating at a given speed.
//!
//! Each car knows only its angle about the centre and its fresh neighbours' angles. Along the
//! circle it moves at the commanded speed plus a correction proportional to the difference of
//! the gaps to the next car ahead and the next car behind (the cyclic-pursuit balance law), so
//! the gaps converge to `2 pi / n` without any assignment of places (`n` counts the cars within
//! a quarter radius of the circle). Across the circle a proportional term pulls it onto the
//! radius.

use crate::fixed::{from_mrad, fx, mul_q14, mul_shift, wrap, IVec2, TURN};
use crate::law::{error_units_fx, Guidance, Law, LawInput, Plan, Waypoint};
use crate::param::{Param, Values};
use crate::{CarPose, Neighbour, Phase};

/// Gain of the gap balance, 1/s (mm/s of extra speed per mm of gap difference), in tenths.
const GAP_GAIN_TENTHS: i32 = 6;
/// Gain onto the radius: 1/s, which is 2.5 mm/s per tracking unit of error.
const RADIAL_MM_S_PER_UNIT: (i32, i32) = (5, 2);
/// Spacing and radius error below which the car counts as in place, tracking units (50 mm).
pub const TOLERANCE_UNITS: i32 = 20;
/// Arc length per binary angle of gap and tracking unit of radius, in 1/16 unit, Q32:
/// 16 * 2 pi / 65536.
const ARC_Q32: i64 = (4_294_967_296.0 * 16.0 * core::f64::consts::TAU / 65_536.0 + 0.5) as i64;

/// The circle law.
#[derive(Debug, Clone, PartialEq)]
pub struct Circle {
    /// Centre, 1/16 tracking unit.
    centre: IVec2,
    radius_units: u16,
    speed_mm_s: i16,
}

/// Angular gaps around one car, as binary angles (65 536 per turn).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Gaps {
    /// Angle to the next car in the direction of rotation, in (0, 65 536].
    pub ahead: i32,
    /// Angle to the next car against the direction of rotation.
    pub behind: i32,
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
        self.plan(&input.own, input.neighbours, input.waypoint)
    }
}

/// A pose's position, 1/16 tracking unit.
fn position(p: &CarPose) -> IVec2 {
    IVec2::from_units(i32::from(p.x), i32::from(p.y))
}

impl Circle {
    /// Centre and radius in tracking units, speed in mm/s (positive counter-clockwise).
    pub fn with(cx: u16, cy: u16, radius_units: u16, speed_mm_s: i16) -> Self {
        Self {
            centre: IVec2::from_units(i32::from(cx), i32::from(cy)),
            radius_units,
            speed_mm_s,
        }
    }

    fn direction(&self) -> i32 {
        if self.speed_mm_s < 0 {
            -1
        } else {
            1
        }
    }

    /// Gaps between the car at `pos` (1/16 unit) and its neighbours on the circle: those whose
    /// distance from the centre is within a quarter of the radius of it.
    pub fn gaps(&self, pos: IVec2, fresh: &[Neighbour]) -> Gaps {
        let s = self.direction();
        let phi = (pos - self.centre).angle();
        let r = i64::from(fx(i32::from(self.radius_units)));
        let (inner, outer) = (r * 3 / 4, r * 5 / 4);
        let mut ahead = TURN;
        let mut behind = TURN;
        let mut count = 1;
        for n in fresh {
            let q = position(&n.pose) - self.centre;
            let d2 = q.len2();
            if d2 < (inner * inner) as u64 || d2 > (outer * outer) as u64 {
                continue;
            }
            count += 1;
            let d = wrap(s * (q.angle() - phi));
            let a = if d <= 0 { d + TURN } else { d };
            let b = TURN - a;
            ahead = ahead.min(a);
            behind = behind.min(if b <= 0 { TURN } else { b });
        }
        Gaps {
            ahead,
            behind,
            count,
        }
    }

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

    /// One period for the car at `own` with its fresh neighbours; the latest waypoint, if any,
    /// is the centre.
    fn plan(&mut self, own: &CarPose, fresh: &[Neighbour], waypoint: Option<Waypoint>) -> Plan {
        if let Some(w) = waypoint {
            self.centre = IVec2::from_units(i32::from(w.x), i32::from(w.y));
        }
        let pos = position(own);
        let rel = pos - self.centre;
        let rho = rel.norm();
        let radial = if rho > 0 {
            rel.unit()
        } else {
            IVec2::from_angle(from_mrad(i32::from(own.heading_mrad)))
        };
        let tangent = radial.perp().times(self.direction());
        let g = self.gaps(pos, fresh);
        let ideal = TURN / g.count as i32;
        let radius = i32::from(self.radius_units);
        // Gaps (binary angles) times the radius (units) as arc lengths, 1/16 unit.
        let arc = |a: i32| mul_shift(i64::from(a) * i64::from(radius), ARC_Q32, 32);
        let spacing_err = arc((g.ahead - ideal).abs().max((g.behind - ideal).abs()));
        let r = fx(radius);
        let radial_err = r - rho;
        // Full balance only once near the circle: far away the neighbours' angles mean little.
        let near = if radial_err.abs() >= r {
            0
        } else {
            ((r - radial_err.abs()) << 14) / r
        };
        let speed = fx(i32::from(self.speed_mm_s).abs());
        // GAP_GAIN * (ahead - behind) / 2 * radius, in mm/s: 2.5 mm per unit of arc, so
        // 0.6 / 2 * 2.5 = 3/4 of the arc.
        let balance = arc(g.ahead - g.behind) * (GAP_GAIN_TENTHS * 5) / 40;
        let v_t = mul_q14(speed + balance, near)
            .max(0)
            .min(2 * speed + fx(150));
        let v_r = radial_err * RADIAL_MM_S_PER_UNIT.0 / RADIAL_MM_S_PER_UNIT.1;
        let v = (tangent.along(v_t) + radial.along(v_r)).clamp_norm(2 * speed + fx(300));
        let err = spacing_err.max(radial_err.abs());
        let converged = err < fx(TOLERANCE_UNITS);
        Plan {
            guidance: if converged && speed == 0 {
                Guidance::Hold
            } else {
                Guidance::velocity(v)
            },
            phase: if converged {
                Phase::Track
            } else {
                Phase::Approach
            },
            converged,
            error_units: error_units_fx(err),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::{HALF_TURN, QUARTER_TURN};

    fn n(id: u8, x: u16, y: u16) -> Neighbour {
        Neighbour {
            id,
            pose: at(x, y),
            age_us: 0,
        }
    }

    fn at(x: u16, y: u16) -> CarPose {
        CarPose {
            x,
            y,
            ..CarPose::default()
        }
    }

    fn velocity(p: &Plan) -> (i16, i16) {
        match p.guidance {
            Guidance::Velocity { vx_mm_s, vy_mm_s } => (vx_mm_s, vy_mm_s),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn gaps_to_neighbours() {
        let c = Circle::with(300, 400, 100, 100);
        let me = IVec2::from_units(400, 400);
        // Me at angle 0; a neighbour at 90 degrees (ahead counter-clockwise), one at 180.
        let g = c.gaps(me, &[n(2, 300, 500), n(3, 200, 400)]);
        assert_eq!((g.ahead, g.behind, g.count), (QUARTER_TURN, HALF_TURN, 3));
        // Clockwise rotation swaps them.
        let c = Circle::with(300, 400, 100, -100);
        let g = c.gaps(me, &[n(2, 300, 500), n(3, 200, 400)]);
        assert_eq!((g.ahead, g.behind), (HALF_TURN, QUARTER_TURN));
    }

    #[test]
    fn cars_far_off_the_circle_are_not_spaced_against() {
        let c = Circle::with(300, 400, 100, 100);
        let g = c.gaps(IVec2::from_units(400, 400), &[n(2, 330, 410), n(3, 200, 400)]);
        assert_eq!(g.count, 2);
        assert_eq!(g.ahead, HALF_TURN);
    }

    #[test]
    fn on_circle_evenly_spaced_moves_tangentially() {
        let mut c = Circle::with(300, 400, 100, 100);
        let p = c.plan(&at(400, 400), &[n(2, 200, 400)], None);
        assert!(p.converged);
        assert_eq!(velocity(&p), (0, 100));
    }

    #[test]
    fn car_with_small_gap_ahead_slows_down() {
        let mut c = Circle::with(300, 400, 100, 100);
        // Neighbour 45 degrees ahead: gap ahead pi/4, behind 7pi/4 -> slow to zero.
        let p = c.plan(&at(400, 400), &[n(2, 371, 471)], None);
        assert!(!p.converged);
        let (vx, vy) = velocity(&p);
        assert!(vx.abs() <= 1 && vy.abs() <= 1, "{p:?}");
        // The other car sees the big gap ahead and speeds up.
        let p = c.plan(&at(371, 471), &[n(1, 400, 400)], None);
        let (vx, vy) = velocity(&p);
        assert!(i32::from(vx).pow(2) + i32::from(vy).pow(2) > 150 * 150, "{p:?}");
    }

    #[test]
    fn pulled_onto_radius() {
        let mut c = Circle::with(300, 400, 100, 0);
        let p = c.plan(&at(350, 400), &[], None);
        let (vx, vy) = velocity(&p);
        assert!(vx > 100 && vy == 0, "{p:?}");
        // On the radius, alone and not rotating: hold.
        assert_eq!(c.plan(&at(400, 400), &[], None).guidance, Guidance::Hold);
    }

    #[test]
    fn a_waypoint_moves_the_centre() {
        let mut c = Circle::with(300, 400, 100, 0);
        let w = Waypoint {
            x: 500,
            y: 400,
            index: 0,
        };
        assert_eq!(c.plan(&at(400, 400), &[], Some(w)).guidance, Guidance::Hold);
        assert!(!c.plan(&at(300, 400), &[], None).converged);
    }
}
