//! Leader-follower formation: line or wedge behind the leader.
//!
//! Each follower computes its slot in the leader's frame from the leader's latest broadcast
//! pose (advanced by its velocity over the broadcast's age) and drives towards it with the
//! leader's velocity as feed-forward plus a proportional correction. The leader itself drives
//! to a waypoint set by the application ([`Formation::set_waypoint`]) at the cruise speed, or
//! holds. A follower without a fresh leader stops ([`Phase::NoReference`]).

use crate::geom::{mrad_to_rad, Vec2};
use crate::{Guidance, Maneuver, Me, Neighbour, Phase, Plan, MM_PER_UNIT};

/// Formation geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Shape {
    /// Single file behind the leader: slot `k` is `(k + 1) * spacing` behind.
    #[default]
    Line = 0,
    /// V opening backwards at 45 degrees each side: slot `k` is in row `k / 2 + 1`, on the
    /// left for even `k`, `row * spacing` from the leader along its arm.
    Wedge = 1,
}

/// Gain of the position correction, 1/s.
const POSITION_GAIN: f32 = 1.2;
/// Slot error below which a follower counts as in formation, tracking units (30 mm).
pub const TOLERANCE_UNITS: f32 = 12.0;
/// A leader slower than this (mm/s) counts as standing still.
const LEADER_STILL_MM_S: f32 = 15.0;
/// The leader counts as at its waypoint within this distance, tracking units.
const ARRIVAL_UNITS: f32 = 8.0;

/// The formation law.
#[derive(Debug, Clone, PartialEq)]
pub struct Formation {
    shape: Shape,
    leader: u8,
    slot: Option<u8>,
    spacing: f32,
    speed: f32,
    waypoint: Option<Vec2>,
    holding: bool,
}

impl Formation {
    /// A formation behind car `leader`; `slot` `None` takes this car's rank among the
    /// followers' IDs; spacing in tracking units; leader cruise speed in mm/s.
    pub fn new(
        shape: Shape,
        leader: u8,
        slot: Option<u8>,
        spacing_units: u16,
        speed_mm_s: u16,
    ) -> Self {
        Self {
            shape,
            leader,
            slot,
            spacing: f32::from(spacing_units),
            speed: f32::from(speed_mm_s),
            waypoint: None,
            holding: false,
        }
    }

    /// Where the leader drives next (tracking units); only the leader uses it.
    pub fn set_waypoint(&mut self, x: u16, y: u16) {
        self.waypoint = Some(Vec2::new(f32::from(x), f32::from(y)));
    }

    /// Offset of slot `k` in the leader's frame (forward, left), tracking units.
    pub fn slot_offset(&self, k: u8) -> Vec2 {
        let s = self.spacing;
        match self.shape {
            Shape::Line => Vec2::new(-(f32::from(k) + 1.0) * s, 0.0),
            Shape::Wedge => {
                let row = f32::from(k / 2 + 1);
                let side = if k.is_multiple_of(2) { 1.0 } else { -1.0 };
                let d = row * s * core::f32::consts::FRAC_1_SQRT_2;
                Vec2::new(-d, side * d)
            }
        }
    }

    fn my_slot(&self, me: &Me, fresh: &[Neighbour]) -> u8 {
        self.slot.unwrap_or_else(|| {
            let rank = fresh
                .iter()
                .filter(|n| n.id != self.leader && n.id < me.id)
                .count();
            u8::try_from(rank).unwrap_or(u8::MAX)
        })
    }

    fn plan_leader(&mut self, me: &Me) -> Plan {
        match self.waypoint {
            Some(w) => {
                let d = (w - me.pos).norm();
                if d <= ARRIVAL_UNITS {
                    self.waypoint = None;
                    return Plan {
                        guidance: Guidance::Hold,
                        phase: Phase::Hold,
                        converged: true,
                        error_units: d,
                    };
                }
                Plan {
                    guidance: Guidance::Point {
                        at: w,
                        speed_mm_s: self.speed,
                    },
                    phase: Phase::Approach,
                    converged: false,
                    error_units: d,
                }
            }
            None => Plan {
                guidance: Guidance::Hold,
                phase: Phase::Hold,
                converged: true,
                error_units: 0.0,
            },
        }
    }
}

