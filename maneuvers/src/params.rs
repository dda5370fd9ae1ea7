//! A group command's maneuver: the law's ID, option overrides and parameter values, and
//! their wire form.
//!
//! The wire form (the body of the console's `GroupStart`, version 2; field tables in
//! `docs/radio-protocol.md`) is a 4-byte header (law ID, reverse mode, arrival radius,
//! neighbour selection; 0 in an option byte keeps the law's default) followed by the
//! parameters in the law's order, each as `value - min`, little-endian, in the narrowest of
//! 1, 2 or 4 bytes that holds its range. The parameter layout comes from the registration
//! list (`laws/mod.rs`), so a law ID this firmware does not know is refused
//! ([`DecodeError::UnknownLaw`]). Decoding is canonical: whatever decodes re-encodes to the
//! same bytes.

use crate::law::{LawOptions, Neighbours, Reverse, MAX_NEAREST};
use crate::laws;
use crate::param::{Range, Values, MAX_PARAMS};

/// Length of the header before the parameters.
pub const HEADER_LEN: usize = 4;
/// Longest wire form: what fits a console request body (32 bytes less the version byte).
pub const MAX_LEN: usize = 31;
/// Law ID 0: no maneuver (the car stops).
pub const IDLE_LAW: u8 = 0;

const NEIGHBOURS_NONE: u8 = 254;
const NEIGHBOURS_ALL: u8 = 255;

/// Options a group command sets instead of the law's defaults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Overrides {
    /// Reverse mode.
    pub reverse: Option<Reverse>,
    /// Arrival radius, tracking units (1..=255).
    pub arrival_units: Option<u8>,
    /// Neighbour selection.
    pub neighbours: Option<Neighbours>,
}

impl Overrides {
    /// `defaults` with these overrides applied.
    pub fn apply(&self, defaults: LawOptions) -> LawOptions {
        LawOptions {
            reverse: self.reverse.unwrap_or(defaults.reverse),
            arrival_units: self.arrival_units.unwrap_or(defaults.arrival_units),
            neighbours: self.neighbours.unwrap_or(defaults.neighbours),
        }
    }
}

/// A law and its parameters, as a group command carries them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ManeuverParams {
    law: u8,
    overrides: Overrides,
    values: Values,
}

/// Why parameters cannot be built or encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// No law with this ID is registered.
    UnknownLaw {
        /// The law ID.
        law: u8,
    },
    /// Not as many values as the law has parameters.
    Count {
        /// Parameters of the law.
        expected: u8,
        /// Values given.
        got: u8,
    },
    /// A value is outside its parameter's range.
    FieldOutOfRange {
        /// Index of the parameter in the law's list.
        param: u8,
    },
    /// An option override is not valid (`Nearest(0)`, more than 16 nearest).
    BadOption,
    /// The output buffer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
}

/// Why bytes do not decode into parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Shorter than the header, or not the length the law's parameters need.
    Length {
        /// Required length (the header's for a short input).
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// The law ID is not in this firmware's registration list.
    UnknownLaw {
        /// The law ID.
        law: u8,
    },
    /// An option byte holds a value without meaning (or idle with options).
    BadOption {
        /// Its offset.
        offset: u8,
    },
    /// A parameter is outside its range.
    FieldOutOfRange {
        /// Index of the parameter in the law's list.
        param: u8,
    },
}

/// The parameter ranges of law `law` (`None`: not registered; law 0 has none).
fn law_ranges(law: u8) -> Option<&'static [Range]> {
    if law == IDLE_LAW {
        return Some(&[]);
    }
    laws::ranges(law)
}

// The byte helpers below never panic (a panic site with a formatted message would pull the
// formatting code into the firmware); callers check the lengths first.

fn put_le(out: &mut [u8], at: usize, v: u32, len: usize) {
    if let Some(d) = out.get_mut(at..at + len) {
        for (d, b) in d.iter_mut().zip(v.to_le_bytes()) {
            *d = b;
        }
    }
}

fn get_le(b: &[u8], at: usize, len: usize) -> u32 {
    b.get(at..at + len).map_or(0, |s| {
        s.iter().rev().fold(0, |w, &x| (w << 8) | u32::from(x))
    })
}

/// Bytes of the parameters with these ranges.
fn params_len(ranges: &[Range]) -> usize {
    ranges.iter().map(Range::wire_len).sum()
}

impl ManeuverParams {
    /// No maneuver.
    pub const IDLE: ManeuverParams = ManeuverParams {
        law: IDLE_LAW,
        overrides: Overrides {
            reverse: None,
            arrival_units: None,
            neighbours: None,
        },
        values: Values::EMPTY,
    };

    /// Law `law` with `values` in its parameter order, each checked against its range.
    pub fn new(law: u8, values: &[i32]) -> Result<Self, EncodeError> {
        let ranges = law_ranges(law).ok_or(EncodeError::UnknownLaw { law })?;
        if values.len() != ranges.len() {
            return Err(EncodeError::Count {
                expected: ranges.len() as u8,
                got: values.len().min(255) as u8,
            });
        }
        for (i, (v, r)) in values.iter().zip(ranges).enumerate() {
            if !r.contains(i64::from(*v)) {
                return Err(EncodeError::FieldOutOfRange { param: i as u8 });
            }
        }
        Ok(ManeuverParams {
            law,
            overrides: Overrides::default(),
            // n <= MAX_PARAMS.
            values: Values::from_slice(values).unwrap_or_default(),
        })
    }

