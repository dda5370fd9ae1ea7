//! Maneuver parameters and their 6-byte wire form.
//!
//! Six bytes is the widest field block of a radio group message, so a whole maneuver (law and
//! parameters) can be announced in one frame. The bytes hold a little-endian 48-bit word; the
//! low 3 bits select the law and the fields follow in the order of the table in
//! `docs/maneuvers.md`. Unused high bits must be zero, so decoding is canonical: whatever
//! decodes re-encodes to the same bytes.

use crate::formation::Shape;

/// Length of an encoded [`ManeuverParams`].
pub const PARAMS_LEN: usize = 6;

/// Slot value on the wire meaning "take the slot from my rank among the followers".
const SLOT_AUTO: u64 = 15;

/// A law and its parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ManeuverParams {
    /// No maneuver: the car stops.
    #[default]
    Idle,
    /// Leader-follower formation.
    Formation {
        /// Line or wedge.
        shape: Shape,
        /// Leader's car ID, 1..=126.
        leader: u8,
        /// Slot index 0..=14, or `None` to use the rank of this car's ID among the followers.
        slot: Option<u8>,
        /// Distance between neighbouring slots, tracking units, 1..=511.
        spacing_units: u16,
        /// Leader's cruise speed towards its waypoint, mm/s, 0..=2047.
        speed_mm_s: u16,
    },
    /// Rendezvous by consensus on the mean position.
    Rendezvous {
        /// Arrival radius around the consensus point, tracking units, 1..=511.
        radius_units: u16,
        /// Maximum speed, mm/s, 0..=2047.
        speed_mm_s: u16,
    },
    /// Even spacing on a circle, rotating.
    Circle {
        /// Centre X, tracking units, 0..=1023.
        cx: u16,
        /// Centre Y, tracking units, 0..=1023.
        cy: u16,
        /// Radius, tracking units, 1..=511.
        radius_units: u16,
        /// Speed along the circle, mm/s, -2048..=2047; positive is counter-clockwise.
        speed_mm_s: i16,
    },
    /// Drive to a point and stop.
    GoTo {
        /// Target X, tracking units, 0..=1023.
        x: u16,
        /// Target Y, tracking units, 0..=1023.
        y: u16,
        /// Maximum speed, mm/s, 0..=2047.
        speed_mm_s: u16,
    },
    /// Follow the car carrying a marker seen by the camera. The camera part of the program
    /// drives the car; the [`crate::Controller`] itself holds still for this law.
    CameraFollow {
        /// Vision colour class index of the leader's marker, 0..=255.
        marker: u8,
        /// Distance to keep behind the leader, tracking units, 1..=511.
        distance_units: u16,
        /// Maximum speed, mm/s, 0..=2047.
        speed_mm_s: u16,
    },
}

/// A parameter field, named in errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamField {
    /// Formation leader ID.
    Leader,
    /// Formation slot.
    Slot,
    /// Formation spacing.
    Spacing,
    /// A radius.
    Radius,
    /// A speed.
    Speed,
    /// An X coordinate.
    X,
    /// A Y coordinate.
    Y,
    /// Camera-follow distance.
    Distance,
    /// Camera-follow marker class.
    Marker,
}

/// Why parameters cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The field's value does not fit its wire width or is not allowed.
    FieldOutOfRange {
        /// Which field.
        field: ParamField,
    },
}

/// Why bytes do not decode into parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// Not [`PARAMS_LEN`] bytes.
    Length {
        /// Required length.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// The law selector is not one this crate knows.
    UnknownKind {
        /// The selector value.
        kind: u8,
    },
    /// Bits above the law's fields are not zero.
    ReservedBitsSet,
    /// A field holds a value the law does not accept (a zero radius or spacing, leader 0 or 127).
    FieldOutOfRange {
        /// Which field.
        field: ParamField,
    },
}

const KIND_IDLE: u64 = 0;
const KIND_FORMATION: u64 = 1;
const KIND_RENDEZVOUS: u64 = 2;
const KIND_CIRCLE: u64 = 3;
const KIND_GOTO: u64 = 4;
const KIND_CAMERA_FOLLOW: u64 = 5;

/// Packs fields LSB first into a 48-bit word.
struct Packer {
    word: u64,
    bit: u32,
}

impl Packer {
    fn new(kind: u64) -> Self {
        Self { word: kind, bit: 3 }
    }

    fn put(mut self, value: u64, width: u32, field: ParamField) -> Result<Self, EncodeError> {
        if value >> width != 0 {
            return Err(EncodeError::FieldOutOfRange { field });
        }
        self.word |= value << self.bit;
        self.bit += width;
        Ok(self)
    }

