//! Leader-follower formation: line or wedge behind the leader.
//!
//! Each follower computes its slot in the leader's frame from the leader's latest broadcast
//! pose (advanced by its velocity over the broadcast's age) and drives towards it with the
//! leader's velocity as feed-forward plus a proportional correction. The leader itself drives
//! to the latest waypoint ([`LawInput::waypoint`]) at the cruise speed, and holds once within
//! its arrival radius (until the next waypoint). A follower without a fresh leader stops
//! ([`Phase::NoReference`]).

use crate::geom::{mrad_to_rad, Vec2};
use crate::law::{error_units, Guidance, Law, LawInput, Me, Plan, Waypoint};
use crate::param::{Param, Values};
use crate::{Neighbour, Phase, MM_PER_UNIT};

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

const SHAPE: usize = 0;
const LEADER: usize = 1;
const SLOT: usize = 2;
const SPACING: usize = 3;
const SPEED: usize = 4;

/// The formation law.
#[derive(Debug, Clone, PartialEq)]
pub struct Formation {
    shape: Shape,
    leader: u8,
    slot: Option<u8>,
    spacing: f32,
    speed: f32,
    speed_mm_s: u16,
    /// Index of the last waypoint the leader reached.
    reached: Option<u16>,
    holding: bool,
}

impl Law for Formation {
    const NAME: &'static str = "formation";
    const SUMMARY: &'static str = "Leader-follower formation: the followers keep slots of a line or a wedge in the leader's frame; the leader drives through the waypoints.";
    const PARAMS: &'static [Param] = &[
        Param::choice("shape", &["line", "wedge"])
            .doc("line: single file behind the leader; wedge: a V opening backwards at 45 degrees (slot 0 front left, 1 front right, ...)"),
        Param::int("leader", "car ID", 1, 126).doc("the leader's car ID"),
        Param::int("slot", "", -1, 14)
            .default(-1)
            .doc("this car's slot; -1: its rank among the followers' IDs"),
        Param::int("spacing_units", "units", 1, 511)
            .default(100)
            .doc("distance between neighbouring slots; at least 100 keeps the slots out of the avoidance band"),
        Param::int("speed_mm_s", "mm/s", 0, 2047)
            .default(150)
            .doc("the leader's cruise speed towards its waypoint"),
    ];

    fn new(p: &Values) -> Self {
        Self::with(
            if p.get(SHAPE) == 1 {
                Shape::Wedge
            } else {
                Shape::Line
            },
            p.u8(LEADER),
            u8::try_from(p.get(SLOT)).ok(),
            p.u16(SPACING),
            p.u16(SPEED),
        )
    }

    fn step(&mut self, input: &LawInput<'_>) -> Plan {
        self.plan(&input.me(), input.neighbours, input.waypoint, input.options.arrival_units)
    }

    fn leads(&self, id: u8) -> bool {
        id == self.leader
    }
}

