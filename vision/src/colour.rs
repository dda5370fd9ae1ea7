//! Colour classes: a 256-entry table from an RGB332 pixel to a class (0 = background), built at
//! compile time by `const fn` so firmware keeps it in read-only memory, and a word test that lets
//! the row scan skip four background pixels with a few ALU instructions.
//!
//! The word test relies on markers being saturated colours: every marker code has a channel with
//! its top two bits set ("high") and a channel with its top bit clear ("low"). A word whose four
//! pixels have no high channel at all (floor, dark backdrop, car bodies) or no low channel at all
//! (white walls) holds no marker pixel. [`ColourClasses::from_table`] checks the property for its
//! table; a table that breaks it disables the skip, and the scan looks at every pixel.

/// Class of pixels that belong to no marker.
pub const BACKGROUND: u8 = 0;
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

/// Bits 7, 4 and 1 of each byte of a word: the top bit of red, green and blue in `RRRGGGBB`.
pub const TOP_BITS: u32 = 0x9292_9292;

/// Whether RGB332 code `p` is saturated in the sense of the word test: some channel has its top
/// two bits set and some channel has its top bit clear.
pub const fn is_saturated(p: u8) -> bool {
    let high = p & (p << 1) & 0x92;
    let low = !p & 0x92;
    high != 0 && low != 0
}

/// Whether a word of four RGB332 pixels may hold a saturated pixel. `false` guarantees that none
/// of the four is saturated: no byte has a high channel, or every byte has all three top bits set.
#[inline(always)]
pub const fn word_may_be_saturated(w: u32) -> bool {
    (w & (w << 1) & TOP_BITS) != 0 && (w & TOP_BITS) != TOP_BITS
}

/// Class lookup table.
#[derive(Clone)]
pub struct ColourClasses {
    class: [u8; 256],
    /// Every non-background code is saturated, so words failing [`word_may_be_saturated`] are
    /// background.
    skip_unsaturated: bool,
}

impl core::fmt::Debug for ColourClasses {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ColourClasses")
            .field("class", &&self.class[..])
            .field("skip_unsaturated", &self.skip_unsaturated)
            .finish()
    }
}

impl ColourClasses {
    /// Builds the table from a class per RGB332 code; classes above [`MAX_CLASSES`] count as
    /// background.
    pub const fn from_table(table: [u8; 256]) -> Self {
        let mut class = table;
        let mut skip_unsaturated = true;
        let mut i = 0;
        while i < 256 {
            if class[i] as usize > MAX_CLASSES {
                class[i] = BACKGROUND;
            }
            if class[i] != BACKGROUND && !is_saturated(i as u8) {
                skip_unsaturated = false;
            }
            i += 1;
        }
        ColourClasses {
            class,
            skip_unsaturated,
        }
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

    /// Whether the four RGB332 pixels of `w` (first pixel in the low byte) are certainly all
    /// background: a cheap test that is exact in one direction only (`false` says nothing).
    #[inline(always)]
    pub fn word_is_background(&self, w: u32) -> bool {
        self.skip_unsaturated && !word_may_be_saturated(w)
    }

    /// The class of every RGB332 code (what the vision unit's table is loaded with).
    pub fn table(&self) -> &[u8; 256] {
        &self.class
    }

    /// Whether [`ColourClasses::word_is_background`] can ever answer `true` for this table.
    pub fn skips_background_words(&self) -> bool {
        self.skip_unsaturated
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
    fn every_marker_code_is_saturated_so_words_can_be_skipped() {
        assert!(MARKER_CLASSES.skips_background_words());
        for p in 0..=255u8 {
            if MARKER_CLASSES.class_of_rgb332(p) != BACKGROUND {
                assert!(is_saturated(p), "{p:#04x}");
            }
        }
    }

    #[test]
    fn word_test_never_skips_a_saturated_pixel() {
        // Exhaustive over one saturated byte at every position among fixed fillers, and over
        // all byte pairs repeated.
        let fillers = [0x00u8, 0xFF, 0x92, 0x49, 0x6D, 0xB6, 0xDB, 0x25];
        for p in 0..=255u8 {
            for &f in &fillers {
                for pos in 0..4 {
                    let mut b = [f; 4];
                    b[pos] = p;
                    let w = u32::from_le_bytes(b);
                    if is_saturated(p) || is_saturated(f) {
                        assert!(word_may_be_saturated(w), "{w:#010x}");
                    }
                }
            }
            for q in 0..=255u8 {
                let w = u32::from_le_bytes([p, q, q, p]);
                let any = is_saturated(p) || is_saturated(q);
                assert!(!any || word_may_be_saturated(w), "{w:#010x}");
            }
        }
    }

    #[test]
    fn scene_words_are_skipped() {
        // Floor greys, white walls, the dark backdrop and car bodies, noisy by +/-12.
        for base in [
            Rgb::new(150, 140, 120),
            Rgb::new(120, 115, 100),
            Rgb::new(225, 225, 225),
            Rgb::new(40, 40, 48),
            Rgb::new(70, 70, 70),
        ] {
            for d in [-12i16, 0, 12] {
                let n = |v: u8| (i16::from(v) + d).clamp(0, 255) as u8;
                let p = Rgb::new(n(base.r), n(base.g), n(base.b)).to_rgb332();
                let w = u32::from_le_bytes([p; 4]);
                assert!(
                    MARKER_CLASSES.word_is_background(w),
                    "{base:?} {d} {p:#04x}"
                );
            }
        }
    }

    #[test]
    fn a_table_with_an_unsaturated_class_disables_the_skip() {
        let mut t = [0u8; 256];
        t[0x92] = 1; // mid grey
        let c = ColourClasses::from_table(t);
        assert!(!c.skips_background_words());
        assert!(!c.word_is_background(0x9292_9292));
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
