//! Drive to a point and stop (for example the pose of a radio `Target` group message).

use crate::geom::Vec2;
use crate::{Guidance, Maneuver, Me, Neighbour, Phase, Plan};

/// Arrival distance, tracking units (the LBC's own `MOVE_XY` arrival distance).
pub const ARRIVAL_UNITS: f32 = 8.0;

/// The go-to law.
#[derive(Debug, Clone, PartialEq)]
pub struct GoTo {
    target: Vec2,
    speed: f32,
    arrived: bool,
}

impl GoTo {
    /// Target in tracking units, cruise speed in mm/s.
    pub fn new(x: u16, y: u16, speed_mm_s: u16) -> Self {
        Self {
            target: Vec2::new(f32::from(x), f32::from(y)),
            speed: f32::from(speed_mm_s),
            arrived: false,
        }
    }
}

impl Maneuver for GoTo {
    fn plan(&mut self, me: &Me, _fresh: &[Neighbour]) -> Plan {
        let e = (self.target - me.pos).norm();
        // Once there, stay unless pushed well away.
        self.arrived = e
            <= if self.arrived {
                3.0 * ARRIVAL_UNITS
            } else {
                ARRIVAL_UNITS
            };
        Plan {
            guidance: if self.arrived {
                Guidance::Hold
            } else {
                Guidance::Point {
                    at: self.target,
                    speed_mm_s: self.speed,
                }
            },
            phase: if self.arrived {
                Phase::Hold
            } else {
                Phase::Approach
            },
            converged: self.arrived,
            error_units: e,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn approaches_then_holds() {
        let mut g = GoTo::new(100, 200, 250);
        let me = |x, y| Me {
            id: 1,
            pos: Vec2::new(x, y),
            heading: 0.0,
            speed: 0.0,
        };
        let p = g.plan(&me(100.0, 100.0), &[]);
        assert_eq!(p.phase, Phase::Approach);
        assert!((p.error_units - 100.0).abs() < 1e-3);
        let p = g.plan(&me(100.0, 195.0), &[]);
        assert_eq!(p.guidance, Guidance::Hold);
        assert!(g.plan(&me(100.0, 180.0), &[]).converged);
        assert!(!g.plan(&me(100.0, 170.0), &[]).converged);
    }
}
