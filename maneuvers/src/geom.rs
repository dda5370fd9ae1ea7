//! Small plane-geometry helpers on `f32` (tracking units, radians), using [`crate::fmath`] so
//! that the same compact code runs on the FPU-less firmware and on the host.

use core::f32::consts::TAU;
use core::ops::{Add, Mul, Neg, Sub};

use crate::fmath::{atan2, round, sin_cos, sqrt};

// The small arithmetic helpers below are kept out of line (`#[inline(never)]`): on the
// FPU-less firmware every `f32` operation is already a call into `compiler_builtins`, and
// inlining the helpers at each of their many uses costs more code than calling them
// (measured: 1.2 KiB of firmware text).

/// A 2-D vector (a position in tracking units or a velocity in mm/s, as documented at each use).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    /// X component.
    pub x: f32,
    /// Y component.
    pub y: f32,
}

impl Vec2 {
    /// The zero vector.
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };

    /// A vector from its components.
    pub const fn new(x: f32, y: f32) -> Self {
        Self { x, y }
    }

    /// Unit vector at `angle` rad from +X.
    pub fn from_angle(angle: f32) -> Self {
        let (s, c) = sin_cos(angle);
        Self::new(c, s)
    }

    /// Euclidean length.
    pub fn norm(self) -> f32 {
        sqrt(self.x * self.x + self.y * self.y)
    }

    /// Dot product.
    #[inline(never)]
    pub fn dot(self, o: Vec2) -> f32 {
        self.x * o.x + self.y * o.y
    }

    /// Direction, rad in -pi..=pi (0 for the zero vector).
    pub fn angle(self) -> f32 {
        atan2(self.y, self.x)
    }

    /// Rotated by +90 degrees (counter-clockwise).
    pub fn perp(self) -> Vec2 {
        Vec2::new(-self.y, self.x)
    }

    /// Same direction, length at most `max`.
    pub fn clamp_norm(self, max: f32) -> Vec2 {
        let n = self.norm();
        if n > max && n > 0.0 {
            self * (max / n)
        } else {
            self
        }
    }

    /// Unit vector in the same direction, or zero.
    pub fn unit(self) -> Vec2 {
        let n = self.norm();
        if n > 1e-6 {
            self * (1.0 / n)
        } else {
            Vec2::ZERO
        }
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    #[inline(never)]
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Vec2 {
    type Output = Vec2;
    #[inline(never)]
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f32> for Vec2 {
    type Output = Vec2;
    #[inline(never)]
    fn mul(self, k: f32) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

impl Neg for Vec2 {
    type Output = Vec2;
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

/// Angle wrapped into -pi..=pi (within `f32` rounding), for angles of up to a few
/// thousand turns.
#[inline(never)]
pub fn wrap(a: f32) -> f32 {
    a - round(a * (1.0 / TAU)) * TAU
}

/// Heading in mrad (0..=6283) to rad.
pub fn mrad_to_rad(mrad: u16) -> f32 {
    f32::from(mrad) * 1e-3
}

/// Rad to heading in mrad, 0..=6283.
pub fn rad_to_mrad(rad: f32) -> u16 {
    let a = wrap(rad);
    let a = if a < 0.0 { a + TAU } else { a };
    // `as` saturates; the wrap keeps it within 0..=6283.
    (round(a * 1000.0) as u16).min(6283)
}

/// Clamp a float into `lo..=hi` (NaN gives `lo`).
#[inline(never)]
pub fn clampf(v: f32, lo: f32, hi: f32) -> f32 {
    if v.is_nan() {
        lo
    } else {
        v.max(lo).min(hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f32::consts::PI;

    #[test]
    fn wrap_keeps_angles_in_range() {
        assert!((wrap(3.0 * PI) - PI).abs() < 1e-4 || (wrap(3.0 * PI) + PI).abs() < 1e-4);
        assert!((wrap(-0.5) + 0.5).abs() < 1e-6);
        assert!((wrap(TAU + 0.25) - 0.25).abs() < 1e-5);
        assert!((wrap(-TAU - 0.25) + 0.25).abs() < 1e-5);
    }

    #[test]
    fn mrad_round_trip() {
        for m in [0u16, 1, 1571, 3142, 6283] {
            assert_eq!(rad_to_mrad(mrad_to_rad(m)), m);
        }
        assert_eq!(rad_to_mrad(-0.001), 6282);
    }

    #[test]
    fn clamp_norm_limits_length() {
        let v = Vec2::new(30.0, 40.0).clamp_norm(5.0);
        assert!((v.norm() - 5.0).abs() < 1e-5);
        assert!((v.x - 3.0).abs() < 1e-5);
        assert_eq!(Vec2::new(1.0, 0.0).clamp_norm(5.0), Vec2::new(1.0, 0.0));
    }
}
