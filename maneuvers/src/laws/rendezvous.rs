//! Rendezvous by average consensus.
//!
//! Every car drives towards the mean of its own position and its fresh neighbours' positions,
//! with a speed proportional to the distance (gain [`GAIN`], saturated at the maneuver speed),
//! and holds once within the arrival radius. With all cars hearing each other the mean is
//! invariant under this law (the velocities sum to zero while none saturates), so each car's
//! distance to it decays as `exp(-GAIN t)`; see `docs/maneuvers.md` for the bound and the
//! measured times.

use crate::fixed::{fx, IVec2};
use crate::law::{error_units_fx, Guidance, Law, LawInput, Plan};
use crate::param::{Param, Values};
use crate::{CarPose, Neighbour, Phase};

/// Consensus gain: 0.8/s, which is 2 mm/s per tracking unit of distance.
pub const GAIN_MM_S_PER_UNIT: i32 = 2;
/// A holding car starts again only when the consensus point is this much beyond the radius:
/// 13/10.
const HYSTERESIS: (i32, i32) = (13, 10);
/// A neighbour nearer than this (tracking units, 325 mm: the avoidance band of the default
/// [`crate::SafetyConfig`] plus a little) that is closer to the consensus point and within 60
/// degrees of the way there blocks the car: it holds instead of pushing into the avoidance field.
pub const BLOCK_UNITS: i32 = 130;

/// The rendezvous law.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendezvous {
    radius_units: u16,
    speed_mm_s: u16,
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
        self.plan(&input.own, input.neighbours)
    }
}

/// A pose's position, 1/16 tracking unit.
fn position(p: &CarPose) -> IVec2 {
    IVec2::from_units(i32::from(p.x), i32::from(p.y))
}

impl Rendezvous {
    /// Arrival radius in tracking units, maximum speed in mm/s.
    pub fn with(radius_units: u16, speed_mm_s: u16) -> Self {
        Self {
            radius_units,
            speed_mm_s,
            holding: false,
        }
    }

    /// The consensus point: mean of this car (at `own`) and its fresh neighbours, 1/16
    /// tracking unit (rounded towards zero).
    pub fn consensus(own: &CarPose, fresh: &[Neighbour]) -> IVec2 {
        let mut sum = position(own);
        for n in fresh {
            sum = sum + position(&n.pose);
        }
        // At most a few dozen cars: the count converts exactly.
        let count = fresh.len() as i32 + 1;
        IVec2::new(sum.x / count, sum.y / count)
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

    /// One period for the car at `own` with its fresh neighbours.
    fn plan(&mut self, own: &CarPose, fresh: &[Neighbour]) -> Plan {
        let me = position(own);
        let c = Self::consensus(own, fresh);
        let err = c - me;
        let e2 = err.len2();
        let e = err.norm();
        let radius = fx(i32::from(self.radius_units));
        let limit = if self.holding {
            radius * HYSTERESIS.0 / HYSTERESIS.1
        } else {
            radius
        };
        let block = fx(BLOCK_UNITS);
        let block = i64::from(if self.holding { block * 6 / 5 } else { block });
        let blocked = fresh.iter().any(|n| {
            let q = position(&n.pose);
            let to = q - me;
            let d2 = to.len2();
            // Near, nearer the consensus point, and within 60 degrees of the way there:
            // to . err > |to| |err| / 2, squared.
            let along = to.dot(err);
            d2 < (block * block) as u64
                && (c - q).len2() < e2
                && along > 0
                // Saturating: far outside the arena the test only errs towards not blocked.
                && (along as u64).saturating_mul(along as u64).saturating_mul(4)
                    > d2.saturating_mul(e2)
        });
        self.holding = e <= limit || (blocked && e <= radius + fx(BLOCK_UNITS));
        if self.holding {
            return Plan::hold(Phase::Hold, true, error_units_fx(e));
        }
        let v = err.times(GAIN_MM_S_PER_UNIT);
        Plan {
            guidance: Guidance::velocity(v.clamp_norm(fx(i32::from(self.speed_mm_s)))),
            phase: Phase::Approach,
            converged: false,
            error_units: error_units_fx(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    #[test]
    fn moves_towards_the_mean() {
        let mut r = Rendezvous::with(20, 200);
        let fresh = [n(2, 400, 100), n(3, 100, 400)];
        // Mean of (100,100), (400,100), (100,400) is (200,200).
        assert_eq!(
            Rendezvous::consensus(&at(100, 100), &fresh),
            IVec2::from_units(200, 200)
        );
        let p = r.plan(&at(100, 100), &fresh);
        // Saturated at the speed, towards the mean.
        assert_eq!(
            p.guidance,
            Guidance::Velocity {
                vx_mm_s: 141,
                vy_mm_s: 141
            }
        );
        assert_eq!(p.error_units, 141);
    }

    #[test]
    fn proportional_inside_saturation() {
        let mut r = Rendezvous::with(5, 1000);
        let p = r.plan(&at(90, 100), &[n(2, 110, 100)]);
        // 10 units = 25 mm from the mean: 0.8/s * 25 mm = 20 mm/s.
        assert_eq!(
            p.guidance,
            Guidance::Velocity {
                vx_mm_s: 20,
                vy_mm_s: 0
            }
        );
    }

    #[test]
    fn holds_within_radius_with_hysteresis() {
        let mut r = Rendezvous::with(20, 200);
        let p = r.plan(&at(100, 100), &[n(2, 130, 100)]);
        assert!(p.converged && p.guidance == Guidance::Hold);
        // 22 units away: beyond the radius, within the hysteresis.
        let p = r.plan(&at(100, 100), &[n(2, 144, 100)]);
        assert!(p.converged);
        let p = r.plan(&at(100, 100), &[n(2, 160, 100)]);
        assert!(!p.converged && p.phase == Phase::Approach);
    }

    #[test]
    fn holds_when_blocked_by_a_car_nearer_the_mean() {
        let mut r = Rendezvous::with(20, 200);
        // Mean at (200, 100); a car at (180, 100) lies between me and it, 80 units away.
        let fresh = [n(2, 180, 100), n(3, 320, 100)];
        let p = r.plan(&at(100, 100), &fresh);
        assert!(p.converged && p.guidance == Guidance::Hold, "{p:?}");
        // The same car off to the side does not block.
        let fresh = [n(2, 100, 180), n(3, 400, 20)];
        assert!(!r.plan(&at(100, 100), &fresh).converged);
    }

    #[test]
    fn alone_is_already_there() {
        let mut r = Rendezvous::with(20, 200);
        assert!(r.plan(&at(300, 300), &[]).converged);
    }
}
