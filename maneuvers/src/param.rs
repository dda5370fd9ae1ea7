//! A law's parameters: their description ([`Param`], part of the law's registration) and
//! their values ([`Values`], what the law is built from).
//!
//! Every parameter is an integer in a closed range; a parameter with named choices (a shape)
//! takes the index of the choice. Its range also fixes its width on the wire (1, 2 or 4
//! bytes, see [`Param::wire_len`]).

/// Most parameters a law may have.
pub const MAX_PARAMS: usize = 8;

/// One parameter of a law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Param {
    /// Name in commands and files: lowercase letters, digits and `_`, with the unit as a
    /// suffix where there is one (`spacing_units`, `speed_mm_s`).
    pub name: &'static str,
    /// Unit (`units` = tracking units of 2.5 mm, `mm/s`, `mrad`, `ms`, `car ID`, ...), empty
    /// for a count or a choice.
    pub unit: &'static str,
    /// Smallest value.
    pub min: i32,
    /// Largest value.
    pub max: i32,
    /// Value when a command does not give one (`None`: it must be given).
    pub default: Option<i32>,
    /// Names of the values `0, 1, ...` for a choice (empty otherwise).
    pub choices: &'static [&'static str],
    /// What it means.
    pub doc: &'static str,
}

impl Param {
    /// An integer parameter in `min..=max`, required unless given a [`Param::default`].
    pub const fn int(name: &'static str, unit: &'static str, min: i32, max: i32) -> Param {
        Param {
            name,
            unit,
            min,
            max,
            default: None,
            choices: &[],
            doc: "",
        }
    }

    /// A parameter naming one of `choices` (value = index); the first is the default.
    pub const fn choice(name: &'static str, choices: &'static [&'static str]) -> Param {
        Param {
            name,
            unit: "",
            min: 0,
            max: choices.len() as i32 - 1,
            default: Some(0),
            choices,
            doc: "",
        }
    }

    /// The same with a default value.
    pub const fn default(self, value: i32) -> Param {
        Param {
            default: Some(value),
            ..self
        }
    }

    /// The same with its meaning.
    pub const fn doc(self, doc: &'static str) -> Param {
        Param { doc, ..self }
    }

    /// The range without the texts (what the firmware needs).
    pub const fn range(&self) -> Range {
        Range {
            min: self.min,
            max: self.max,
        }
    }

    /// The value named `word` among the choices.
    pub fn choice_value(&self, word: &str) -> Option<i32> {
        self.choices
            .iter()
            .position(|c| *c == word)
            .and_then(|i| i32::try_from(i).ok())
    }
}

/// A parameter's range, which also fixes its wire width.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Range {
    /// Smallest value.
    pub min: i32,
    /// Largest value.
    pub max: i32,
}

impl Range {
    /// `max - min` (in 32 bits: the ranges are checked to be non-empty).
    pub const fn span(&self) -> u32 {
        self.max.wrapping_sub(self.min) as u32
    }

    /// Bytes on the wire: the narrowest of 1, 2 or 4 that holds `max - min`.
    pub const fn wire_len(&self) -> usize {
        let span = self.span();
        if span <= 0xFF {
            1
        } else if span <= 0xFFFF {
            2
        } else {
            4
        }
    }

    /// Whether `v` is in the range.
    pub const fn contains(&self, v: i64) -> bool {
        v >= self.min as i64 && v <= self.max as i64
    }
}

impl Param {
    /// Bytes on the wire.
    pub const fn wire_len(&self) -> usize {
        self.range().wire_len()
    }
}

/// The values of a law's parameters, in its [`Param`] order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Values {
    v: [i32; MAX_PARAMS],
    len: u8,
}

impl Values {
    /// No values.
    pub const EMPTY: Values = Values {
        v: [0; MAX_PARAMS],
        len: 0,
    };

    /// Values from a slice (at most [`MAX_PARAMS`]; more are `None`).
    pub fn from_slice(values: &[i32]) -> Option<Values> {
        if values.len() > MAX_PARAMS {
            return None;
        }
        let mut v = [0; MAX_PARAMS];
        for (d, s) in v.iter_mut().zip(values) {
            *d = *s;
        }
        Some(Values {
            v,
            // At most MAX_PARAMS: exact.
            len: values.len() as u8,
        })
    }

    /// The values as a slice.
    pub fn as_slice(&self) -> &[i32] {
        self.v.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Number of values.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// True without values.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Value `i` (0 past the end).
    pub fn get(&self, i: usize) -> i32 {
        // Past `len` the array holds zeros.
        self.v.get(i).copied().unwrap_or(0)
    }

    /// Value `i` as `u8`: a plain cast, exact for a parameter whose range fits `u8` (the
    /// value is within its range).
    pub fn u8(&self, i: usize) -> u8 {
        self.get(i) as u8
    }

    /// Value `i` as `u16` (a cast, exact for a range that fits).
    pub fn u16(&self, i: usize) -> u16 {
        self.get(i) as u16
    }

    /// Value `i` as `i16` (a cast, exact for a range that fits).
    pub fn i16(&self, i: usize) -> i16 {
        self.get(i) as i16
    }

    /// Replaces value `i` (ignored past the end).
    pub fn set(&mut self, i: usize, value: i32) {
        if i < self.len() {
            if let Some(v) = self.v.get_mut(i) {
                *v = value;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widths_follow_the_range() {
        assert_eq!(Param::int("a", "", 0, 255).wire_len(), 1);
        assert_eq!(Param::int("a", "", -1, 14).wire_len(), 1);
        assert_eq!(Param::int("a", "", -128, 128).wire_len(), 2);
        assert_eq!(Param::int("a", "", -2048, 2047).wire_len(), 2);
        assert_eq!(Param::int("a", "", 0, 65_536).wire_len(), 4);
        assert_eq!(Param::int("a", "", i32::MIN, i32::MAX).wire_len(), 4);
        let shape = Param::choice("shape", &["line", "wedge"]);
        assert_eq!((shape.min, shape.max, shape.default), (0, 1, Some(0)));
        assert_eq!(shape.choice_value("wedge"), Some(1));
        assert_eq!(shape.choice_value("v"), None);
    }

    #[test]
    fn values_cast() {
        let v = Values::from_slice(&[200, 65_000, -300]).unwrap();
        assert_eq!(
            (v.u8(0), v.u16(1), v.i16(2), v.get(3)),
            (200, 65_000, -300, 0)
        );
        assert_eq!(v.as_slice(), &[200, 65_000, -300]);
        assert!(Values::from_slice(&[0; MAX_PARAMS + 1]).is_none());
    }
}
