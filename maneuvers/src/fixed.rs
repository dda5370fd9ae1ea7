//! Fixed-point plane geometry: the arithmetic of the controller, the avoidance, the steering
//! and the stock laws. The firmware's core has no FPU, where every `f32` operation is a
//! library call of tens to hundreds of cycles; everything here is a few integer instructions.
//!
//! Representations:
//!
//! * positions in 1/16 tracking unit and velocities in 1/16 mm/s ([`FRAC`] fraction bits), as
//!   `i32`, two of them in an [`IVec2`];
//! * angles as binary angles of 65 536 per turn ([`TURN`]) in an `i32`; [`wrap`] brings one
//!   into -32 768..=32 767 (-pi..pi) and [`from_mrad`] / [`to_mrad`] convert from and to the
//!   project's mrad;
//! * sines, cosines, unit vectors and weights in Q14 ([`Q14`] = 16 384 = 1.0).
//!
//! Products are formed in `i64` (a few multiply instructions on RV32IM) and shifted back;
//! divisions are 32-bit only (the core divides 32-bit numbers in hardware, a 64-bit division
//! is a library call). Accuracy, each checked against `f64` by the tests below:
//!
//! | function | error |
//! |---|---|
//! | [`sin_cos`] | within 2/16 384 of the exact value |
//! | [`atan2`] | within 1.1 binary angles (0.11 mrad); exactly 0 on +X, `TURN / 2` on -X |
//! | [`norm`] | exact (rounded) below 2^15; above, within 2^-13 of the larger component |
//! | [`IVec2::unit`] | each component within 1.5 / 16 384 of the exact unit vector |
//! | [`from_mrad`], [`to_mrad`] | rounded, within half a step of the target unit |

use core::ops::{Add, Neg, Sub};

use crate::imath::{isqrt, sin_binary};

/// Fraction bits of positions (tracking units) and velocities (mm/s).
pub const FRAC: u32 = 4;
/// 1 tracking unit or 1 mm/s.
pub const ONE: i32 = 1 << FRAC;
/// 1.0 in Q14.
pub const Q14: i32 = 1 << 14;
/// One turn as a binary angle.
pub const TURN: i32 = 1 << 16;
/// Half a turn (pi).
pub const HALF_TURN: i32 = 1 << 15;
/// A quarter turn (pi/2).
pub const QUARTER_TURN: i32 = 1 << 14;

/// 65536 / (2 pi 1000): mrad to binary angle, in Q32.
const MRAD_TO_BAM_Q32: i64 = (281_474_976_710_656.0 / 6_283.185_307_179_586 + 0.5) as i64;
/// 2 pi 1000 / 65536: binary angle to mrad, in Q32.
const BAM_TO_MRAD_Q32: i64 = (6_283.185_307_179_586 * 65_536.0 + 0.5) as i64;

/// `round(2^18 / (2 pi) * atan(i / 64))` for `i` in 0..=64: arctangent on [0, 1] in binary
/// angles of 2^18 per turn (atan(1) = 32 768).
const ATAN: [u16; 65] = [
    0, 652, 1303, 1954, 2604, 3253, 3900, 4545, 5188, 5829, 6467, 7101, 7733, 8361, 8985, 9605,
    10221, 10832, 11439, 12040, 12637, 13228, 13814, 14394, 14968, 15537, 16100, 16656, 17206,
    17750, 18288, 18819, 19344, 19862, 20374, 20879, 21378, 21870, 22355, 22834, 23306, 23771,
    24230, 24682, 25128, 25568, 26001, 26427, 26848, 27262, 27670, 28072, 28467, 28857, 29241,
    29619, 29991, 30357, 30718, 31073, 31423, 31767, 32106, 32439, 32768,
];

/// `v` whole units (tracking units or mm/s) in the fixed point.
pub const fn fx(v: i32) -> i32 {
    v << FRAC
}

/// `v` rounded to whole units, halves away from zero.
// Out of line: its two rounding branches inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub const fn unfx(v: i32) -> i32 {
    if v >= 0 {
        (v + ONE / 2) >> FRAC
    } else {
        -((-v + ONE / 2) >> FRAC)
    }
}

/// `a * b / 2^shift`, rounded (halves up); `shift` in 1..=62. The product is exact (`i64`);
/// the caller keeps the result within `i32`.
#[inline]
pub const fn mul_shift(a: i64, b: i64, shift: u32) -> i32 {
    ((a * b + (1 << (shift - 1))) >> shift) as i32
}

