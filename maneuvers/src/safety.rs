//! Car and wall avoidance, layered on top of every law.
//!
//! Two mechanisms, both from the broadcast poses only:
//!
//! * a **field** applied to the law's desired velocity: within `safety_radius + influence` of a
//!   fresh neighbour's body, the part of the velocity relative to that neighbour which closes
//!   the distance is removed progressively (all of it at the safety radius), half of it turned
//!   into a sideways term so that cars pass each other on their right; inside the safety radius
//!   a push away is added. Cars moving in parallel are left alone. A moving neighbour with a
//!   higher ID takes only half the effort (the higher ID yields). Towards a wall the velocity
//!   component into it fades out across `wall_influence`, and beyond the keep-out a push back
//!   is added;
//! * a **gate** on the resulting command: the car's body and each neighbour's body (advanced
//!   along its broadcast velocity, including the broadcast's age) are predicted over
//!   `horizon_s`; a command that would bring the bodies closer than `safety_radius + guard` or
//!   the body beyond the wall keep-out, while making it worse than standing still, is refused.
//!   The controller then tries full-lock and reverse alternatives, and else holds still
//!   (priority to the lower ID: a car refused because of a lower-ID car backs away).
//!
//! Distances are between body centres: the pose is the rear-axle midpoint and the body of the
//! 100 mm car is centred [`SafetyConfig::body_offset_units`] ahead of it.

use crate::drive::{predict, Sv};
use crate::fixed::{from_mrad, fx, mul_q14, mul_shift, IVec2, Q14};
use crate::{CarPose, Neighbour, ARENA_X_MAX, ARENA_Y_MAX};

/// Avoidance parameters (tracking units unless named otherwise).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub struct SafetyConfig {
    /// Minimum distance between body centres: car length 100 mm + 50 mm margin.
    pub safety_radius_units: u16,
    /// Extra margin the gate keeps beyond the safety radius.
    pub guard_units: u16,
    /// Width of the repulsive band beyond the safety radius (at least 1).
    pub influence_units: u16,
    /// Body centre ahead of the rear axle (40 mm).
    pub body_offset_units: u16,
    /// Radius of the circle that covers the body (60 mm).
    pub body_radius_units: u16,
    /// Keep-out between the body circle and a wall.
    pub wall_margin_units: u16,
    /// Width of the repulsive band beyond the wall keep-out (at least 1).
    pub wall_influence_units: u16,
    /// Strength of the push out of the safety radius and off the walls, mm/s per band width.
    pub repulse_mm_s: u16,
    /// Prediction horizon of the gate, ms (at most [`crate::drive::MAX_PREDICT_MS`]).
    pub horizon_ms: u16,
    /// Neighbours older than this are ignored, microseconds.
    pub stale_after_us: u32,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            safety_radius_units: 60,
            guard_units: 6,
            influence_units: 36,
            body_offset_units: 16,
            body_radius_units: 24,
            wall_margin_units: 8,
            wall_influence_units: 30,
            repulse_mm_s: 250,
            horizon_ms: 450,
            stale_after_us: 500_000,
        }
    }
}

/// This car as the avoidance sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ego {
    /// Car ID.
    pub id: u8,
    /// Rear axle, 1/16 tracking unit.
    pub pos: IVec2,
    /// Heading, binary angle.
    pub heading: i32,
}

impl Ego {
    /// Car `id` at `pose`.
    pub fn new(id: u8, pose: &CarPose) -> Self {
        Self {
            id,
            pos: IVec2::from_units(i32::from(pose.x), i32::from(pose.y)),
            heading: from_mrad(i32::from(pose.heading_mrad)),
        }
    }
}

/// Distance travelled in `t_us` microseconds at `velocity` (1/16 mm/s), in 1/16 tracking unit
/// (`t_us` is capped at 2^24, 16.8 s).
// Out of line: its 64-bit products inlined at each use cost the firmware 216 bytes more.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn travelled(velocity: i32, t_us: u32) -> i32 {
    // 1/2.5 mm per unit and 1e-6 s per us, Q36.
    const PER_US_Q36: i64 = (68_719_476_736.0 / 2_500_000.0 + 0.5) as i64;
    // |velocity| < 2^20 and t < 2^24: the product of all three stays below 2^59.
    mul_shift(
        i64::from(velocity) * i64::from(t_us.min(1 << 24)),
        PER_US_Q36,
        36,
    )
}