    /// The law ID (0: none).
    pub fn law(&self) -> u8 {
        self.law
    }

    /// True for "no maneuver".
    pub fn is_idle(&self) -> bool {
        self.law == IDLE_LAW
    }

    /// The parameter values.
    pub fn values(&self) -> &Values {
        &self.values
    }

    /// The option overrides.
    pub fn overrides(&self) -> Overrides {
        self.overrides
    }

    /// The same with these option overrides.
    pub fn with_overrides(self, overrides: Overrides) -> Self {
        Self { overrides, ..self }
    }

    /// The options in force: the law's defaults with the overrides (`None` for idle).
    pub fn options(&self) -> Option<LawOptions> {
        laws::default_options(self.law).map(|d| self.overrides.apply(d))
    }

    /// Bytes of the wire form.
    pub fn wire_len(&self) -> usize {
        law_ranges(self.law).map_or(HEADER_LEN, |r| HEADER_LEN + params_len(r))
    }

    /// Writes the wire form to `out`; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let law = self.law;
        let ranges = law_ranges(law).ok_or(EncodeError::UnknownLaw { law })?;
        if self.values.len() != ranges.len() {
            return Err(EncodeError::Count {
                expected: ranges.len() as u8,
                got: self.values.len() as u8,
            });
        }
        let len = self.wire_len();
        if out.len() < len {
            return Err(EncodeError::BufferTooSmall { needed: len });
        }
        let o = self.overrides;
        if law == IDLE_LAW && o != Overrides::default() {
            return Err(EncodeError::BadOption);
        }
        let neighbours = match o.neighbours {
            None => 0,
            Some(Neighbours::All) => NEIGHBOURS_ALL,
            Some(Neighbours::None) => NEIGHBOURS_NONE,
            Some(Neighbours::Nearest(k)) if (1..=MAX_NEAREST).contains(&k) => k,
            Some(Neighbours::Nearest(_)) => return Err(EncodeError::BadOption),
        };
        if o.arrival_units == Some(0) {
            return Err(EncodeError::BadOption);
        }
        let header = [
            law,
            o.reverse.map_or(0, |r| r as u8),
            o.arrival_units.unwrap_or(0),
            neighbours,
        ];
        for (d, b) in out.iter_mut().zip(header) {
            *d = b;
        }
        let mut at = HEADER_LEN;
        for (i, (v, r)) in self.values.as_slice().iter().zip(ranges).enumerate() {
            if !r.contains(i64::from(*v)) {
                return Err(EncodeError::FieldOutOfRange { param: i as u8 });
            }
            let w = r.wire_len();
            // In range, so `v - min` fits the width.
            put_le(out, at, v.wrapping_sub(r.min) as u32, w);
            at += w;
        }
        Ok(len)
    }

    /// Parses the wire form (untrusted input: never panics).
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let [law, reverse, arrival, neighbours, ref rest @ ..] = *bytes else {
            return Err(DecodeError::Length {
                expected: HEADER_LEN,
                got: bytes.len(),
            });
        };
        let ranges = law_ranges(law).ok_or(DecodeError::UnknownLaw { law })?;
        let need = params_len(ranges);
        if rest.len() != need {
            return Err(DecodeError::Length {
                expected: HEADER_LEN + need,
                got: bytes.len(),
            });
        }
        if law == IDLE_LAW && (reverse | arrival | neighbours) != 0 {
            return Err(DecodeError::BadOption { offset: 1 });
        }
        let reverse = match reverse {
            0 => None,
            v => Some(Reverse::from_u8(v).ok_or(DecodeError::BadOption { offset: 1 })?),
        };
        let neighbours = match neighbours {
            0 => None,
            NEIGHBOURS_ALL => Some(Neighbours::All),
            NEIGHBOURS_NONE => Some(Neighbours::None),
            k if k <= MAX_NEAREST => Some(Neighbours::Nearest(k)),
            _ => return Err(DecodeError::BadOption { offset: 3 }),
        };
        let mut v = [0i32; MAX_PARAMS];
        let mut at = 0;
        for (i, (r, slot)) in ranges.iter().zip(&mut v).enumerate() {
            let w = r.wire_len();
            let raw = get_le(rest, at, w);
            if raw > r.span() {
                return Err(DecodeError::FieldOutOfRange { param: i as u8 });
            }
            *slot = r.min.wrapping_add(raw as i32);
            at += w;
        }
        let n = ranges.len();
        Ok(ManeuverParams {
            law,
            overrides: Overrides {
                reverse,
                arrival_units: (arrival != 0).then_some(arrival),
                neighbours,
            },
            values: Values::from_slice(v.get(..n).unwrap_or(&[])).unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests;