    fn put_signed(self, value: i64, width: u32, field: ParamField) -> Result<Self, EncodeError> {
        let half = 1i64 << (width - 1);
        if value < -half || value >= half {
            return Err(EncodeError::FieldOutOfRange { field });
        }
        let mask = (1u64 << width) - 1;
        // Two's complement truncated to `width` bits.
        self.put((value as u64) & mask, width, field)
    }
}

/// Reads fields back in the same order.
struct Unpacker {
    word: u64,
    bit: u32,
}

impl Unpacker {
    fn take(&mut self, width: u32) -> u64 {
        let v = (self.word >> self.bit) & ((1u64 << width) - 1);
        self.bit += width;
        v
    }

    fn take_signed(&mut self, width: u32) -> i64 {
        let v = self.take(width) as i64;
        if v >= 1 << (width - 1) {
            v - (1 << width)
        } else {
            v
        }
    }

    fn finish(self) -> Result<(), DecodeError> {
        if self.word >> self.bit != 0 {
            Err(DecodeError::ReservedBitsSet)
        } else {
            Ok(())
        }
    }
}

fn check(ok: bool, field: ParamField) -> Result<(), ParamField> {
    if ok {
        Ok(())
    } else {
        Err(field)
    }
}

impl ManeuverParams {
    /// Semantic checks shared by encode and decode.
    fn validate(&self) -> Result<(), ParamField> {
        match *self {
            ManeuverParams::Idle => Ok(()),
            ManeuverParams::Formation {
                leader,
                slot,
                spacing_units,
                ..
            } => {
                check((1..=126).contains(&leader), ParamField::Leader)?;
                check(
                    slot.is_none_or(|s| u64::from(s) < SLOT_AUTO),
                    ParamField::Slot,
                )?;
                check(spacing_units >= 1, ParamField::Spacing)
            }
            ManeuverParams::Rendezvous { radius_units, .. }
            | ManeuverParams::Circle { radius_units, .. } => {
                check(radius_units >= 1, ParamField::Radius)
            }
            ManeuverParams::GoTo { .. } => Ok(()),
            ManeuverParams::CameraFollow { distance_units, .. } => {
                check(distance_units >= 1, ParamField::Distance)
            }
        }
    }

    /// The law selector of the wire form (the low 3 bits): 0 idle, 1 formation,
    /// 2 rendezvous, 3 circle, 4 go-to, 5 camera follow.
    pub const fn kind(&self) -> u8 {
        (match self {
            ManeuverParams::Idle => KIND_IDLE,
            ManeuverParams::Formation { .. } => KIND_FORMATION,
            ManeuverParams::Rendezvous { .. } => KIND_RENDEZVOUS,
            ManeuverParams::Circle { .. } => KIND_CIRCLE,
            ManeuverParams::GoTo { .. } => KIND_GOTO,
            ManeuverParams::CameraFollow { .. } => KIND_CAMERA_FOLLOW,
        }) as u8
    }

    /// The 6-byte wire form.
    pub fn encode(&self) -> Result<[u8; PARAMS_LEN], EncodeError> {
        self.validate()
            .map_err(|field| EncodeError::FieldOutOfRange { field })?;
        let p = match *self {
            ManeuverParams::Idle => Packer::new(KIND_IDLE),
            ManeuverParams::Formation {
                shape,
                leader,
                slot,
                spacing_units,
                speed_mm_s,
            } => Packer::new(KIND_FORMATION)
                .put(shape as u64, 1, ParamField::Slot)?
                .put(slot.map_or(SLOT_AUTO, u64::from), 4, ParamField::Slot)?
                .put(u64::from(leader), 7, ParamField::Leader)?
                .put(u64::from(spacing_units), 9, ParamField::Spacing)?
                .put(u64::from(speed_mm_s), 11, ParamField::Speed)?,
            ManeuverParams::Rendezvous {
                radius_units,
                speed_mm_s,
            } => Packer::new(KIND_RENDEZVOUS)
                .put(u64::from(radius_units), 9, ParamField::Radius)?
                .put(u64::from(speed_mm_s), 11, ParamField::Speed)?,
            ManeuverParams::Circle {
                cx,
                cy,
                radius_units,
                speed_mm_s,
            } => Packer::new(KIND_CIRCLE)
                .put(u64::from(cx), 10, ParamField::X)?
                .put(u64::from(cy), 10, ParamField::Y)?
                .put(u64::from(radius_units), 9, ParamField::Radius)?
                .put_signed(i64::from(speed_mm_s), 12, ParamField::Speed)?,
            ManeuverParams::GoTo { x, y, speed_mm_s } => Packer::new(KIND_GOTO)
                .put(u64::from(x), 10, ParamField::X)?
                .put(u64::from(y), 10, ParamField::Y)?
                .put(u64::from(speed_mm_s), 11, ParamField::Speed)?,
            ManeuverParams::CameraFollow {
                marker,
                distance_units,
                speed_mm_s,
            } => Packer::new(KIND_CAMERA_FOLLOW)
                .put(u64::from(marker), 8, ParamField::Marker)?
                .put(u64::from(distance_units), 9, ParamField::Distance)?
                .put(u64::from(speed_mm_s), 11, ParamField::Speed)?,
        };
        let b = p.word.to_le_bytes();
        let mut out = [0u8; PARAMS_LEN];
        out.copy_from_slice(&b[..PARAMS_LEN]);
        Ok(out)
    }