/// How far `velocity` (1/16 mm/s) goes in `t_us` microseconds, 1/16 tracking unit.
// Out of line: inlined at each use, it made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub(crate) fn travel(velocity: IVec2, t_us: u32) -> IVec2 {
    IVec2::new(travelled(velocity.x, t_us), travelled(velocity.y, t_us))
}

impl SafetyConfig {
    /// Body centre of a car at rear-axle `pos` (1/16 unit) with `heading` (binary angle).
    pub fn body(&self, pos: IVec2, heading: i32) -> IVec2 {
        pos + IVec2::from_angle(heading).along(fx(i32::from(self.body_offset_units)))
    }

    /// A neighbour as an obstacle: its body centre now (advanced along its broadcast
    /// velocity over the broadcast's age) and its velocity.
    pub fn obstacle(&self, n: &Neighbour) -> Obstacle {
        let heading = from_mrad(i32::from(n.pose.heading_mrad));
        let velocity = IVec2::from_angle(heading).along(fx(i32::from(n.pose.velocity_mm_s)));
        let pos = IVec2::from_units(i32::from(n.pose.x), i32::from(n.pose.y));
        let body = self.body(pos, heading) + travel(velocity, n.age_us);
        let at = |step: u16| body + travel(velocity, 1000 * u32::from(self.gate_ms(step)));
        Obstacle {
            id: n.id,
            body,
            velocity,
            steps: [at(1), at(2), at(3)],
        }
    }

    /// The gate's `step`-th instant (1..=3), ms: a third of the horizon each.
    fn gate_ms(&self, step: u16) -> u16 {
        self.horizon_ms * step / 3
    }

    /// Lowest and highest allowed body-centre coordinate along X and Y, whole units.
    fn keep_in(&self) -> (i32, i32, i32) {
        let m = i32::from(self.body_radius_units) + i32::from(self.wall_margin_units);
        (m, i32::from(ARENA_X_MAX) - m, i32::from(ARENA_Y_MAX) - m)
    }

    /// Distance of the goal area from each wall (see [`SafetyConfig::clamp_goal`]), tracking
    /// units: the body keeps out of the walls' keep-out whatever the heading, with a third of
    /// the wall band (rounded) to spare so that the goal can be reached.
    pub fn goal_margin_units(&self) -> u16 {
        self.body_radius_units
            + self.wall_margin_units
            + self.body_offset_units
            + (self.wall_influence_units + 1) / 3
    }

    /// A rear-axle goal moved into the goal area (tracking units).
    pub fn clamp_goal(&self, x: u16, y: u16) -> (u16, u16) {
        let m = self.goal_margin_units();
        // Not `Ord::clamp`: it panics on an empty range.
        (
            x.max(m).min(ARENA_X_MAX.saturating_sub(m)),
            y.max(m).min(ARENA_Y_MAX.saturating_sub(m)),
        )
    }
}

/// A neighbour's body, predicted along a straight line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Obstacle {
    /// Car ID.
    pub id: u8,
    /// Body centre now, 1/16 tracking unit.
    pub body: IVec2,
    /// Velocity, 1/16 mm/s.
    pub velocity: IVec2,
    /// Body centre at the gate's three instants (a third, two thirds and all of the horizon
    /// from now), computed once per control period for every rollout of the gate.
    pub steps: [IVec2; 3],
}

impl Obstacle {
    /// Body centre `t_ms` milliseconds from now.
    pub fn at(&self, t_ms: u16) -> IVec2 {
        self.body + travel(self.velocity, 1000 * u32::from(t_ms))
    }
}

