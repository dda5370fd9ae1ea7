//! Integer helpers for laws written without floating point: square root and distance,
//! sine and cosine of an angle in mrad as Q14 fixed point (`1 << 14` = 1.0), and vector
//! length limiting. Every function is exact or documented with its error, and cheap on a
//! core without an FPU (a few dozen integer instructions).

/// 1.0 in the Q14 fixed point of [`sin_cos_mrad`].
pub const ONE_Q14: i32 = 1 << 14;

/// `round(16384 * sin(i * pi / 256))` for `i` in 0..=128: a quarter wave.
const QUARTER: [i16; 129] = [
    0, 201, 402, 603, 804, 1005, 1205, 1406, 1606, 1806, 2006, 2205, 2404, 2603, 2801, 2999, 3196,
    3393, 3590, 3786, 3981, 4176, 4370, 4563, 4756, 4948, 5139, 5330, 5520, 5708, 5897, 6084, 6270,
    6455, 6639, 6823, 7005, 7186, 7366, 7545, 7723, 7900, 8076, 8250, 8423, 8595, 8765, 8935, 9102,
    9269, 9434, 9598, 9760, 9921, 10080, 10238, 10394, 10549, 10702, 10853, 11003, 11151, 11297,
    11442, 11585, 11727, 11866, 12004, 12140, 12274, 12406, 12537, 12665, 12792, 12916, 13039,
    13160, 13279, 13395, 13510, 13623, 13733, 13842, 13949, 14053, 14155, 14256, 14354, 14449,
    14543, 14635, 14724, 14811, 14896, 14978, 15059, 15137, 15213, 15286, 15357, 15426, 15493,
    15557, 15619, 15679, 15736, 15791, 15843, 15893, 15941, 15986, 16029, 16069, 16107, 16143,
    16176, 16207, 16235, 16261, 16284, 16305, 16324, 16340, 16353, 16364, 16373, 16379, 16383,
    16384,
];

/// Largest `r` with `r * r <= v` (floor of the square root).
// Out of line: its loop inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub fn isqrt(v: u32) -> u32 {
    // Bit by bit, from the highest even bit of v.
    let mut rem = v;
    let mut root = 0u32;
    let mut bit = 1u32 << 30;
    while bit > v {
        bit >>= 2;
    }
    while bit != 0 {
        if rem >= root + bit {
            rem -= root + bit;
            root = (root >> 1) + bit;
        } else {
            root >>= 1;
        }
        bit >>= 2;
    }
    root
}

/// `dx * dx + dy * dy`, saturated at `u32::MAX` (exact while below it: for components up to
/// 46 340, far beyond the arena's 1 000 units).
// Out of line: its saturating products inlined at each use made the firmware larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub fn dist2(dx: i32, dy: i32) -> u32 {
    let (x, y) = (dx.unsigned_abs(), dy.unsigned_abs());
    x.saturating_mul(x).saturating_add(y.saturating_mul(y))
}

/// Length of `(dx, dy)`, rounded down (see [`dist2`] for the range).
pub fn hypot(dx: i32, dy: i32) -> u32 {
    isqrt(dist2(dx, dy))
}

/// `(dx, dy)` shortened to at most `max` (unchanged when shorter), within 1 of the exact
/// length. 32-bit divisions only (the core divides 32-bit numbers in hardware; 64-bit
/// divisions are a library call).
pub fn clamp_norm(dx: i32, dy: i32, max: u16) -> (i32, i32) {
    let n = hypot(dx, dy);
    if n <= u32::from(max) || n == 0 {
        return (dx, dy);
    }
    // max / n in Q16, below 1.0.
    let scale = (u32::from(max) << 16) / n;
    let shrink = |v: i32| ((i64::from(v) * i64::from(scale)) >> 16) as i32;
    (shrink(dx), shrink(dy))
}

/// Sine on a quarter turn, `r` in 0..=65536 (binary angle of 2^18 per turn: 65536 = pi/2),
/// linear interpolation of [`QUARTER`].
// Out of line: called from four places, it is smaller as one call each.
#[inline(never)]
fn quarter_sin(r: u32) -> i32 {
    let i = (r >> 9) as usize;
    let f = (r & 0x1FF) as i32;
    let a = i32::from(QUARTER[i.min(128)]);
    let b = i32::from(QUARTER[(i + 1).min(128)]);
    a + (((b - a) * f + 256) >> 9)
}

/// Sine of a binary angle (2^18 = one turn), Q14.
pub(crate) fn sin_binary(b: u32) -> i32 {
    let r = b & 0xFFFF;
    match (b >> 16) & 3 {
        0 => quarter_sin(r),
        1 => quarter_sin(0x1_0000 - r),
        2 => -quarter_sin(r),
        _ => -quarter_sin(0x1_0000 - r),
    }
}

/// Sine and cosine of `mrad` (6283.185 mrad = one turn), each in Q14 (16384 = 1.0), within 2
/// of the exact value times 16384 for `|mrad| <= 100_000` (16 turns; beyond, the error grows
/// by about 1 per 150 000 mrad).
pub fn sin_cos_mrad(mrad: i32) -> (i32, i32) {
    // 2^18 / (2 pi 1000) in Q16, rounded: mrad to binary angle.
    let b = ((i64::from(mrad) * 2_734_261 + (1 << 15)) >> 16) as u32;
    (sin_binary(b), sin_binary(b.wrapping_add(0x1_0000)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn square_roots() {
        for v in [
            0u32,
            1,
            2,
            3,
            4,
            15,
            16,
            17,
            99,
            100,
            65_535,
            1 << 30,
            u32::MAX,
        ] {
            let r = u64::from(isqrt(v));
            let v = u64::from(v);
            assert!(r * r <= v, "{v}");
            assert!((r + 1) * (r + 1) > v, "{v}");
        }
        assert_eq!(dist2(65_536, 0), u32::MAX);
        assert_eq!(hypot(3, -4), 5);
        assert_eq!(hypot(-600, 800), 1000);
        assert_eq!(clamp_norm(300, 400, 100), (59, 79));
        let (x, y) = clamp_norm(-3000, 4000, 1000);
        assert!(
            (hypot(x, y) as i32 - 1000).abs() <= 1 && x < 0 && y > 0,
            "{x} {y}"
        );
        assert_eq!(clamp_norm(3, 4, 100), (3, 4));
        assert_eq!(clamp_norm(0, 0, 0), (0, 0));
    }

    #[test]
    fn sine_and_cosine_within_two_lsb() {
        let mut worst = 0.0f64;
        for mrad in -100_000..100_000 {
            let (s, c) = sin_cos_mrad(mrad);
            let a = f64::from(mrad) / 1000.0;
            let (es, ec) = (a.sin() * 16384.0, a.cos() * 16384.0);
            worst = worst.max((f64::from(s) - es).abs().max((f64::from(c) - ec).abs()));
            assert!((f64::from(s) - es).abs() <= 2.0, "sin {mrad}: {s} vs {es}");
            assert!((f64::from(c) - ec).abs() <= 2.0, "cos {mrad}: {c} vs {ec}");
        }
        eprintln!("largest error {worst:.3} / 16384");
        assert_eq!(sin_cos_mrad(0), (0, ONE_Q14));
    }

    proptest! {
        #[test]
        fn isqrt_is_the_floor(v in any::<u32>()) {
            let r = u64::from(isqrt(v));
            let v = u64::from(v);
            prop_assert!(r * r <= v);
            prop_assert!((r + 1) * (r + 1) > v);
        }
    }
}
