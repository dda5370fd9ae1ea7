//! Drive to a point and stop; each waypoint given later becomes the new point.

use crate::law::{Guidance, Law, LawInput, Plan};
use crate::param::{Param, Values};
use crate::{imath, Phase};

/// The go-to law. Written in integers.
#[derive(Debug, Clone, PartialEq)]
pub struct GoTo {
    target: (u16, u16),
    speed: u16,
    arrived: bool,
    /// Index of the waypoint driven to (`None`: the point of the command).
    waypoint: Option<u16>,
}

impl Law for GoTo {
    const NAME: &'static str = "goto";
    const SUMMARY: &'static str = "Drive to a point and hold within the arrival radius (moving again if pushed beyond three times it); a waypoint replaces the point.";
    const PARAMS: &'static [Param] = &[
        Param::int("x", "units", 0, 1023).doc("target X (moved inside the walls)"),
        Param::int("y", "units", 0, 1023).doc("target Y (moved inside the walls)"),
        Param::int("speed_mm_s", "mm/s", 0, 2047)
            .default(200)
            .doc("cruise speed (slowing down on arrival)"),
    ];

    fn new(p: &Values) -> Self {
        Self::with(p.u16(0), p.u16(1), p.u16(2))
    }

    fn step(&mut self, input: &LawInput<'_>) -> Plan {
        if let Some(w) = input.waypoint {
            if self.waypoint != Some(w.index) {
                self.waypoint = Some(w.index);
                self.target = (w.x, w.y);
                self.arrived = false;
            }
        }
        let (x, y) = input.area.clamp(self.target.0, self.target.1);
        let d2 = imath::dist2(
            i32::from(x) - i32::from(input.own.x),
            i32::from(y) - i32::from(input.own.y),
        );
        let arrival = u32::from(input.options.arrival_units);
        // Once there, stay unless pushed well away.
        let limit = if self.arrived { 3 * arrival } else { arrival };
        self.arrived = d2 <= limit * limit;
        // At most 65 535 (the root of a u32): fits.
        let error_units = imath::isqrt(d2) as u16;
        if self.arrived {
            return Plan::hold(Phase::Hold, true, error_units);
        }
        Plan {
            guidance: Guidance::Point {
                x,
                y,
                speed_mm_s: self.speed,
            },
            phase: Phase::Approach,
            converged: false,
            error_units,
        }
    }
}

impl GoTo {
    /// Target in tracking units, cruise speed in mm/s.
    pub fn with(x: u16, y: u16, speed_mm_s: u16) -> Self {
        Self {
            target: (x, y),
            speed: speed_mm_s,
            arrived: false,
            waypoint: None,
        }
    }

    /// The group command for this go-to.
    pub fn params(
        x: u16,
        y: u16,
        speed_mm_s: u16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[i32::from(x), i32::from(y), i32::from(speed_mm_s)],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::law::{GoalArea, LawOptions, Waypoint};
    use crate::CarPose;

    const AREA: GoalArea = GoalArea {
        x_min: 58,
        x_max: 542,
        y_min: 58,
        y_max: 742,
    };

    fn at(g: &mut GoTo, x: u16, y: u16, waypoint: Option<Waypoint>, arrival: u8) -> Plan {
        g.step(&LawInput {
            now_us: 0,
            id: 1,
            own: CarPose {
                x,
                y,
                ..CarPose::default()
            },
            neighbours: &[],
            waypoint,
            options: LawOptions {
                arrival_units: arrival,
                ..LawOptions::DEFAULT
            },
            area: AREA,
        })
    }

    #[test]
    fn approaches_then_holds() {
        let mut g = GoTo::with(100, 200, 250);
        let p = at(&mut g, 100, 100, None, 8);
        assert_eq!(p.phase, Phase::Approach);
        assert_eq!(p.error_units, 100);
        assert_eq!(
            p.guidance,
            Guidance::Point {
                x: 100,
                y: 200,
                speed_mm_s: 250
            }
        );
        let p = at(&mut g, 100, 195, None, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        assert!(at(&mut g, 100, 180, None, 8).converged);
        assert!(!at(&mut g, 100, 170, None, 8).converged);
    }

    #[test]
    fn targets_are_clamped_and_waypoints_replace_them() {
        let mut g = GoTo::with(1000, 10, 250);
        assert!(matches!(
            at(&mut g, 300, 300, None, 8).guidance,
            Guidance::Point { x: 542, y: 58, .. }
        ));
        let w = Waypoint {
            x: 300,
            y: 500,
            index: 0,
        };
        assert!(matches!(
            at(&mut g, 300, 300, Some(w), 8).guidance,
            Guidance::Point { x: 300, y: 500, .. }
        ));
        // A 30-unit arrival radius: there at 25 units.
        assert!(at(&mut g, 300, 475, Some(w), 30).converged);
    }
}
