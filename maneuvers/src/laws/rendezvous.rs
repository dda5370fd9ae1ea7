//! Rendezvous by average consensus.
//!
//! Every car drives towards the mean of its own position and its fresh neighbours' positions,
//! with a speed proportional to the distance (gain [`GAIN`], saturated at the maneuver speed),
//! and holds once within the arrival radius. With all cars hearing each other the mean is
//! invariant under this law (the velocities sum to zero while none saturates), so each car's
//! distance to it decays as `exp(-GAIN t)`; see `docs/maneuvers.md` for the bound and the
//! measured times.

use crate::geom::Vec2;
use crate::law::{error_units, Guidance, Law, LawInput, Me, Plan};
use crate::param::{Param, Values};
use crate::{Neighbour, Phase, MM_PER_UNIT};

/// Consensus gain, 1/s.
pub const GAIN: f32 = 0.8;
/// A holding car starts again only when the consensus point is this much beyond the radius.
const HYSTERESIS: f32 = 1.3;
/// A neighbour nearer than this (tracking units, 325 mm: the avoidance band of the default
/// [`crate::SafetyConfig`] plus a little) that is closer to the consensus point and within 60
/// degrees of the way there blocks the car: it holds instead of pushing into the avoidance field.
pub const BLOCK_UNITS: f32 = 130.0;

/// The rendezvous law.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendezvous {
    radius: f32,
    speed: f32,
    holding: bool,
}

impl Law for Rendezvous {
    const NAME: &'static str = "rendezvous";
    const SUMMARY: &'static str = "Rendezvous by consensus: every car drives towards the mean position of itself and its neighbours and holds once within the radius of it.";
    const PARAMS: &'static [Param] = &[
        Param::int("radius_units", "units", 1, 511)
            .default(60)
            .doc("arrival radius around the consensus point; at least 60 for 3 cars"),
        Param::int("speed_mm_s", "mm/s", 0, 2047)
            .default(200)
            .doc("maximum speed"),
    ];

    fn new(p: &Values) -> Self {
        Self::with(p.u16(0), p.u16(1))
    }

    fn step(&mut self, input: &LawInput<'_>) -> Plan {
        self.plan(&input.me(), input.neighbours)
    }
}

impl Rendezvous {
    /// Arrival radius in tracking units, maximum speed in mm/s.
    pub fn with(radius_units: u16, speed_mm_s: u16) -> Self {
        Self {
            radius: f32::from(radius_units),
            speed: f32::from(speed_mm_s),
            holding: false,
        }
    }

    /// The consensus point: mean of this car and its fresh neighbours, tracking units.
    pub fn consensus(me: &Me, fresh: &[Neighbour]) -> Vec2 {
        let mut sum = me.pos;
        for n in fresh {
            sum = sum + Vec2::new(f32::from(n.pose.x), f32::from(n.pose.y));
        }
        // At most a few dozen cars: the count converts exactly.
        sum * (1.0 / (fresh.len() as f32 + 1.0))
    }

    /// The group command for this rendezvous.
    pub fn params(
        radius_units: u16,
        speed_mm_s: u16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[i32::from(radius_units), i32::from(speed_mm_s)],
        )
    }

    /// One period for car `me` with its fresh neighbours.
    fn plan(&mut self, me: &Me, fresh: &[Neighbour]) -> Plan {
        let c = Self::consensus(me, fresh);
        let err = c - me.pos;
        let e = err.norm();
        let limit = if self.holding {
            self.radius * HYSTERESIS
        } else {
            self.radius
        };
        let blocked = fresh.iter().any(|n| {
            let q = Vec2::new(f32::from(n.pose.x), f32::from(n.pose.y));
            let to = q - me.pos;
            let d = to.norm();
            d < BLOCK_UNITS * if self.holding { 1.2 } else { 1.0 }
                && (c - q).norm() < e
                && to.dot(err) > 0.5 * d * e
        });
        self.holding = e <= limit || (blocked && e <= self.radius + BLOCK_UNITS);
        if self.holding {
            return Plan::hold(Phase::Hold, true, error_units(e));
        }
        Plan {
            guidance: Guidance::VelocityF((err * (GAIN * MM_PER_UNIT)).clamp_norm(self.speed)),
            phase: Phase::Approach,
            converged: false,
            error_units: error_units(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CarPose;

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
    fn moves_towards_the_mean() {
        let mut r = Rendezvous::with(20, 200);
        let fresh = [n(2, 400, 100), n(3, 100, 400)];
        // Mean of (100,100), (400,100), (100,400) is (200,200).
        assert_eq!(
            Rendezvous::consensus(&me(100.0, 100.0), &fresh),
            Vec2::new(200.0, 200.0)
        );
        let p = r.plan(&me(100.0, 100.0), &fresh);
        match p.guidance {
            Guidance::VelocityF(v) => {
                assert!((v.norm() - 200.0).abs() < 0.1, "saturated at the speed");
                assert!((v.x - v.y).abs() < 0.1);
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(p.error_units, 141);
    }

    #[test]
    fn proportional_inside_saturation() {
        let mut r = Rendezvous::with(5, 1000);
        let p = r.plan(&me(90.0, 100.0), &[n(2, 110, 100)]);
        // 10 units = 25 mm from the mean: 0.8/s * 25 mm = 20 mm/s.
        assert_eq!(p.guidance, Guidance::VelocityF(Vec2::new(20.0, 0.0)));
    }

    #[test]
    fn holds_within_radius_with_hysteresis() {
        let mut r = Rendezvous::with(20, 200);
        let p = r.plan(&me(100.0, 100.0), &[n(2, 130, 100)]);
        assert!(p.converged && p.guidance == Guidance::Hold);
        // 22 units away: beyond the radius, within the hysteresis.
        let p = r.plan(&me(100.0, 100.0), &[n(2, 144, 100)]);
        assert!(p.converged);
        let p = r.plan(&me(100.0, 100.0), &[n(2, 160, 100)]);
        assert!(!p.converged && p.phase == Phase::Approach);
    }

    #[test]
    fn holds_when_blocked_by_a_car_nearer_the_mean() {
        let mut r = Rendezvous::with(20, 200);
        // Mean at (200, 100); a car at (180, 100) lies between me and it, 80 units away.
        let fresh = [n(2, 180, 100), n(3, 320, 100)];
        let p = r.plan(&me(100.0, 100.0), &fresh);
        assert!(p.converged && p.guidance == Guidance::Hold, "{p:?}");
        // The same car off to the side does not block.
        let fresh = [n(2, 100, 180), n(3, 400, 20)];
        assert!(!r.plan(&me(100.0, 100.0), &fresh).converged);
    }

    #[test]
    fn alone_is_already_there() {
        let mut r = Rendezvous::with(20, 200);
        assert!(r.plan(&me(300.0, 300.0), &[]).converged);
    }
}