/// `a * k` with `k` in Q14, rounded.
// Out of line: the most frequent operation; its 64-bit product, rounding and shift are about
// ten instructions, more code at each use than a call.
#[inline(never)]
pub const fn mul_q14(a: i32, k: i32) -> i32 {
    mul_shift(a as i64, k as i64, 14)
}

/// A binary angle wrapped into -32 768..=32 767 (-pi..pi).
#[inline]
pub const fn wrap(a: i32) -> i32 {
    a as i16 as i32
}

/// mrad (|mrad| below 2^31 / 11, 31 000 turns) to a binary angle, rounded (not wrapped).
// Out of line: its 64-bit product inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub const fn from_mrad(mrad: i32) -> i32 {
    mul_shift(mrad as i64, MRAD_TO_BAM_Q32, 32)
}

/// A binary angle to mrad, rounded.
// Out of line, like `from_mrad`.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub const fn to_mrad(bam: i32) -> i32 {
    mul_shift(bam as i64, BAM_TO_MRAD_Q32, 32)
}

/// Sine and cosine of binary angle `a`, Q14 (linear interpolation of the quarter-wave table of
/// [`crate::imath`]).
// Out of line: its two table look-ups inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub fn sin_cos(a: i32) -> (i32, i32) {
    // The table's binary angle has 2^18 steps per turn.
    let b = (a as u32) << 2;
    (sin_binary(b), sin_binary(b.wrapping_add(0x1_0000)))
}

/// `v` (an `f32` in whole units) in the fixed point, truncated towards zero and saturated to
/// `i32` (NaN gives 0). Integer operations on the bits only: converting the answer of a law
/// written in `f32` pulls no soft-float routine into the firmware.
pub fn fx_from_f32(v: f32) -> i32 {
    let bits = v.to_bits();
    let exp = ((bits >> 23) & 0xFF) as i32;
    if exp == 0xFF && bits & 0x7F_FFFF != 0 {
        return 0;
    }
    // |v| * 2^FRAC = mantissa * 2^(exp - 127 - 23 + FRAC); a normal mantissa is at least
    // 2^23, so from a shift of 8 on the magnitude is beyond i32.
    let mantissa = (bits & 0x7F_FFFF) | if exp == 0 { 0 } else { 0x80_0000 };
    let shift = exp - 150 + FRAC as i32;
    let magnitude = if shift >= 8 {
        i32::MAX
    } else if shift >= 0 {
        (mantissa << shift).min(i32::MAX as u32) as i32
    } else if shift > -32 {
        (mantissa >> -shift) as i32
    } else {
        0
    };
    if bits >> 31 == 0 {
        magnitude
    } else {
        -magnitude
    }
}

/// Scales `(x, y)` by a power of two so that the larger magnitude lies in 2^14..2^15 (rounding
/// when scaling down). Returns the scaled pair and the shift (positive: scaled up by
/// `2^shift`). `(0, 0)` stays.
fn normalise(x: i32, y: i32) -> (i32, i32, i32) {
    let m = x.unsigned_abs().max(y.unsigned_abs());
    if m == 0 {
        return (0, 0, 0);
    }
    let shift = 15 - (32 - m.leading_zeros() as i32);
    if shift >= 0 {
        (x << shift, y << shift, shift)
    } else {
        let down = (-shift) as u32;
        let r = 1i64 << (down - 1);
        // Rounded towards the nearest (halves up); the magnitude stays at most 2^15.
        let scale = |v: i32| ((i64::from(v) + r) >> down) as i32;
        (scale(x), scale(y), shift)
    }
}

/// Square root rounded to the nearest integer.
fn sqrt_round(v: u32) -> i32 {
    let n = isqrt(v);
    // sqrt(v) >= n + 1/2 exactly when v > n^2 + n (both integers).
    (n + u32::from(v - n * n > n)) as i32
}

/// `a / b` rounded to the nearest (halves away from zero), `b > 0`.
fn div_round(a: i32, b: i32) -> i32 {
    if a >= 0 {
        (a + b / 2) / b
    } else {
        (a - b / 2) / b
    }
}

/// Length of `(x, y)`, rounded.
pub fn norm(x: i32, y: i32) -> i32 {
    let (a, b, shift) = normalise(x, y);
    // Both at most 2^15: the sum of squares is at most 2^31.
    let v = (a * a + b * b) as u32;
    if shift > 0 {
        // floor((floor(r) + h) / 2^s) = floor((r + h) / 2^s) for an integer h: rounded once.
        (isqrt(v) as i32 + (1 << (shift - 1))) >> shift
    } else {
        sqrt_round(v) << -shift
    }
}