impl Maneuver for Formation {
    fn plan(&mut self, me: &Me, fresh: &[Neighbour]) -> Plan {
        if me.id == self.leader {
            return self.plan_leader(me);
        }
        let Some(leader) = fresh.iter().find(|n| n.id == self.leader) else {
            self.holding = false;
            return Plan {
                guidance: Guidance::Hold,
                phase: Phase::NoReference,
                converged: false,
                error_units: 0.0,
            };
        };
        let heading = mrad_to_rad(leader.pose.heading_mrad);
        let fwd = Vec2::from_angle(heading);
        let v_leader = f32::from(leader.pose.velocity_mm_s);
        let age_s = leader.age_us as f32 * 1e-6;
        let leader_pos = Vec2::new(f32::from(leader.pose.x), f32::from(leader.pose.y))
            + fwd * (v_leader * age_s / MM_PER_UNIT);
        let off = self.slot_offset(self.my_slot(me, fresh));
        let target = leader_pos + fwd * off.x + fwd.perp() * off.y;
        let err = target - me.pos;
        let e = err.norm();
        let leader_still = v_leader.abs() < LEADER_STILL_MM_S;
        // Hold once in the slot behind a standing leader; move again when pushed out of it.
        if leader_still && (e < TOLERANCE_UNITS || (self.holding && e < 1.5 * TOLERANCE_UNITS)) {
            self.holding = true;
            return Plan {
                guidance: Guidance::Hold,
                phase: Phase::Hold,
                converged: true,
                error_units: e,
            };
        }
        self.holding = false;
        let v = fwd * v_leader + err * (POSITION_GAIN * MM_PER_UNIT);
        let max = (2.0 * self.speed).max(300.0);
        Plan {
            guidance: Guidance::Velocity(v.clamp_norm(max)),
            phase: if e < TOLERANCE_UNITS {
                Phase::Track
            } else {
                Phase::Approach
            },
            converged: e < TOLERANCE_UNITS,
            error_units: e,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CarPose;

    fn leader_at(x: u16, y: u16, heading_mrad: u16, v: i16) -> Neighbour {
        Neighbour {
            id: 1,
            pose: CarPose {
                x,
                y,
                heading_mrad,
                velocity_mm_s: v,
            },
            age_us: 0,
        }
    }

    fn me(id: u8, x: f32, y: f32) -> Me {
        Me {
            id,
            pos: Vec2::new(x, y),
            heading: 0.0,
            speed: 0.0,
        }
    }

    #[test]
    fn slot_offsets() {
        let line = Formation::new(Shape::Line, 1, None, 50, 100);
        assert_eq!(line.slot_offset(0), Vec2::new(-50.0, 0.0));
        assert_eq!(line.slot_offset(2), Vec2::new(-150.0, 0.0));
        let wedge = Formation::new(Shape::Wedge, 1, None, 50, 100);
        let o0 = wedge.slot_offset(0);
        let o1 = wedge.slot_offset(1);
        let o2 = wedge.slot_offset(2);
        assert!((o0.x + 35.355).abs() < 0.01 && (o0.y - 35.355).abs() < 0.01);
        assert!((o1.x + 35.355).abs() < 0.01 && (o1.y + 35.355).abs() < 0.01);
        assert!((o2.norm() - 100.0).abs() < 0.01 && o2.y > 0.0);
    }

    #[test]
    fn follower_targets_slot_in_leader_frame() {
        // Leader at (300, 400) heading +Y (1571 mrad), standing. Slot 0 of a line is 50 below.
        let mut f = Formation::new(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 1571, 0)];
        let p = f.plan(&me(2, 300.0, 300.0), &n);
        assert_eq!(p.phase, Phase::Approach);
        assert!((p.error_units - 50.0).abs() < 0.1);
        match p.guidance {
            Guidance::Velocity(v) => assert!(v.y > 50.0 && v.x.abs() < 1.0),
            other => panic!("{other:?}"),
        }
        // In the slot: hold.
        let p = f.plan(&me(2, 300.0, 350.0), &n);
        assert_eq!(p.guidance, Guidance::Hold);
        assert!(p.converged);
    }

    #[test]
    fn follower_matches_leader_velocity() {
        let mut f = Formation::new(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 0, 200)];
        let p = f.plan(&me(2, 250.0, 400.0), &n);
        match p.guidance {
            Guidance::Velocity(v) => assert!((v.x - 200.0).abs() < 1.0 && v.y.abs() < 1.0),
            other => panic!("{other:?}"),
        }
        assert_eq!(p.phase, Phase::Track);
    }

    #[test]
    fn slot_by_rank_among_followers() {
        let mut f = Formation::new(Shape::Line, 1, None, 40, 100);
        let mut n = [leader_at(300, 400, 1571, 0); 3];
        n[1].id = 3;
        n[2].id = 7;
        // Car 5 is behind car 3 only: slot 1, 80 units behind the leader.
        let p = f.plan(&me(5, 300.0, 320.0), &n);
        assert!(p.converged, "{p:?}");
        let p = f.plan(&me(2, 300.0, 320.0), &n);
        assert!(!p.converged);
    }

    #[test]
    fn missing_leader_stops() {
        let mut f = Formation::new(Shape::Wedge, 1, None, 40, 100);
        let p = f.plan(&me(2, 300.0, 320.0), &[]);
        assert_eq!(p.guidance, Guidance::Hold);
        assert_eq!(p.phase, Phase::NoReference);
    }

    #[test]
    fn leader_drives_to_waypoint_then_holds() {
        let mut f = Formation::new(Shape::Line, 1, None, 40, 150);
        assert_eq!(f.plan(&me(1, 100.0, 100.0), &[]).guidance, Guidance::Hold);
        f.set_waypoint(100, 500);
        let p = f.plan(&me(1, 100.0, 100.0), &[]);
        assert_eq!(
            p.guidance,
            Guidance::Point {
                at: Vec2::new(100.0, 500.0),
                speed_mm_s: 150.0
            }
        );
        let p = f.plan(&me(1, 100.0, 495.0), &[]);
        assert_eq!(p.guidance, Guidance::Hold);
    }
}