    /// Parse the 6-byte wire form (untrusted input: never panics).
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        if bytes.len() != PARAMS_LEN {
            return Err(DecodeError::Length {
                expected: PARAMS_LEN,
                got: bytes.len(),
            });
        }
        let mut b = [0u8; 8];
        b[..PARAMS_LEN].copy_from_slice(bytes);
        let mut u = Unpacker {
            word: u64::from_le_bytes(b),
            bit: 3,
        };
        let kind = u.word & 0b111;
        // Every `take(n)` below is at most 11 bits, so the narrowing casts are lossless.
        let params = match kind {
            KIND_IDLE => ManeuverParams::Idle,
            KIND_FORMATION => {
                let shape = if u.take(1) == 0 {
                    Shape::Line
                } else {
                    Shape::Wedge
                };
                let slot = u.take(4);
                let leader = u.take(7) as u8;
                ManeuverParams::Formation {
                    shape,
                    leader,
                    slot: (slot != SLOT_AUTO).then_some(slot as u8),
                    spacing_units: u.take(9) as u16,
                    speed_mm_s: u.take(11) as u16,
                }
            }
            KIND_RENDEZVOUS => ManeuverParams::Rendezvous {
                radius_units: u.take(9) as u16,
                speed_mm_s: u.take(11) as u16,
            },
            KIND_CIRCLE => ManeuverParams::Circle {
                cx: u.take(10) as u16,
                cy: u.take(10) as u16,
                radius_units: u.take(9) as u16,
                speed_mm_s: u.take_signed(12) as i16,
            },
            KIND_GOTO => ManeuverParams::GoTo {
                x: u.take(10) as u16,
                y: u.take(10) as u16,
                speed_mm_s: u.take(11) as u16,
            },
            KIND_CAMERA_FOLLOW => ManeuverParams::CameraFollow {
                marker: u.take(8) as u8,
                distance_units: u.take(9) as u16,
                speed_mm_s: u.take(11) as u16,
            },
            other => return Err(DecodeError::UnknownKind { kind: other as u8 }),
        };
        u.finish()?;
        params
            .validate()
            .map_err(|field| DecodeError::FieldOutOfRange { field })?;
        Ok(params)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn circle_bytes() {
        // kind 3 | cx 300 << 3 | cy 400 << 13 | r 150 << 23 | speed -200 (0xF38) << 32
        let p = ManeuverParams::Circle {
            cx: 300,
            cy: 400,
            radius_units: 150,
            speed_mm_s: -200,
        };
        let word: u64 = 3 | (300 << 3) | (400 << 13) | (150 << 23) | (0xF38 << 32);
        let expected = &word.to_le_bytes()[..6];
        assert_eq!(p.encode().unwrap(), expected);
        assert_eq!(p.encode().unwrap(), [0x63, 0x09, 0x32, 0x4B, 0x38, 0x0F]);
        assert_eq!(ManeuverParams::decode(expected), Ok(p));
    }

    #[test]
    fn formation_bytes() {
        let p = ManeuverParams::Formation {
            shape: Shape::Wedge,
            leader: 1,
            slot: None,
            spacing_units: 60,
            speed_mm_s: 100,
        };
        // kind 1 | wedge << 3 | auto slot 15 << 4 | leader 1 << 8 | 60 << 15 | 100 << 24
        assert_eq!(p.encode().unwrap(), [0xF9, 0x01, 0x1E, 0x64, 0x00, 0x00]);
    }