/// `num / den` clamped into 0..=1, Q14 (`den > 0`).
// Out of line: its division and clamps inlined at each use cost the firmware 380 bytes more.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn ratio_q14(num: i32, den: i32) -> i32 {
    if num <= 0 {
        0
    } else if num >= den {
        Q14
    } else {
        // Distances and bands are below 2^21 sixteenths: scaled below 2^17, the shifted
        // numerator fits.
        if den < 1 << 17 {
            (num << 14) / den
        } else {
            ((num >> 4) << 14) / (den >> 4).max(1)
        }
    }
}

/// Adds the avoidance field to `desired` (1/16 mm/s). `holding` limits car repulsion to
/// neighbours already inside the safety radius, so that cars at rest stay at rest.
///
/// Inside the band `safety_radius..safety_radius + influence` the part of the velocity
/// relative to a neighbour that closes the distance is removed progressively (fully at the
/// safety radius), half of it reappearing as a sideways term to the right; cars moving in
/// parallel are left alone. Inside the safety radius a push away is added on top.
pub fn field(
    cfg: &SafetyConfig,
    me: &Ego,
    obstacles: &[Obstacle],
    desired: IVec2,
    holding: bool,
) -> IVec2 {
    let b = cfg.body(me.pos, me.heading);
    let mut v = desired;
    let radius = fx(i32::from(cfg.safety_radius_units));
    let band = fx(i32::from(cfg.influence_units.max(1)));
    let outer = radius + band;
    let reach = i64::from(if holding { radius } else { outer });
    let repulse = fx(i32::from(cfg.repulse_mm_s));
    // 20 mm/s, squared.
    let moving = (fx(20) * fx(20)) as u64;
    for n in obstacles {
        let to = n.body - b;
        // Far ones are left out before any root.
        if to.len2() >= (reach * reach) as u64 {
            continue;
        }
        let d = to.norm();
        let u = to.unit();
        // The higher ID yields: a moving neighbour with a higher ID takes half the effort.
        let half = n.id >= me.id && n.velocity.len2() > moving;
        let prio = |x: i32| if half { x / 2 } else { x };
        let w = prio(ratio_q14(outer - d, band));
        let closing = mul_shift((desired - n.velocity).dot(u), 1, 14);
        if closing > 0 {
            let cw = mul_q14(closing, w);
            let right = IVec2::new(u.y, -u.x);
            v = v - u.along(cw) + right.along(cw / 2);
        }
        if d < radius {
            let depth = ratio_q14(radius - d, band);
            v = v - u.along(prio(mul_q14(depth, repulse)));
        }
    }
    if holding && v == desired {
        return v;
    }
    // Walls: the component into a wall fades out across the band, and beyond the keep-in
    // edge a push back is added.
    let (lo, hi_x, hi_y) = cfg.keep_in();
    let wall_band = fx(i32::from(cfg.wall_influence_units.max(1)));
    let axis = |v: i32, c_lo: i32, c_hi: i32| -> i32 {
        let mut out = v;
        if out < 0 {
            out = mul_q14(out, ratio_q14(c_lo, wall_band));
        }
        if out > 0 {
            out = mul_q14(out, ratio_q14(c_hi, wall_band));
        }
        out + mul_q14(ratio_q14(-c_lo, wall_band), repulse)
            - mul_q14(ratio_q14(-c_hi, wall_band), repulse)
    };
    IVec2::new(
        axis(v.x, b.x - fx(lo), fx(hi_x) - b.x),
        axis(v.y, b.y - fx(lo), fx(hi_y) - b.y),
    )
}

/// Why the gate refused a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conflict {
    /// It would bring this car too close to the neighbour with this ID.
    Car(u8),
    /// It would take the body into the wall keep-out.
    Wall,
}