/// Angle of `(x, y)` from +X as a binary angle in -32 768..=32 768 (0 for the origin), within
/// 1.1 binary angles: a 65-entry table of the arctangent on [0, 1], interpolated.
pub fn atan2(y: i32, x: i32) -> i32 {
    let (ax, ay) = (x.unsigned_abs(), y.unsigned_abs());
    let (lo, hi) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if hi == 0 {
        return 0;
    }
    // Scale so that hi lies in 2^15..2^16 (rounding lo), then t = lo / hi in Q16.
    let bits = 32 - hi.leading_zeros();
    let (lo, hi) = if bits > 16 {
        let s = bits - 16;
        ((lo + (1 << (s - 1))) >> s, (hi + (1 << (s - 1))) >> s)
    } else {
        (lo << (16 - bits), hi << (16 - bits))
    };
    // Rounded; lo < hi <= 2^16 keeps the numerator below 2^32.
    let t = if lo >= hi {
        1 << 16
    } else {
        ((lo << 16) + hi / 2) / hi
    };
    let i = (t >> 10) as usize;
    let f = (t & 0x3FF) as i32;
    let a = i32::from(ATAN[i.min(64)]);
    let b = i32::from(ATAN[(i + 1).min(64)]);
    // Binary angle of 2^18 per turn, in 0..=32 768 (pi/4).
    let mut r = a + (((b - a) * f + 512) >> 10);
    if ay > ax {
        r = (1 << 16) - r;
    }
    if x < 0 {
        r = (1 << 17) - r;
    }
    let r = (r + 2) >> 2;
    if y < 0 {
        -r
    } else {
        r
    }
}

/// A pair of fixed-point numbers: a position in 1/16 tracking unit, a velocity in 1/16 mm/s or
/// a unit vector in Q14, as documented at each use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IVec2 {
    /// X component.
    pub x: i32,
    /// Y component.
    pub y: i32,
}

impl IVec2 {
    /// The zero vector.
    pub const ZERO: IVec2 = IVec2 { x: 0, y: 0 };

    /// A vector from its components.
    pub const fn new(x: i32, y: i32) -> Self {
        Self { x, y }
    }

    /// A point or velocity given in whole units, in the fixed point.
    pub const fn from_units(x: i32, y: i32) -> Self {
        Self::new(fx(x), fx(y))
    }

    /// Unit vector (Q14) at binary angle `a` from +X.
    pub fn from_angle(a: i32) -> Self {
        let (s, c) = sin_cos(a);
        Self::new(c, s)
    }

    /// Squared length (exact).
    // Out of line: its two 64-bit products inlined at each use made the firmware larger.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    pub const fn len2(self) -> u64 {
        let (x, y) = (self.x as i64, self.y as i64);
        (x * x + y * y) as u64
    }

    /// Length, rounded ([`norm`]).
    pub fn norm(self) -> i32 {
        norm(self.x, self.y)
    }

    /// Direction as a binary angle ([`atan2`]).
    pub fn angle(self) -> i32 {
        atan2(self.y, self.x)
    }

    /// Dot product (exact).
    pub const fn dot(self, o: IVec2) -> i64 {
        self.x as i64 * o.x as i64 + self.y as i64 * o.y as i64
    }

    /// Rotated by +90 degrees (counter-clockwise).
    pub const fn perp(self) -> IVec2 {
        IVec2::new(-self.y, self.x)
    }

    /// Each component times `k` (Q14), rounded.
    pub const fn scale_q14(self, k: i32) -> IVec2 {
        IVec2::new(mul_q14(self.x, k), mul_q14(self.y, k))
    }

    /// Each component times the integer `k`.
    pub const fn times(self, k: i32) -> IVec2 {
        IVec2::new(self.x * k, self.y * k)
    }

    /// `self` (a Q14 unit vector) times the length `len`, in the unit of `len`.
    // Out of line: its two products inlined at each use cost the firmware 372 bytes more.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    pub const fn along(self, len: i32) -> IVec2 {
        IVec2::new(mul_q14(len, self.x), mul_q14(len, self.y))
    }

    /// Unit vector in the same direction, Q14 (zero for the zero vector).
    pub fn unit(self) -> IVec2 {
        let (a, b, _) = normalise(self.x, self.y);
        if a == 0 && b == 0 {
            return IVec2::ZERO;
        }
        let n = sqrt_round((a * a + b * b) as u32);
        // |a|, |b| <= 2^15 and n >= 2^14: the quotients are at most 2^14 + 1.
        IVec2::new(div_round(a << 14, n), div_round(b << 14, n))
    }

    /// Same direction, length at most `max` (unchanged when shorter).
    pub fn clamp_norm(self, max: i32) -> IVec2 {
        if self.len2() <= (max as i64 * max as i64) as u64 {
            self
        } else {
            self.unit().along(max)
        }
    }

    /// Rounded to whole units.
    pub const fn to_units(self) -> (i32, i32) {
        (unfx(self.x), unfx(self.y))
    }
}

