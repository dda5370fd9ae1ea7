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
use crate::geom::{clampf, mrad_to_rad, Vec2};
use crate::{Me, Neighbour, ARENA_X_MAX, ARENA_Y_MAX, MM_PER_UNIT};

/// Avoidance parameters (tracking units unless named otherwise).
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct SafetyConfig {
    /// Minimum distance between body centres: car length 100 mm + 50 mm margin.
    pub safety_radius_units: f32,
    /// Extra margin the gate keeps beyond the safety radius.
    pub guard_units: f32,
    /// Width of the repulsive band beyond the safety radius.
    pub influence_units: f32,
    /// Body centre ahead of the rear axle (40 mm).
    pub body_offset_units: f32,
    /// Radius of the circle that covers the body (60 mm).
    pub body_radius_units: f32,
    /// Keep-out between the body circle and a wall.
    pub wall_margin_units: f32,
    /// Width of the repulsive band beyond the wall keep-out.
    pub wall_influence_units: f32,
    /// Strength of the push out of the safety radius and off the walls, mm/s per band width.
    pub repulse_mm_s: f32,
    /// Prediction horizon of the gate, s.
    pub horizon_s: f32,
    /// Neighbours older than this are ignored, microseconds.
    pub stale_after_us: u32,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            safety_radius_units: 60.0,
            guard_units: 6.0,
            influence_units: 36.0,
            body_offset_units: 16.0,
            body_radius_units: 24.0,
            wall_margin_units: 8.0,
            wall_influence_units: 30.0,
            repulse_mm_s: 250.0,
            horizon_s: 0.45,
            stale_after_us: 500_000,
        }
    }
}

impl SafetyConfig {
    /// Body centre of a car at rear-axle `pos` with `heading`.
    pub fn body(&self, pos: Vec2, heading: f32) -> Vec2 {
        pos + Vec2::from_angle(heading) * self.body_offset_units
    }

    /// A neighbour as an obstacle: its body centre now (advanced along its broadcast
    /// velocity over the broadcast's age) and its velocity.
    pub fn obstacle(&self, n: &Neighbour) -> Obstacle {
        let dir = Vec2::from_angle(mrad_to_rad(n.pose.heading_mrad));
        let velocity = dir * f32::from(n.pose.velocity_mm_s);
        let pos = Vec2::new(f32::from(n.pose.x), f32::from(n.pose.y));
        Obstacle {
            id: n.id,
            body: pos
                + dir * self.body_offset_units
                + velocity * (n.age_us as f32 * 1e-6 / MM_PER_UNIT),
            velocity,
        }
    }

    /// Lowest and highest allowed body-centre coordinate along X and Y.
    fn keep_in(&self) -> (Vec2, Vec2) {
        let m = self.body_radius_units + self.wall_margin_units;
        (
            Vec2::new(m, m),
            Vec2::new(f32::from(ARENA_X_MAX) - m, f32::from(ARENA_Y_MAX) - m),
        )
    }

    /// Distance of the goal area from each wall (see [`SafetyConfig::clamp_goal`]), tracking
    /// units, rounded.
    pub fn goal_margin_units(&self) -> u16 {
        let m = self.body_radius_units
            + self.wall_margin_units
            + self.body_offset_units
            + self.wall_influence_units / 3.0;
        // A few dozen units: exact.
        crate::fmath::round(m) as u16
    }

    /// Clamp a rear-axle goal so that the body keeps out of the walls whatever the heading,
    /// with a third of the wall band to spare so that the goal can be reached.
    pub fn clamp_goal(&self, p: Vec2) -> Vec2 {
        let (lo, hi) = self.keep_in();
        let m = self.body_offset_units + self.wall_influence_units / 3.0;
        Vec2::new(
            clampf(p.x, lo.x + m, hi.x - m),
            clampf(p.y, lo.y + m, hi.y - m),
        )
    }
}

/// A neighbour's body, predicted along a straight line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obstacle {
    /// Car ID.
    pub id: u8,
    /// Body centre now, tracking units.
    pub body: Vec2,
    /// Velocity, mm/s.
    pub velocity: Vec2,
}

impl Obstacle {
    /// Body centre `t` seconds from now.
    pub fn at(&self, t: f32) -> Vec2 {
        self.body + self.velocity * (t / MM_PER_UNIT)
    }
}

