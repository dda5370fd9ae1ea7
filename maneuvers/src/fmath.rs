//! Compact `f32` elementary functions for the FPU-less firmware.
//!
//! `libm`'s `sinf`/`cosf`/`tanf` reduce any argument exactly (a 3.7 KiB routine) and compute
//! their kernels in `f64`, which on RV32IMA drags in about 5.5 KiB of `f64` soft-float; its
//! `atanf`/`atan2f` are larger than needed too. The laws only see angles of a few turns, so
//! here one sine/cosine kernel and one arctangent kernel serve every trigonometric call, in
//! `f32` only:
//!
//! * [`sin_cos`]: reduction by multiples of pi/2 with a two-part constant (exact for
//!   |x| < 6000 rad), then polynomials on [-pi/4, pi/4]. Absolute error below 2.5e-7 for
//!   |x| <= 100 rad and below 2e-6 up to [`MAX_TRIG_ARG`]; beyond that (or for NaN) it
//!   answers `(0, 1)`.
//! * [`atan2`] (and [`atan`]): octant reduction to [0, tan(pi/8)], one odd polynomial.
//!   Absolute error below 4e-7 rad everywhere (two f32 ulps near pi); `atan2(0, 0)` is 0.
//! * [`tan`] is `sin / cos`; relative error below 5e-7 on the steering range (+/-0.6 rad).
//!
//! * [`sqrt`]: an exponent-halving first guess and three Newton steps; relative error below
//!   3e-7 for normal arguments (0 for zero, negative and NaN arguments).
//!
//! The polynomial coefficients are least-squares fits on Chebyshev nodes (error of the
//! fits below 1e-8, under `f32` resolution). The tests compare against the host's `std`
//! functions. Nothing here uses `f64`.

use core::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// Largest argument [`sin_cos`] reduces; larger ones (and NaN) give `(0, 1)`.
pub const MAX_TRIG_ARG: f32 = 6000.0;

/// pi/2 in two parts: `PIO2_HI` has 12 significant bits, so `k * PIO2_HI` is exact for
/// |k| < 4096.
const PIO2_HI: f32 = 3217.0 / 2048.0;
const PIO2_LO: f32 = -4.454_455e-6;
const TWO_OVER_PI: f32 = core::f32::consts::FRAC_2_PI;
const TAN_PI_8: f32 = 0.414_213_57;

/// `(sin r - r) / r^3` as a polynomial in `r^2`, |r| <= pi/4.
const SIN: [f32; 3] = [-0.166_666_65, 0.008_332_749, -0.000_195_879_5];
/// `(cos r - 1) / r^2` as a polynomial in `r^2`, |r| <= pi/4.
const COS: [f32; 4] = [-0.5, 0.041_666_65, -0.001_388_759, 2.446_384e-5];
/// `(atan u - u) / u^3` as a polynomial in `u^2`, |u| <= tan(pi/8).
const ATAN: [f32; 5] = [
    -0.333_333_3,
    0.199_995_5,
    -0.142_642_33,
    0.107_462_98,
    -0.064_593_76,
];

/// `c[0] + c[1] z + c[2] z^2 + ...` by Horner's rule.
fn poly(c: &[f32], z: f32) -> f32 {
    c.iter().rev().fold(0.0, |acc, &k| acc * z + k)
}