impl Add for IVec2 {
    type Output = IVec2;
    fn add(self, o: IVec2) -> IVec2 {
        IVec2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for IVec2 {
    type Output = IVec2;
    fn sub(self, o: IVec2) -> IVec2 {
        IVec2::new(self.x - o.x, self.y - o.y)
    }
}

impl Neg for IVec2 {
    type Output = IVec2;
    fn neg(self) -> IVec2 {
        IVec2::new(-self.x, -self.y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{PI, TAU};

    fn bam_to_rad(a: i32) -> f64 {
        f64::from(a) * TAU / f64::from(TURN)
    }

    /// Difference of two angles in rad, wrapped into -pi..pi.
    fn angle_diff(a: f64, b: f64) -> f64 {
        let d = (a - b).rem_euclid(TAU);
        if d > PI {
            d - TAU
        } else {
            d
        }
    }

    #[test]
    fn the_arctangent_table_is_what_it_says() {
        for (i, &v) in ATAN.iter().enumerate() {
            let exact = (i as f64 / 64.0).atan() * f64::from(1u32 << 18) / TAU;
            assert_eq!(f64::from(v), exact.round(), "{i}");
        }
    }

    #[test]
    fn arctangent_on_the_axes_and_diagonals() {
        assert_eq!(atan2(0, 0), 0);
        assert_eq!(atan2(0, 5), 0);
        assert_eq!(atan2(0, -5), HALF_TURN);
        assert_eq!(atan2(7, 0), QUARTER_TURN);
        assert_eq!(atan2(-7, 0), -QUARTER_TURN);
        assert_eq!(atan2(3, 3), TURN / 8);
        assert_eq!(atan2(-3, -3), -3 * TURN / 8);
        assert_eq!(atan2(i32::MAX, i32::MIN), 3 * TURN / 8);
    }

    #[test]
    fn conversions_from_f32() {
        assert_eq!(fx_from_f32(1.0), ONE);
        assert_eq!(fx_from_f32(-2.5), -40);
        assert_eq!(fx_from_f32(0.03), 0);
        assert_eq!(fx_from_f32(-0.07), -1);
        assert_eq!(fx_from_f32(f32::NAN), 0);
        assert_eq!(fx_from_f32(f32::INFINITY), i32::MAX);
        assert_eq!(fx_from_f32(f32::NEG_INFINITY), -i32::MAX);
        assert_eq!(fx_from_f32(1e-40), 0);
    }

    #[test]
    fn conversions_of_angles() {
        assert_eq!(from_mrad(0), 0);
        assert_eq!(from_mrad(1000), 10430);
        assert_eq!(from_mrad(1571), 16386);
        assert_eq!(from_mrad(-1571), -16386);
        assert_eq!(from_mrad(6283), 65534);
        assert_eq!(to_mrad(HALF_TURN), 3142);
        assert_eq!(to_mrad(-QUARTER_TURN), -1571);
        assert_eq!(wrap(TURN + 5), 5);
        assert_eq!(wrap(HALF_TURN), -HALF_TURN);
        for m in -7000..7000 {
            let back = to_mrad(from_mrad(m));
            assert!((back - m).abs() <= 0, "{m} -> {back}");
        }
    }

    #[test]
    fn norms_of_small_and_large_vectors() {
        assert_eq!(norm(0, 0), 0);
        assert_eq!(norm(3, -4), 5);
        assert_eq!(norm(1, 1), 1);
        assert_eq!(norm(-600, 800), 1000);
        assert_eq!(norm(1 << 20, 0), 1 << 20);
        assert_eq!(IVec2::new(3, 4).unit(), IVec2::new(9830, 13107));
        assert_eq!(IVec2::ZERO.unit(), IVec2::ZERO);
        assert_eq!(IVec2::new(0, -1).unit(), IVec2::new(0, -Q14));
        assert_eq!(
            IVec2::new(300, 400).clamp_norm(100),
            IVec2::new(60, 80),
            "shortened"
        );
        assert_eq!(IVec2::new(3, 4).clamp_norm(100), IVec2::new(3, 4));
        assert_eq!(unfx(fx(-7) - ONE / 2), -8);
        assert_eq!(unfx(fx(7) + ONE / 2), 8);
        assert_eq!(unfx(fx(7) + ONE / 2 - 1), 7);
    }

    #[test]
    fn sine_and_cosine_of_binary_angles() {
        let mut worst = 0.0f64;
        for a in (-TURN..=TURN).step_by(7) {
            let (s, c) = sin_cos(a);
            let r = bam_to_rad(a);
            let es = (f64::from(s) - r.sin() * 16384.0).abs();
            let ec = (f64::from(c) - r.cos() * 16384.0).abs();
            worst = worst.max(es.max(ec));
        }
        assert!(worst <= 2.0, "{worst}");
        assert_eq!(sin_cos(0), (0, Q14));
        assert_eq!(sin_cos(QUARTER_TURN), (Q14, 0));
    }

    /// The bound of [`atan2`], rad.
    const ATAN2_BOUND: f64 = 1.1 * TAU / 65_536.0;

    #[test]
    fn arctangent_everywhere_within_its_bound() {
        let mut worst = 0.0f64;
        for y in (-2000..=2000).step_by(13) {
            for x in (-2000..=2000).step_by(11) {
                let e = angle_diff(bam_to_rad(atan2(y, x)), f64::from(y).atan2(f64::from(x)));
                worst = worst.max(e.abs());
            }
        }
        let step = TAU / f64::from(TURN);
        eprintln!("atan2: largest error {:.3} binary angles", worst / step);
        assert!(worst <= ATAN2_BOUND, "{worst}");
    }

    proptest! {
        #[test]
        fn atan2_against_f64(y in any::<i32>(), x in any::<i32>()) {
            let e = angle_diff(bam_to_rad(atan2(y, x)), f64::from(y).atan2(f64::from(x)));
            prop_assert!(e.abs() <= ATAN2_BOUND, "{} {} {}", y, x, e);
        }

        #[test]
        fn atan2_of_small_vectors(y in -300i32..300, x in -300i32..300) {
            let e = angle_diff(bam_to_rad(atan2(y, x)), f64::from(y).atan2(f64::from(x)));
            prop_assert!(e.abs() <= ATAN2_BOUND, "{} {} {}", y, x, e);
        }

        #[test]
        fn norm_against_f64(x in -(1i32 << 30)..(1 << 30), y in -(1i32 << 30)..(1 << 30)) {
            let exact = f64::from(x).hypot(f64::from(y));
            let m = f64::from(x.unsigned_abs().max(y.unsigned_abs()));
            let e = (f64::from(norm(x, y)) - exact).abs();
            prop_assert!(e <= 0.5 + m / 8192.0, "{} {} {} {}", x, y, norm(x, y), exact);
        }

        #[test]
        fn small_norms_are_rounded(x in -20_000i32..20_000, y in -20_000i32..20_000) {
            let exact = f64::from(x).hypot(f64::from(y));
            prop_assert!((f64::from(norm(x, y)) - exact).abs() <= 0.5 + 1e-9);
        }

        #[test]
        fn unit_vectors_against_f64(x in -(1i32 << 30)..(1 << 30), y in -(1i32 << 30)..(1 << 30)) {
            prop_assume!(x != 0 || y != 0);
            let u = IVec2::new(x, y).unit();
            let n = f64::from(x).hypot(f64::from(y));
            let ex = f64::from(x) / n * 16384.0;
            let ey = f64::from(y) / n * 16384.0;
            prop_assert!((f64::from(u.x) - ex).abs() <= 1.5 && (f64::from(u.y) - ey).abs() <= 1.5,
                "{} {} -> {:?} ({} {})", x, y, u, ex, ey);
        }

        #[test]
        fn f32_to_fixed_point(v in any::<f32>()) {
            let exact = f64::from(v) * f64::from(ONE);
            let expected = if v.is_nan() {
                0
            } else {
                exact.trunc().clamp(-f64::from(i32::MAX), f64::from(i32::MAX)) as i32
            };
            prop_assert_eq!(fx_from_f32(v), expected, "{}", v);
        }

        #[test]
        fn mrad_round_trip(m in -200_000i32..200_000) {
            let a = from_mrad(m);
            let exact = f64::from(m) * 1e-3 / TAU * f64::from(TURN);
            prop_assert!((f64::from(a) - exact).abs() <= 0.5 + 1e-4);
            let back = f64::from(to_mrad(a));
            prop_assert!((back - f64::from(a) * TAU * 1000.0 / f64::from(TURN)).abs() <= 0.5 + 1e-4);
        }
    }
}