impl Formation {
    /// A formation behind car `leader`; `slot` `None` takes this car's rank among the
    /// followers' IDs; spacing in tracking units; leader cruise speed in mm/s.
    pub fn with(
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
            speed_mm_s,
            reached: None,
            holding: false,
        }
    }

    /// The group command for this formation (`slot` `None`: by rank).
    pub fn params(
        shape: Shape,
        leader: u8,
        slot: Option<u8>,
        spacing_units: u16,
        speed_mm_s: u16,
    ) -> Result<crate::ManeuverParams, crate::EncodeError> {
        crate::ManeuverParams::new(
            <Self as crate::registry::Registered>::ID,
            &[
                shape as i32,
                i32::from(leader),
                slot.map_or(-1, i32::from),
                i32::from(spacing_units),
                i32::from(speed_mm_s),
            ],
        )
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

    fn plan_leader(&mut self, me: &Me, waypoint: Option<Waypoint>, arrival_units: u8) -> Plan {
        match waypoint.filter(|w| Some(w.index) != self.reached) {
            Some(w) => {
                let d = (Vec2::new(f32::from(w.x), f32::from(w.y)) - me.pos).norm();
                if d <= f32::from(arrival_units) {
                    self.reached = Some(w.index);
                    return Plan::hold(Phase::Hold, true, error_units(d));
                }
                Plan {
                    guidance: Guidance::Point {
                        x: w.x,
                        y: w.y,
                        speed_mm_s: self.speed_mm_s,
                    },
                    phase: Phase::Approach,
                    converged: false,
                    error_units: error_units(d),
                }
            }
            None => Plan::hold(Phase::Hold, true, 0),
        }
    }

    /// One period for car `me` with its fresh neighbours, the latest waypoint and the
    /// arrival radius.
    fn plan(
        &mut self,
        me: &Me,
        fresh: &[Neighbour],
        waypoint: Option<Waypoint>,
        arrival_units: u8,
    ) -> Plan {
        if me.id == self.leader {
            return self.plan_leader(me, waypoint, arrival_units);
        }
        let Some(leader) = fresh.iter().find(|n| n.id == self.leader) else {
            self.holding = false;
            return Plan::hold(Phase::NoReference, false, 0);
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
            return Plan::hold(Phase::Hold, true, error_units(e));
        }
        self.holding = false;
        let v = fwd * v_leader + err * (POSITION_GAIN * MM_PER_UNIT);
        let max = (2.0 * self.speed).max(300.0);
        Plan {
            guidance: Guidance::VelocityF(v.clamp_norm(max)),
            phase: if e < TOLERANCE_UNITS {
                Phase::Track
            } else {
                Phase::Approach
            },
            converged: e < TOLERANCE_UNITS,
            error_units: error_units(e),
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
        let line = Formation::with(Shape::Line, 1, None, 50, 100);
        assert_eq!(line.slot_offset(0), Vec2::new(-50.0, 0.0));
        assert_eq!(line.slot_offset(2), Vec2::new(-150.0, 0.0));
        let wedge = Formation::with(Shape::Wedge, 1, None, 50, 100);
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
        let mut f = Formation::with(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 1571, 0)];
        let p = f.plan(&me(2, 300.0, 300.0), &n, None, 8);
        assert_eq!(p.phase, Phase::Approach);
        assert!(p.error_units.abs_diff(50) <= 1, "{p:?}");
        match p.guidance {
            Guidance::VelocityF(v) => assert!(v.y > 50.0 && v.x.abs() < 1.0),
            other => panic!("{other:?}"),
        }
        // In the slot: hold.
        let p = f.plan(&me(2, 300.0, 350.0), &n, None, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        assert!(p.converged);
    }

    #[test]
    fn follower_matches_leader_velocity() {
        let mut f = Formation::with(Shape::Line, 1, Some(0), 50, 100);
        let n = [leader_at(300, 400, 0, 200)];
        let p = f.plan(&me(2, 250.0, 400.0), &n, None, 8);
        match p.guidance {
            Guidance::VelocityF(v) => assert!((v.x - 200.0).abs() < 1.0 && v.y.abs() < 1.0),
            other => panic!("{other:?}"),
        }
        assert_eq!(p.phase, Phase::Track);
    }

    #[test]
    fn slot_by_rank_among_followers() {
        let mut f = Formation::with(Shape::Line, 1, None, 40, 100);
        let mut n = [leader_at(300, 400, 1571, 0); 3];
        n[1].id = 3;
        n[2].id = 7;
        // Car 5 is behind car 3 only: slot 1, 80 units behind the leader.
        let p = f.plan(&me(5, 300.0, 320.0), &n, None, 8);
        assert!(p.converged, "{p:?}");
        let p = f.plan(&me(2, 300.0, 320.0), &n, None, 8);
        assert!(!p.converged);
    }

    #[test]
    fn missing_leader_stops() {
        let mut f = Formation::with(Shape::Wedge, 1, None, 40, 100);
        let p = f.plan(&me(2, 300.0, 320.0), &[], None, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        assert_eq!(p.phase, Phase::NoReference);
    }

    #[test]
    fn leader_drives_to_waypoint_then_holds() {
        let mut f = Formation::with(Shape::Line, 1, None, 40, 150);
        assert_eq!(f.plan(&me(1, 100.0, 100.0), &[], None, 8).guidance, Guidance::Hold);
        let w = Some(Waypoint {
            x: 100,
            y: 500,
            index: 0,
        });
        let p = f.plan(&me(1, 100.0, 100.0), &[], w, 8);
        assert_eq!(
            p.guidance,
            Guidance::Point {
                x: 100,
                y: 500,
                speed_mm_s: 150
            }
        );
        let p = f.plan(&me(1, 100.0, 495.0), &[], w, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        // Reached: it holds there even when pushed away, until the next waypoint.
        let p = f.plan(&me(1, 100.0, 400.0), &[], w, 8);
        assert_eq!(p.guidance, Guidance::Hold);
        let next = Waypoint {
            x: 100,
            y: 500,
            index: 1,
        };
        assert!(matches!(
            f.plan(&me(1, 100.0, 400.0), &[], Some(next), 8).guidance,
            Guidance::Point { .. }
        ));
        // A wider arrival radius counts it as there sooner.
        let third = Waypoint { index: 2, ..next };
        assert_eq!(
            f.plan(&me(1, 100.0, 480.0), &[], Some(third), 30).guidance,
            Guidance::Hold
        );
    }
}