/// Rounded to the nearest integer, halves away from zero (|v| < 2^31).
pub fn round(v: f32) -> f32 {
    // `as` truncates towards zero and saturates; NaN becomes 0.
    let t = v as i32 as f32;
    let d = v - t;
    if d >= 0.5 {
        t + 1.0
    } else if d <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

/// Sine and cosine of `x` (rad).
pub fn sin_cos(x: f32) -> (f32, f32) {
    if x.is_nan() || x.abs() > MAX_TRIG_ARG {
        return (0.0, 1.0);
    }
    let k = round(x * TWO_OVER_PI);
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let z = r * r;
    let s = r + r * z * poly(&SIN, z);
    let c = 1.0 + z * poly(&COS, z);
    // |k| <= 3820 here: the cast is exact.
    match (k as i32) & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// Sine of `x` (rad).
pub fn sin(x: f32) -> f32 {
    sin_cos(x).0
}

/// Cosine of `x` (rad).
pub fn cos(x: f32) -> f32 {
    sin_cos(x).1
}

/// Tangent of `x` (rad).
pub fn tan(x: f32) -> f32 {
    let (s, c) = sin_cos(x);
    s / c
}

/// Angle of the point `(x, y)` from +X, rad in -pi..=pi (0 for the origin).
pub fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (num, den) = if ay > ax { (ax, ay) } else { (ay, ax) };
    if den == 0.0 {
        return 0.0;
    }
    // t in [0, 1]; above tan(pi/8) it is shifted by pi/4 into [-tan(pi/8), 0].
    let t = num / den;
    let (base, u) = if t > TAN_PI_8 {
        (FRAC_PI_4, (t - 1.0) / (t + 1.0))
    } else {
        (0.0, t)
    };
    let z = u * u;
    let mut a = base + u + u * z * poly(&ATAN, z);
    if ay > ax {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 {
        -a
    } else {
        a
    }
}

/// Arctangent of `v`, rad in -pi/2..=pi/2.
pub fn atan(v: f32) -> f32 {
    atan2(v, 1.0)
}

/// Square root; 0 for arguments that are not positive (and NaN), infinity for infinity.
pub fn sqrt(v: f32) -> f32 {
    if v.is_nan() || v <= 0.0 {
        return 0.0;
    }
    if v == f32::INFINITY {
        return v;
    }
    // Halving the biased exponent (and with it the mantissa bits) gives the root within 4%.
    let mut y = f32::from_bits((v.to_bits() >> 1) + 0x1FBB_4F2E);
    for _ in 0..3 {
        y = 0.5 * (y + v / y);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Largest absolute error of `f` against `reference` over `n + 1` even steps of `lo..=hi`.
    fn worst(f: impl Fn(f32) -> f32, reference: impl Fn(f64) -> f64, lo: f32, hi: f32) -> f64 {
        let n = 200_000;
        (0..=n)
            .map(|i| {
                let x = lo + (hi - lo) * (i as f32 / n as f32);
                (f64::from(f(x)) - reference(f64::from(x))).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn sine_and_cosine_accuracy() {
        assert!(worst(sin, f64::sin, -100.0, 100.0) < 2.5e-7);
        assert!(worst(cos, f64::cos, -100.0, 100.0) < 2.5e-7);
        assert!(worst(sin, f64::sin, -MAX_TRIG_ARG, MAX_TRIG_ARG) < 2e-6);
        assert!(worst(cos, f64::cos, -MAX_TRIG_ARG, MAX_TRIG_ARG) < 2e-6);
        // At least as good as libm's own f32 results, within f32 rounding.
        let libm_err = worst(libm::sinf, f64::sin, -10.0, 10.0);
        assert!(worst(sin, f64::sin, -10.0, 10.0) < libm_err + 2e-7);
    }

    #[test]
    fn exact_points_and_out_of_range() {
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        let (s, c) = sin_cos(FRAC_PI_2);
        assert!((s - 1.0).abs() < 1e-7 && c.abs() < 1e-7);
        assert_eq!(sin_cos(f32::NAN), (0.0, 1.0));
        assert_eq!(sin_cos(1e9), (0.0, 1.0));
        assert_eq!(sin_cos(f32::INFINITY), (0.0, 1.0));
    }

    #[test]
    fn tangent_accuracy_on_the_steering_range() {
        for i in -600..=600 {
            let x = i as f32 * 1e-3;
            let r = f64::from(x).tan();
            let e = (f64::from(tan(x)) - r).abs();
            assert!(e <= 5e-7 * r.abs().max(1e-3), "{x}: {e}");
        }
    }

    #[test]
    fn arctangent_accuracy() {
        assert!(worst(atan, f64::atan, -50.0, 50.0) < 2.5e-7);
        assert!(worst(atan, f64::atan, -1e6, 1e6) < 2.5e-7);
        assert_eq!(atan(f32::INFINITY), FRAC_PI_2);
        assert_eq!(atan2(0.0, 0.0), 0.0);
        assert_eq!(atan2(0.0, -1.0), PI);
        assert_eq!(atan2(0.0, 1.0), 0.0);
        assert!((atan2(-1.0, -1.0) + 3.0 * FRAC_PI_4).abs() < 2.5e-7);
    }

    #[test]
    fn square_root_accuracy() {
        let mut x = 1e-30f32;
        while x < 1e30 {
            for k in [1.0f32, 1.37, 2.0, 3.3, 7.9] {
                let v = x * k;
                let r = f64::from(v).sqrt();
                let e = (f64::from(sqrt(v)) - r).abs() / r;
                assert!(e < 3e-7, "{v}: {e}");
            }
            x *= 10.0;
        }
        assert_eq!(sqrt(0.0), 0.0);
        assert_eq!(sqrt(-4.0), 0.0);
        assert_eq!(sqrt(f32::NAN), 0.0);
        assert_eq!(sqrt(f32::INFINITY), f32::INFINITY);
        assert_eq!(sqrt(25.0), 5.0);
    }

    #[test]
    fn atan2_near_minus_pi() {
        // Third quadrant, result close to -pi: the case that needs the two-ulp bound.
        let (y, x) = (-2592.646f32, -4402.3296f32);
        let e = (f64::from(atan2(y, x)) - f64::from(y).atan2(f64::from(x))).abs();
        assert!(e < 4e-7, "{e}");
    }

    #[test]
    fn rounding() {
        assert_eq!(round(2.5), 3.0);
        assert_eq!(round(-2.5), -3.0);
        assert_eq!(round(2.49), 2.0);
        assert_eq!(round(-0.4), 0.0);
        assert_eq!(round(6282.6), 6283.0);
        assert_eq!(round(f32::NAN), 0.0);
    }

    proptest! {
        #[test]
        fn atan2_matches_std_everywhere(y in -1e4f32..1e4, x in -1e4f32..1e4) {
            let e = (f64::from(atan2(y, x)) - f64::from(y).atan2(f64::from(x))).abs();
            // The two answers for points on the negative X axis (pi and -pi) are both right.
            // Near +/-pi one f32 ulp is 2.4e-7, so the bound is two ulps there.
            prop_assert!(e < 4e-7 || (e - 2.0 * std::f64::consts::PI).abs() < 1e-6, "{} {} {}", y, x, e);
        }

        #[test]
        fn sin_cos_is_on_the_unit_circle(x in -1000f32..1000.0) {
            let (s, c) = sin_cos(x);
            prop_assert!((s * s + c * c - 1.0).abs() < 1e-6);
        }
    }
}