/// Checks a command over the prediction horizon; `Ok` when it is safe. Distances are compared
/// squared: no square roots.
pub fn gate(cfg: &SafetyConfig, me: &Ego, obstacles: &[Obstacle], sv: Sv) -> Result<(), Conflict> {
    let b0 = cfg.body(me.pos, me.heading);
    let (lo, hi_x, hi_y) = cfg.keep_in();
    let (lo, hi_x, hi_y) = (fx(lo), fx(hi_x), fx(hi_y));
    let limit = i64::from(fx(
        i32::from(cfg.safety_radius_units) + i32::from(cfg.guard_units)
    ));
    let limit2 = (limit * limit) as u64;
    for step in 1..=3u16 {
        let (p, h) = predict(me.pos, me.heading, sv, cfg.gate_ms(step));
        let b = cfg.body(p, h);
        // Beyond the keep-in edge and further out than now.
        if (b.x < lo && b.x < b0.x)
            || (b.y < lo && b.y < b0.y)
            || (b.x > hi_x && b.x > b0.x)
            || (b.y > hi_y && b.y > b0.y)
        {
            return Err(Conflict::Wall);
        }
        for n in obstacles {
            let nb = n.steps[usize::from(step - 1)];
            let d2 = (nb - b).len2();
            if d2 < limit2 && d2 < (nb - b0).len2() {
                return Err(Conflict::Car(n.id));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::{unfx, QUARTER_TURN};

    fn me(x: i32, y: i32, heading: i32) -> Ego {
        Ego {
            id: 2,
            pos: IVec2::from_units(x, y),
            heading,
        }
    }

    fn n(id: u8, x: u16, y: u16, heading_mrad: u16, v: i16) -> Neighbour {
        Neighbour {
            id,
            pose: CarPose {
                x,
                y,
                heading_mrad,
                velocity_mm_s: v,
            },
            age_us: 0,
        }
    }

    fn obs(cfg: &SafetyConfig, fresh: &[Neighbour]) -> Vec<Obstacle> {
        fresh.iter().map(|n| cfg.obstacle(n)).collect()
    }

    /// The field in whole mm/s.
    fn field_mm_s(
        cfg: &SafetyConfig,
        m: &Ego,
        o: &[Obstacle],
        vx: i32,
        vy: i32,
        hold: bool,
    ) -> (i32, i32) {
        field(cfg, m, o, IVec2::from_units(vx, vy), hold).to_units()
    }

    const AHEAD: Sv = Sv {
        steering_mrad: 0,
        velocity_mm_s: 200,
    };
    const BACK: Sv = Sv {
        steering_mrad: 0,
        velocity_mm_s: -100,
    };

    #[test]
    fn gate_refuses_driving_into_a_car() {
        let cfg = SafetyConfig::default();
        // Neighbour body 70 units ahead of mine, standing.
        let m = me(100, 400, 0);
        let fresh = [n(3, 170, 400, 0, 0)];
        assert_eq!(
            gate(&cfg, &m, &obs(&cfg, &fresh), AHEAD),
            Err(Conflict::Car(3))
        );
        // Backing away is fine; so is standing.
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), BACK), Ok(()));
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), Sv::default()), Ok(()));
    }

    #[test]
    fn gate_uses_neighbour_velocity_and_age() {
        let cfg = SafetyConfig::default();
        let m = me(100, 400, 0);
        // 150 units ahead but coming at us at 300 mm/s, 0.2 s old: it is really 126 ahead and
        // closes 54 units in the horizon.
        let mut fresh = [n(3, 250, 400, 3142, 300)];
        fresh[0].age_us = 200_000;
        let o = obs(&cfg, &fresh);
        assert_eq!(unfx(o[0].body.x), 250 - 16 - 24);
        assert_eq!(gate(&cfg, &m, &o, AHEAD), Err(Conflict::Car(3)));
        fresh[0].pose.velocity_mm_s = 0;
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), AHEAD), Ok(()));
    }

    #[test]
    fn gate_refuses_walls_but_allows_leaving() {
        let cfg = SafetyConfig::default();
        // Facing the X = 600 wall, body at 570: keep-in ends at 568.
        let m = me(554, 400, 0);
        assert_eq!(gate(&cfg, &m, &[], AHEAD), Err(Conflict::Wall));
        assert_eq!(gate(&cfg, &m, &[], BACK), Ok(()));
        let m = me(100, 40, -QUARTER_TURN);
        assert_eq!(gate(&cfg, &m, &[], AHEAD), Err(Conflict::Wall));
    }

    #[test]
    fn field_pushes_away_and_to_the_right() {
        let cfg = SafetyConfig::default();
        let m = me(300, 300, QUARTER_TURN);
        // Neighbour straight ahead (+Y), 60 units between bodies; I want to go +Y.
        let fresh = [n(1, 300, 376, 4712, 0)];
        let (vx, vy) = field_mm_s(&cfg, &m, &obs(&cfg, &fresh), 0, 200, false);
        assert!(vy < 0, "stopped and pushed back: {vx} {vy}");
        assert!(vx > 50, "veers right: {vx} {vy}");
        // In the band (64 units) the closing speed is only partly removed.
        let far = [n(1, 300, 396, 4712, 0)];
        let (_, vy) = field_mm_s(&cfg, &m, &obs(&cfg, &far), 0, 200, false);
        assert!(vy > 0 && vy < 100, "{vy}");
        // A moving higher-ID neighbour takes half the effort.
        let mut hi = [n(9, 300, 396, 4712, 100)];
        let v_hi = field_mm_s(&cfg, &m, &obs(&cfg, &hi), 0, 200, false);
        hi[0].id = 1;
        let v_lo = field_mm_s(&cfg, &m, &obs(&cfg, &hi), 0, 200, false);
        assert!(v_hi.1 > v_lo.1, "{v_hi:?} {v_lo:?}");
        // A neighbour ahead moving away as fast as me changes nothing.
        let same = [n(1, 300, 380, 1571, 200)];
        assert_eq!(
            field_mm_s(&cfg, &m, &obs(&cfg, &same), 0, 200, false),
            (0, 200)
        );
    }

    #[test]
    fn field_leaves_holding_cars_alone_unless_inside_radius() {
        let cfg = SafetyConfig::default();
        let m = me(300, 300, 0);
        let near = [n(1, 380, 300, 0, 0)];
        assert_eq!(field_mm_s(&cfg, &m, &obs(&cfg, &near), 0, 0, true), (0, 0));
        let inside = [n(1, 340, 300, 0, 0)];
        assert!(field_mm_s(&cfg, &m, &obs(&cfg, &inside), 0, 0, true).0 < -100);
    }

    #[test]
    fn field_slides_along_walls() {
        let cfg = SafetyConfig::default();
        // Body 10 units inside the keep-in edge at the left wall; desired velocity into it.
        let m = me(26, 400, QUARTER_TURN);
        let (vx, vy) = field_mm_s(&cfg, &m, &[], -200, 100, false);
        assert!(vx > 0, "{vx}");
        assert_eq!(vy, 100);
        // Half-way into the band: the component into the wall is halved, nothing added.
        let m = me(47, 400, QUARTER_TURN);
        assert_eq!(field_mm_s(&cfg, &m, &[], -200, 100, false), (-100, 100));
        // Away from the wall: untouched.
        assert_eq!(field_mm_s(&cfg, &m, &[], 200, 100, false), (200, 100));
    }

    #[test]
    fn goals_are_clamped_inside() {
        let cfg = SafetyConfig::default();
        assert_eq!(cfg.goal_margin_units(), 58);
        assert_eq!(cfg.clamp_goal(0, 900), (58, 742));
        assert_eq!(cfg.clamp_goal(300, 400), (300, 400));
    }

    #[test]
    fn obstacles_move_with_their_age() {
        let cfg = SafetyConfig::default();
        // Heading +X at 250 mm/s, 0.4 s old: 100 mm = 40 units further.
        let mut a = n(1, 100, 200, 0, 250);
        a.age_us = 400_000;
        let o = cfg.obstacle(&a);
        assert_eq!(o.body, IVec2::from_units(100 + 16 + 40, 200));
        assert_eq!(o.at(1000), IVec2::from_units(100 + 16 + 140, 200));
        // 450 ms horizon: 15, 30 and 45 units further at the gate's instants.
        assert_eq!(o.steps[0], IVec2::from_units(100 + 16 + 40 + 15, 200));
        assert_eq!(o.steps[2], o.at(450));
    }
}
