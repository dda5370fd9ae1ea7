//! Radio addresses: car IDs (the LBC's READ_ID value), the ground station and broadcast.
//!
//! One address byte on air: `0x00` ground station, `0x01..=0x7E` cars, `0x7F` broadcast.
//! Values with bit 7 set are invalid, so a byte from a foreign protocol is rejected early.

use crate::wire::FrameError;

/// A car's 7-bit ID as stored in EEPROM register 0x00 and reported by READ_ID; 1..=126.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarId(u8);

impl CarId {
    /// Lowest usable car ID.
    pub const MIN: u8 = 1;
    /// Highest usable car ID (0 and 127 are the ground station and broadcast).
    pub const MAX: u8 = 126;

    /// A car ID, or `None` outside 1..=126.
    pub const fn new(id: u8) -> Option<Self> {
        if id >= Self::MIN && id <= Self::MAX {
            Some(Self(id))
        } else {
            None
        }
    }

    /// The raw ID.
    pub const fn get(self) -> u8 {
        self.0
    }
}

/// Source or destination of a radio frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Address {
    /// The user's ground station.
    Ground,
    /// One car.
    Car(CarId),
    /// Every node in range (destination only).
    Broadcast,
}

impl Address {
    /// Wire value of the ground station.
    pub const GROUND: u8 = 0x00;
    /// Wire value of broadcast.
    pub const BROADCAST: u8 = 0x7F;

    /// Decode one address byte.
    pub fn from_byte(value: u8) -> Result<Self, FrameError> {
        match value {
            Self::GROUND => Ok(Address::Ground),
            Self::BROADCAST => Ok(Address::Broadcast),
            v => CarId::new(v)
                .map(Address::Car)
                .ok_or(FrameError::InvalidAddress { value }),
        }
    }

    /// Encode as one byte.
    pub const fn to_byte(self) -> u8 {
        match self {
            Address::Ground => Self::GROUND,
            Address::Car(id) => id.get(),
            Address::Broadcast => Self::BROADCAST,
        }
    }
}

impl From<CarId> for Address {
    fn from(id: CarId) -> Self {
        Address::Car(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_byte_decodes_or_errors() {
        for b in 0..=255u8 {
            match Address::from_byte(b) {
                Ok(a) => assert_eq!(a.to_byte(), b),
                Err(e) => {
                    assert!(b >= 0x80);
                    assert_eq!(e, FrameError::InvalidAddress { value: b });
                }
            }
        }
    }

    #[test]
    fn car_id_range() {
        assert!(CarId::new(0).is_none());
        assert!(CarId::new(127).is_none());
        assert_eq!(CarId::new(1).map(CarId::get), Some(1));
        assert_eq!(CarId::new(126).map(CarId::get), Some(126));
    }
}
