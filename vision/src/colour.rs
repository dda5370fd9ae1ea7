//! Colour classes: a 256-entry table from an RGB332 pixel to a class (0 = background), and a
//! 64 KiB pair table that classifies two adjacent pixels with one lookup (the class when both
//! agree, [`MIXED`] otherwise). Both are built at compile time by `const fn`, so firmware keeps
//! them in read-only memory.

/// Class of pixels that belong to no marker.
pub const BACKGROUND: u8 = 0;
/// Pair-table entry for two pixels of different classes.
pub const MIXED: u8 = 0xFF;
/// Most marker classes a table can hold (class numbers 1..=MAX_CLASSES).
pub const MAX_CLASSES: usize = 15;

/// An 8-bit-per-channel colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Rgb {
    pub r: u8,
    pub g: u8,
    pub b: u8,
}

impl Rgb {
    pub const fn new(r: u8, g: u8, b: u8) -> Self {
        Rgb { r, g, b }
    }

    /// `RRRGGGBB`, truncating.
    pub const fn to_rgb332(self) -> u8 {
        (self.r & 0xE0) | ((self.g >> 5) << 2) | (self.b >> 6)
    }

    /// `RRRRRGGG GGGBBBBB`, truncating.
    pub const fn to_rgb565(self) -> u16 {
        ((self.r as u16 >> 3) << 11) | ((self.g as u16 >> 2) << 5) | (self.b as u16 >> 3)
    }

    /// The colour at the middle of an RGB332 code's cell, each channel scaled to 0..=255.
    pub const fn from_rgb332(p: u8) -> Self {
        let r = p >> 5;
        let g = (p >> 2) & 7;
        let b = p & 3;
        Rgb {
            r: ((r as u16 * 255) / 7) as u8,
            g: ((g as u16 * 255) / 7) as u8,
            b: ((b as u16 * 255) / 3) as u8,
        }
    }

    /// Each channel scaled to 0..=255.
    pub const fn from_rgb565(p: u16) -> Self {
        let r = (p >> 11) & 0x1F;
        let g = (p >> 5) & 0x3F;
        let b = p & 0x1F;
        Rgb {
            r: ((r * 255) / 31) as u8,
            g: ((g * 255) / 63) as u8,
            b: ((b * 255) / 31) as u8,
        }
    }
}

/// RGB565 pixel to the RGB332 code of its top bits (used to classify RGB565 frames).
pub const fn rgb565_to_rgb332(p: u16) -> u8 {
    let hi = (p >> 8) as u8;
    let lo = p as u8;
    (hi & 0xE0) | ((hi & 0x07) << 2) | ((lo >> 3) & 0x03)
}

/// Marker colours of the cars: car `id` carries `MARKER_PALETTE[id % 8]`, which is colour class
/// `id % 8 + 1` of [`MARKER_CLASSES`].
pub const MARKER_PALETTE: [Rgb; 8] = [
    Rgb::new(255, 0, 0),   // red
    Rgb::new(0, 255, 0),   // green
    Rgb::new(0, 0, 255),   // blue
    Rgb::new(255, 255, 0), // yellow
    Rgb::new(255, 0, 255), // magenta
    Rgb::new(0, 255, 255), // cyan
    Rgb::new(255, 128, 0), // orange
    Rgb::new(128, 0, 255), // violet
];

/// Largest distance (8-bit RGB, Euclidean) from a palette colour that still counts as a marker.
pub const MARKER_MAX_DISTANCE: u16 = 72;

/// The tables for [`MARKER_PALETTE`].
pub static MARKER_CLASSES: ColourClasses =
    ColourClasses::from_palette(&MARKER_PALETTE, MARKER_MAX_DISTANCE);

/// Colour class of the marker on car `id`.
pub const fn marker_class_for_car(id: u8) -> u8 {
    id % 8 + 1
}

/// Class lookup tables.
#[derive(Clone)]
pub struct ColourClasses {
    class: [u8; 256],
    pair: [u8; 65536],
}

impl core::fmt::Debug for ColourClasses {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ColourClasses")
            .field("class", &&self.class[..])
            .finish_non_exhaustive()
    }
}

impl ColourClasses {
    /// Builds the tables from a class per RGB332 code; classes above [`MAX_CLASSES`] count as
    /// background.
    pub const fn from_table(table: [u8; 256]) -> Self {
        let mut class = table;
        let mut i = 0;
        while i < 256 {
            if class[i] as usize > MAX_CLASSES {
                class[i] = BACKGROUND;
            }
            i += 1;
        }
        let mut pair = [0u8; 65536];
        let mut a = 0;
        while a < 256 {
            let mut b = 0;
            while b < 256 {
                pair[a | (b << 8)] = if class[a] == class[b] {
                    class[a]
                } else {
                    MIXED
                };
                b += 1;
            }
            a += 1;
        }
        ColourClasses { class, pair }
    }