/// Adds the avoidance field to `desired` (mm/s). `holding` limits car repulsion to
/// neighbours already inside the safety radius, so that cars at rest stay at rest.
///
/// Inside the band `safety_radius..safety_radius + influence` the part of the velocity
/// relative to a neighbour that closes the distance is removed progressively (fully at the
/// safety radius), half of it reappearing as a sideways term to the right; cars moving in
/// parallel are left alone. Inside the safety radius a push away is added on top.
pub fn field(
    cfg: &SafetyConfig,
    me: &Me,
    obstacles: &[Obstacle],
    desired: Vec2,
    holding: bool,
) -> Vec2 {
    let b = cfg.body(me.pos, me.heading);
    let mut v = desired;
    let outer = cfg.safety_radius_units + cfg.influence_units;
    let reach = if holding {
        cfg.safety_radius_units
    } else {
        outer
    };
    for n in obstacles {
        let to = n.body - b;
        let d = to.norm();
        if d >= reach {
            continue;
        }
        let u = to.unit();
        let v_n = n.velocity;
        let moving = v_n.norm() > 20.0;
        // The higher ID yields: a moving neighbour with a higher ID takes half the effort.
        let prio = if n.id < me.id || !moving { 1.0 } else { 0.5 };
        let w = clampf((outer - d) / cfg.influence_units, 0.0, 1.0) * prio;
        let closing = (desired - v_n).dot(u);
        if closing > 0.0 {
            let right = Vec2::new(u.y, -u.x);
            v = v - u * (closing * w) + right * (0.5 * closing * w);
        }
        if d < cfg.safety_radius_units {
            let depth = (cfg.safety_radius_units - d) / cfg.influence_units;
            v = v - u * (clampf(depth, 0.0, 1.0) * cfg.repulse_mm_s * prio);
        }
    }
    // Walls: the component into a wall fades out across the band, and beyond the keep-in
    // edge a push back is added.
    let (lo, hi) = cfg.keep_in();
    let band = cfg.wall_influence_units;
    let axis = |v: f32, c_lo: f32, c_hi: f32| -> f32 {
        let mut out = v;
        if out < 0.0 {
            out *= clampf(c_lo / band, 0.0, 1.0);
        }
        if out > 0.0 {
            out *= clampf(c_hi / band, 0.0, 1.0);
        }
        out + clampf(-c_lo / band, 0.0, 1.0) * cfg.repulse_mm_s
            - clampf(-c_hi / band, 0.0, 1.0) * cfg.repulse_mm_s
    };
    if holding && v == desired {
        return v;
    }
    Vec2::new(
        axis(v.x, b.x - lo.x, hi.x - b.x),
        axis(v.y, b.y - lo.y, hi.y - b.y),
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

/// Checks a command over the prediction horizon; `Ok` when it is safe.
pub fn gate(cfg: &SafetyConfig, me: &Me, obstacles: &[Obstacle], sv: Sv) -> Result<(), Conflict> {
    let b0 = cfg.body(me.pos, me.heading);
    let (lo, hi) = cfg.keep_in();
    let limit = cfg.safety_radius_units + cfg.guard_units;
    for step in 1..=3u8 {
        let t = cfg.horizon_s * f32::from(step) / 3.0;
        let (p, h) = predict(me.pos, me.heading, sv, t);
        let b = cfg.body(p, h);
        let worse = |now: f32, then: f32| then < now - 0.01;
        if (b.x < lo.x && worse(b0.x, b.x))
            || (b.y < lo.y && worse(b0.y, b.y))
            || (b.x > hi.x && worse(-b0.x, -b.x))
            || (b.y > hi.y && worse(-b0.y, -b.y))
        {
            return Err(Conflict::Wall);
        }
        for n in obstacles {
            let nb = n.at(t);
            let d = (nb - b).norm();
            if d < limit && worse((nb - b0).norm(), d) {
                return Err(Conflict::Car(n.id));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CarPose;
    use core::f32::consts::FRAC_PI_2;

    fn me(x: f32, y: f32, heading: f32) -> Me {
        Me {
            id: 2,
            pos: Vec2::new(x, y),
            heading,
            speed: 0.0,
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

    const AHEAD: Sv = Sv {
        steering: 0.0,
        velocity: 200.0,
    };

    #[test]
    fn gate_refuses_driving_into_a_car() {
        let cfg = SafetyConfig::default();
        // Neighbour body 70 units ahead of mine, standing.
        let m = me(100.0, 400.0, 0.0);
        let fresh = [n(3, 170, 400, 0, 0)];
        assert_eq!(
            gate(&cfg, &m, &obs(&cfg, &fresh), AHEAD),
            Err(Conflict::Car(3))
        );
        // Backing away is fine; so is standing.
        let back = Sv {
            steering: 0.0,
            velocity: -100.0,
        };
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), back), Ok(()));
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), Sv::default()), Ok(()));
    }

    #[test]
    fn gate_uses_neighbour_velocity_and_age() {
        let cfg = SafetyConfig::default();
        let m = me(100.0, 400.0, 0.0);
        // 150 units ahead but coming at us at 300 mm/s, 0.2 s old: it is really 126 ahead and
        // closes 54 units in the horizon.
        let mut fresh = [n(3, 250, 400, 3142, 300)];
        fresh[0].age_us = 200_000;
        assert_eq!(
            gate(&cfg, &m, &obs(&cfg, &fresh), AHEAD),
            Err(Conflict::Car(3))
        );
        fresh[0].pose.velocity_mm_s = 0;
        assert_eq!(gate(&cfg, &m, &obs(&cfg, &fresh), AHEAD), Ok(()));
    }

    #[test]
    fn gate_refuses_walls_but_allows_leaving() {
        let cfg = SafetyConfig::default();
        // Facing the X = 600 wall, body at 570: keep-in ends at 568.
        let m = me(554.0, 400.0, 0.0);
        assert_eq!(gate(&cfg, &m, &[], AHEAD), Err(Conflict::Wall));
        let back = Sv {
            steering: 0.0,
            velocity: -100.0,
        };
        assert_eq!(gate(&cfg, &m, &[], back), Ok(()));
        let m = me(100.0, 40.0, -FRAC_PI_2);
        assert_eq!(gate(&cfg, &m, &[], AHEAD), Err(Conflict::Wall));
    }

    #[test]
    fn field_pushes_away_and_to_the_right() {
        let cfg = SafetyConfig::default();
        let m = me(300.0, 300.0, FRAC_PI_2);
        // Neighbour straight ahead (+Y), 60 units between bodies; I want to go +Y.
        let fresh = [n(1, 300, 376, 4712, 0)];
        let v = field(&cfg, &m, &obs(&cfg, &fresh), Vec2::new(0.0, 200.0), false);
        assert!(v.y < 0.0, "stopped and pushed back: {v:?}");
        assert!(v.x > 50.0, "veers right: {v:?}");
        // In the band (64 units) the closing speed is only partly removed.
        let far = [n(1, 300, 396, 4712, 0)];
        let v = field(&cfg, &m, &obs(&cfg, &far), Vec2::new(0.0, 200.0), false);
        assert!(v.y > 0.0 && v.y < 100.0, "{v:?}");
        // A moving higher-ID neighbour takes half the effort.
        let mut hi = [n(9, 300, 396, 4712, 100)];
        let v_hi = field(&cfg, &m, &obs(&cfg, &hi), Vec2::new(0.0, 200.0), false);
        hi[0].id = 1;
        let v_lo = field(&cfg, &m, &obs(&cfg, &hi), Vec2::new(0.0, 200.0), false);
        assert!(v_hi.y > v_lo.y, "{v_hi:?} {v_lo:?}");
        // A neighbour ahead moving away as fast as me changes nothing.
        let same = [n(1, 300, 380, 1571, 200)];
        assert_eq!(
            field(&cfg, &m, &obs(&cfg, &same), Vec2::new(0.0, 200.0), false),
            Vec2::new(0.0, 200.0)
        );
    }

    #[test]
    fn field_leaves_holding_cars_alone_unless_inside_radius() {
        let cfg = SafetyConfig::default();
        let m = me(300.0, 300.0, 0.0);
        let near = [n(1, 380, 300, 0, 0)];
        assert_eq!(
            field(&cfg, &m, &obs(&cfg, &near), Vec2::ZERO, true),
            Vec2::ZERO
        );
        let inside = [n(1, 340, 300, 0, 0)];
        assert!(field(&cfg, &m, &obs(&cfg, &inside), Vec2::ZERO, true).x < -100.0);
    }

    #[test]
    fn field_slides_along_walls() {
        let cfg = SafetyConfig::default();
        // Body 10 units inside the keep-in edge at the left wall; desired velocity into it.
        let m = me(26.0, 400.0, FRAC_PI_2);
        let v = field(&cfg, &m, &[], Vec2::new(-200.0, 100.0), false);
        assert!(v.x > 0.0, "{v:?}");
        assert!((v.y - 100.0).abs() < 1e-3);
        // Half-way into the band: the component into the wall is halved, nothing added.
        let m = me(47.0, 400.0, FRAC_PI_2);
        let v = field(&cfg, &m, &[], Vec2::new(-200.0, 100.0), false);
        assert!((v.x + 100.0).abs() < 1e-3, "{v:?}");
        // Away from the wall: untouched.
        let v = field(&cfg, &m, &[], Vec2::new(200.0, 100.0), false);
        assert!((v.x - 200.0).abs() < 1e-3, "{v:?}");
    }

    #[test]
    fn goals_are_clamped_inside() {
        let cfg = SafetyConfig::default();
        assert_eq!(
            cfg.clamp_goal(Vec2::new(-10.0, 900.0)),
            Vec2::new(58.0, 742.0)
        );
        assert_eq!(
            cfg.clamp_goal(Vec2::new(300.0, 400.0)),
            Vec2::new(300.0, 400.0)
        );
    }
}