    #[test]
    fn camera_follow_bytes() {
        let p = ManeuverParams::CameraFollow {
            marker: 2,
            distance_units: 80,
            speed_mm_s: 150,
        };
        // kind 5 | marker 2 << 3 | distance 80 << 11 | speed 150 << 20
        let word: u64 = 5 | (2 << 3) | (80 << 11) | (150 << 20);
        assert_eq!(p.encode().unwrap(), &word.to_le_bytes()[..6]);
        assert_eq!(p.encode().unwrap(), [0x15, 0x80, 0x62, 0x09, 0x00, 0x00]);
        assert_eq!(ManeuverParams::decode(&word.to_le_bytes()[..6]), Ok(p));
        assert_eq!(p.kind(), 5);
        assert_eq!(
            ManeuverParams::CameraFollow {
                marker: 0,
                distance_units: 0,
                speed_mm_s: 0
            }
            .encode(),
            Err(EncodeError::FieldOutOfRange {
                field: ParamField::Distance
            })
        );
    }

    #[test]
    fn idle_is_all_zero() {
        assert_eq!(ManeuverParams::Idle.encode().unwrap(), [0; 6]);
        assert_eq!(ManeuverParams::decode(&[0; 6]), Ok(ManeuverParams::Idle));
    }

    #[test]
    fn bad_inputs_are_typed_errors() {
        assert_eq!(
            ManeuverParams::decode(&[0; 5]),
            Err(DecodeError::Length {
                expected: 6,
                got: 5
            })
        );
        assert_eq!(
            ManeuverParams::decode(&[6, 0, 0, 0, 0, 0]),
            Err(DecodeError::UnknownKind { kind: 6 })
        );
        assert_eq!(
            ManeuverParams::decode(&[0, 0, 0, 0, 0, 0x80]),
            Err(DecodeError::ReservedBitsSet)
        );
        // Rendezvous with radius 0.
        assert_eq!(
            ManeuverParams::decode(&[2, 0, 0, 0, 0, 0]),
            Err(DecodeError::FieldOutOfRange {
                field: ParamField::Radius
            })
        );
        assert_eq!(
            ManeuverParams::GoTo {
                x: 1024,
                y: 0,
                speed_mm_s: 0
            }
            .encode(),
            Err(EncodeError::FieldOutOfRange {
                field: ParamField::X
            })
        );
        assert_eq!(
            ManeuverParams::Circle {
                cx: 0,
                cy: 0,
                radius_units: 10,
                speed_mm_s: 2048
            }
            .encode(),
            Err(EncodeError::FieldOutOfRange {
                field: ParamField::Speed
            })
        );
    }

    fn any_params() -> impl Strategy<Value = ManeuverParams> {
        prop_oneof![
            Just(ManeuverParams::Idle),
            (
                any::<bool>(),
                1u8..=126,
                proptest::option::of(0u8..15),
                1u16..512,
                0u16..2048
            )
                .prop_map(|(w, leader, slot, spacing_units, speed_mm_s)| {
                    ManeuverParams::Formation {
                        shape: if w { Shape::Wedge } else { Shape::Line },
                        leader,
                        slot,
                        spacing_units,
                        speed_mm_s,
                    }
                }),
            (1u16..512, 0u16..2048).prop_map(|(radius_units, speed_mm_s)| {
                ManeuverParams::Rendezvous {
                    radius_units,
                    speed_mm_s,
                }
            }),
            (0u16..1024, 0u16..1024, 1u16..512, -2048i16..2048).prop_map(
                |(cx, cy, radius_units, speed_mm_s)| ManeuverParams::Circle {
                    cx,
                    cy,
                    radius_units,
                    speed_mm_s
                }
            ),
            (0u16..1024, 0u16..1024, 0u16..2048)
                .prop_map(|(x, y, speed_mm_s)| ManeuverParams::GoTo { x, y, speed_mm_s }),
            (any::<u8>(), 1u16..512, 0u16..2048).prop_map(
                |(marker, distance_units, speed_mm_s)| {
                    ManeuverParams::CameraFollow {
                        marker,
                        distance_units,
                        speed_mm_s,
                    }
                }
            ),
        ]
    }

    proptest! {
        #[test]
        fn encode_decode_round_trip(p in any_params()) {
            let bytes = p.encode().unwrap();
            prop_assert_eq!(ManeuverParams::decode(&bytes), Ok(p));
        }

        #[test]
        fn decode_is_canonical(bytes in proptest::array::uniform6(any::<u8>())) {
            if let Ok(p) = ManeuverParams::decode(&bytes) {
                prop_assert_eq!(p.encode(), Ok(bytes));
            }
        }

        #[test]
        fn decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..10)) {
            let _ = ManeuverParams::decode(&bytes);
        }
    }
}