    /// Class `i + 1` for the RGB332 codes nearest to `palette[i]` within `max_distance`; palette
    /// entries past [`MAX_CLASSES`] are ignored.
    pub const fn from_palette(palette: &[Rgb], max_distance: u16) -> Self {
        let limit = max_distance as i32 * max_distance as i32;
        let mut table = [BACKGROUND; 256];
        let mut code = 0;
        while code < 256 {
            let c = Rgb::from_rgb332(code as u8);
            let mut best = i32::MAX;
            let mut k = 0;
            while k < palette.len() && k < MAX_CLASSES {
                let dr = c.r as i32 - palette[k].r as i32;
                let dg = c.g as i32 - palette[k].g as i32;
                let db = c.b as i32 - palette[k].b as i32;
                let d = dr * dr + dg * dg + db * db;
                if d <= limit && d < best {
                    best = d;
                    table[code] = k as u8 + 1;
                }
                k += 1;
            }
            code += 1;
        }
        Self::from_table(table)
    }

    /// Class of an RGB332 pixel.
    #[inline(always)]
    pub fn class_of_rgb332(&self, p: u8) -> u8 {
        self.class[usize::from(p)]
    }

    /// Class of an RGB565 pixel.
    #[inline(always)]
    pub fn class_of_rgb565(&self, p: u16) -> u8 {
        self.class[usize::from(rgb565_to_rgb332(p))]
    }

    /// Class of two adjacent RGB332 pixels given as `first | second << 8`, or [`MIXED`].
    #[inline(always)]
    pub fn class_of_pair_index(&self, pair: u16) -> u8 {
        self.pair[usize::from(pair)]
    }

    /// Class of two adjacent RGB332 pixels, or [`MIXED`].
    #[inline(always)]
    pub fn class_of_pair(&self, first: u8, second: u8) -> u8 {
        self.pair[usize::from(first) | (usize::from(second) << 8)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_keep_top_bits() {
        let c = Rgb::new(0b1010_1111, 0b0110_0000, 0b1100_0001);
        assert_eq!(c.to_rgb332(), 0b1010_1111); // RRR GGG BB = 101 011 11
        assert_eq!(c.to_rgb565(), 0b1010_1011_0001_1000); // 10101 011000 11000
        assert_eq!(rgb565_to_rgb332(c.to_rgb565()), c.to_rgb332());
        assert_eq!(Rgb::from_rgb332(0xFF), Rgb::new(255, 255, 255));
        assert_eq!(Rgb::from_rgb565(0), Rgb::new(0, 0, 0));
    }

    #[test]
    fn every_rgb565_maps_like_its_rgb332_truncation() {
        for p in 0..=u16::MAX {
            let widened = Rgb::new(
                ((p >> 11) << 3) as u8,
                (((p >> 5) & 0x3F) << 2) as u8,
                ((p & 0x1F) << 3) as u8,
            );
            assert_eq!(rgb565_to_rgb332(p), widened.to_rgb332(), "{p:#06x}");
        }
    }

    #[test]
    fn palette_colours_and_noise_land_in_their_class() {
        for (k, c) in MARKER_PALETTE.iter().enumerate() {
            let want = k as u8 + 1;
            assert_eq!(MARKER_CLASSES.class_of_rgb332(c.to_rgb332()), want, "{c:?}");
            assert_eq!(MARKER_CLASSES.class_of_rgb565(c.to_rgb565()), want, "{c:?}");
            for d in [-16i16, 16] {
                let n = |v: u8| (i16::from(v) + d).clamp(0, 255) as u8;
                let noisy = Rgb::new(n(c.r), n(c.g), n(c.b));
                assert_eq!(
                    MARKER_CLASSES.class_of_rgb332(noisy.to_rgb332()),
                    want,
                    "{noisy:?}"
                );
            }
        }
    }

    #[test]
    fn scene_colours_are_background() {
        for c in [
            Rgb::new(128, 128, 128),
            Rgb::new(160, 150, 130),
            Rgb::new(230, 230, 230),
            Rgb::new(60, 60, 60),
            Rgb::new(30, 30, 40),
            Rgb::new(0, 0, 0),
            Rgb::new(255, 255, 255),
        ] {
            assert_eq!(
                MARKER_CLASSES.class_of_rgb332(c.to_rgb332()),
                BACKGROUND,
                "{c:?}"
            );
        }
    }

    #[test]
    fn pair_table_agrees_with_single_table() {
        for a in 0..=255u8 {
            for b in 0..=255u8 {
                let (ca, cb) = (
                    MARKER_CLASSES.class_of_rgb332(a),
                    MARKER_CLASSES.class_of_rgb332(b),
                );
                let want = if ca == cb { ca } else { MIXED };
                assert_eq!(MARKER_CLASSES.class_of_pair(a, b), want);
            }
        }
    }

    #[test]
    fn out_of_range_classes_become_background() {
        let mut t = [0u8; 256];
        t[3] = 16;
        t[4] = 15;
        let c = ColourClasses::from_table(t);
        assert_eq!(c.class_of_rgb332(3), BACKGROUND);
        assert_eq!(c.class_of_rgb332(4), 15);
    }
}
