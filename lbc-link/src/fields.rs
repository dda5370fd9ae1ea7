//! Typed message fields with range checks (seed 3.4, 3.5; units from the project docs).
//!
//! Units: coordinates in tracking units (1 unit = 2.5 mm, X 0..=640, Y 0..=960);
//! heading and yaw in milliradians 0..=6283 counter-clockwise from +X; steering in
//! signed milliradians, positive left, limited to +/-523 (30 degrees); velocity in
//! signed mm/s. Signed 14-bit fields are two's complement in 14 bits.

/// Which field a range error is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[non_exhaustive]
pub enum Field {
    X,
    Y,
    SteeringAngle,
    Velocity,
    Heading,
    VehicleId,
    EepromAddress,
    UserRegister,
    EepromValue,
    ParamNumber,
    ParamValue,
    StreamFormat,
    Pattern,
    Duty,
    Unsigned14,
    Signed14,
    Signed28,
    ChipTemperature,
}

/// A value outside the range of its field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct RangeError {
    /// The field.
    pub field: Field,
    /// The rejected value.
    pub value: i64,
}

macro_rules! ranged {
    ($(#[$doc:meta])* $name:ident($inner:ty), $min:expr, $max:expr, $field:expr) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        #[cfg_attr(feature = "serde", derive(serde::Serialize))]
        #[cfg_attr(feature = "serde", serde(transparent))]
        pub struct $name($inner);

        impl $name {
            /// Smallest valid value.
            pub const MIN: $inner = $min;
            /// Largest valid value.
            pub const MAX: $inner = $max;

            /// Checks the range.
            #[allow(unused_comparisons, clippy::manual_range_contains)]
            pub const fn new(value: $inner) -> Result<Self, RangeError> {
                if value < Self::MIN || value > Self::MAX {
                    return Err(RangeError { field: $field, value: value as i64 });
                }
                Ok(Self(value))
            }

            /// Checks the range of a wider value.
            #[allow(clippy::cast_lossless)]
            pub fn try_from_i64(value: i64) -> Result<Self, RangeError> {
                if value < Self::MIN as i64 || value > Self::MAX as i64 {
                    return Err(RangeError { field: $field, value });
                }
                Ok(Self(value as $inner))
            }

            /// The plain value.
            #[must_use]
            pub const fn get(self) -> $inner {
                self.0
            }
        }

        impl TryFrom<$inner> for $name {
            type Error = RangeError;
            fn try_from(value: $inner) -> Result<Self, RangeError> {
                Self::new(value)
            }
        }

        impl From<$name> for $inner {
            fn from(v: $name) -> $inner {
                v.0
            }
        }
    };
}

ranged!(
    /// X coordinate in tracking units (2.5 mm); 0..=640 (the arena spans 0..=600).
    XCoord(u16), 0, 640, Field::X
);
ranged!(
    /// Y coordinate in tracking units (2.5 mm); 0..=960 (the arena spans 0..=800).
    YCoord(u16), 0, 960, Field::Y
);
ranged!(
    /// Steering angle in milliradians, positive left; mechanical limit +/-30 degrees.
    SteeringAngle(i16), -523, 523, Field::SteeringAngle
);
ranged!(
    /// Velocity in mm/s, the full signed 14-bit range.
    Velocity(i16), -8192, 8191, Field::Velocity
);
ranged!(
    /// Heading or yaw in milliradians 0..=6283, counter-clockwise from +X.
    Heading(u16), 0, 6283, Field::Heading
);
ranged!(
    /// Vehicle ID as reported by READ_ID (7 bits).
    VehicleId(u8), 0, 127, Field::VehicleId
);
ranged!(
    /// Any of the 64 EEPROM registers (Table 1-3).
    EepromAddress(u8), 0, 0x3F, Field::EepromAddress
);
ranged!(
    /// An EEPROM user register, 0x20..=0x3F: the only ones WRIT_EP may write.
    UserRegister(u8), 0x20, 0x3F, Field::UserRegister
);
ranged!(
    /// An unsigned 14-bit reading (ADC values, user variables).
    U14(u16), 0, 0x3FFF, Field::Unsigned14
);
ranged!(
    /// A signed 14-bit value (two's complement on the wire).
    I14(i16), -8192, 8191, Field::Signed14
);
ranged!(
    /// A signed 28-bit value (two's complement on the wire).
    I28(i32), -(1 << 27), (1 << 27) - 1, Field::Signed28
);
ranged!(
    /// Chip temperature, 7 bits (assumed degrees Celsius).
    ChipTemperature(u8), 0, 127, Field::ChipTemperature
);

impl I14 {
    /// From 14-bit two's complement; every pattern is valid.
    #[must_use]
    pub const fn from_bits(raw: u32) -> Self {
        I14(crate::pack::sign_extend(raw & 0x3FFF, 14) as i16)
    }
}

impl From<UserRegister> for EepromAddress {
    fn from(r: UserRegister) -> Self {
        EepromAddress(r.0)
    }
}

impl EepromAddress {
    /// True for user registers 0x20..=0x3F.
    #[must_use]
    pub const fn is_user(self) -> bool {
        self.0 >= 0x20
    }
}

/// A position in tracking units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Position {
    pub x: XCoord,
    pub y: YCoord,
}

impl Position {
    /// Checks both coordinates.
    pub const fn new(x: u16, y: u16) -> Result<Self, RangeError> {
        let x = match XCoord::new(x) {
            Ok(v) => v,
            Err(e) => return Err(e),
        };
        let y = match YCoord::new(y) {
            Ok(v) => v,
            Err(e) => return Err(e),
        };
        Ok(Self { x, y })
    }
}

/// Steering angle and velocity, as in MOVE_SV and READ_SV.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SteerVelocity {
    pub steering: SteeringAngle,
    pub velocity: Velocity,
}

/// Duty cycle of an LED or GPIO pattern, in tenths (0 = off, 10 = always on).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Duty(u8);

impl Duty {
    /// Constant low.
    pub const OFF: Duty = Duty(0);
    /// Constant high.
    pub const ON: Duty = Duty(10);

    /// `tenths` must be 0..=10.
    pub const fn new(tenths: u8) -> Result<Self, RangeError> {
        if tenths > 10 {
            return Err(RangeError {
                field: Field::Duty,
                value: tenths as i64,
            });
        }
        Ok(Duty(tenths))
    }

    /// Duty cycle in tenths.
    #[must_use]
    pub const fn tenths(self) -> u8 {
        self.0
    }
}

/// Mode and frequency of an LED pattern (Table 3-5, bits 6..4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[repr(u8)]
pub enum LedRate {
    Blink1Hz = 0,
    Blink2Hz = 1,
    Blink5Hz = 2,
    Blink10Hz = 3,
    Blink20Hz = 4,
    Blink30Hz = 5,
    Dim50Hz = 6,
    Dim100Hz = 7,
}

/// Frequency of a GPIO pattern (Table 3-6, bits 6..4).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[repr(u8)]
pub enum GpioRate {
    Hz1 = 0,
    Hz2 = 1,
    Hz5 = 2,
    Hz10 = 3,
    Hz20 = 4,
    Hz30 = 5,
    Hz50 = 6,
    Hz100 = 7,
}

const RATE_HZ: [u8; 8] = [1, 2, 5, 10, 20, 30, 50, 100];

impl LedRate {
    const ALL: [LedRate; 8] = [
        LedRate::Blink1Hz,
        LedRate::Blink2Hz,
        LedRate::Blink5Hz,
        LedRate::Blink10Hz,
        LedRate::Blink20Hz,
        LedRate::Blink30Hz,
        LedRate::Dim50Hz,
        LedRate::Dim100Hz,
    ];

    /// Frequency in Hz.
    #[must_use]
    pub const fn hz(self) -> u8 {
        RATE_HZ[self as usize]
    }

    /// DIM mode (fast PWM for brightness) rather than BLINK.
    #[must_use]
    pub const fn is_dim(self) -> bool {
        matches!(self, LedRate::Dim50Hz | LedRate::Dim100Hz)
    }
}

impl GpioRate {
    const ALL: [GpioRate; 8] = [
        GpioRate::Hz1,
        GpioRate::Hz2,
        GpioRate::Hz5,
        GpioRate::Hz10,
        GpioRate::Hz20,
        GpioRate::Hz30,
        GpioRate::Hz50,
        GpioRate::Hz100,
    ];

    /// Frequency in Hz.
    #[must_use]
    pub const fn hz(self) -> u8 {
        RATE_HZ[self as usize]
    }
}

macro_rules! pattern {
    ($(#[$doc:meta])* $name:ident, $rate:ident) => {
        $(#[$doc])*
        ///
        /// The raw 7-bit code is kept, so codes 11..=15 in the duty bits (which
        /// the LBC treats as 0, constant low) survive a decode/encode round trip.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        #[cfg_attr(feature = "serde", derive(serde::Serialize))]
        #[cfg_attr(feature = "serde", serde(transparent))]
        pub struct $name(u8);

        impl $name {
            /// Pattern from rate and duty.
            #[must_use]
            pub const fn new(rate: $rate, duty: Duty) -> Self {
                Self(((rate as u8) << 4) | duty.0)
            }

            /// Pattern from its 7-bit code.
            pub const fn from_bits(code: u8) -> Result<Self, RangeError> {
                if code > 0x7F {
                    return Err(RangeError { field: Field::Pattern, value: code as i64 });
                }
                Ok(Self(code))
            }

            /// The 7-bit code.
            #[must_use]
            pub const fn bits(self) -> u8 {
                self.0
            }

            /// Bits 6..4.
            #[must_use]
            pub const fn rate(self) -> $rate {
                $rate::ALL[((self.0 >> 4) & 7) as usize]
            }

            /// Bits 3..0 as a duty cycle; 11..=15 mean constant low.
            #[must_use]
            pub const fn duty(self) -> Duty {
                let d = self.0 & 0x0F;
                if d > 10 {
                    Duty::OFF
                } else {
                    Duty(d)
                }
            }
        }
    };
}

pattern!(
    /// A WRIT_LED pattern: rate/mode in bits 6..4, duty in bits 3..0 (Table 3-5).
    LedPattern,
    LedRate
);
pattern!(
    /// A WRIT_GPO pattern: frequency in bits 6..4, duty in bits 3..0 (Table 3-6).
    GpioPattern,
    GpioRate
);

/// A control parameter of Table 3-3; the number is its wire value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[repr(u8)]
pub enum Param {
    MotorEncoderRatio = 1,
    MotorGearRatio = 2,
    MotorPGain = 3,
    MotorIGain = 4,
    MotorDGain = 5,
    MotorDeadBand = 6,
    ServoOffset = 7,
    ServoGain = 8,
    ServoPGain = 9,
    ServoIGain = 10,
    ServoDGain = 11,
    ServoDeadBand = 12,
}

impl Param {
    /// All parameters in number order.
    pub const ALL: [Param; 12] = [
        Param::MotorEncoderRatio,
        Param::MotorGearRatio,
        Param::MotorPGain,
        Param::MotorIGain,
        Param::MotorDGain,
        Param::MotorDeadBand,
        Param::ServoOffset,
        Param::ServoGain,
        Param::ServoPGain,
        Param::ServoIGain,
        Param::ServoDGain,
        Param::ServoDeadBand,
    ];

    /// Every parameter is 14 bits wide on the wire.
    pub const WIDTH: u8 = 14;

    /// The parameter with wire number `n` (1..=12).
    pub const fn from_number(n: u8) -> Result<Self, RangeError> {
        if n >= 1 && n <= 12 {
            Ok(Self::ALL[(n - 1) as usize])
        } else {
            Err(RangeError {
                field: Field::ParamNumber,
                value: n as i64,
            })
        }
    }

    /// Wire number.
    #[must_use]
    pub const fn number(self) -> u8 {
        self as u8
    }

    /// Signed parameters (S in Table 3-3).
    #[must_use]
    pub const fn is_signed(self) -> bool {
        matches!(self, Param::ServoOffset | Param::ServoGain)
    }

    /// The EEPROM register that stores the parameter (Table 1-3: RegMERR 0x04 .. RegSDB 0x0F).
    #[must_use]
    pub const fn eeprom_address(self) -> EepromAddress {
        EepromAddress(self as u8 + 3)
    }

    /// Table 3-3 name.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Param::MotorEncoderRatio => "Motor Encoder Ratio",
            Param::MotorGearRatio => "Motor Gear Ratio",
            Param::MotorPGain => "Motor PGain",
            Param::MotorIGain => "Motor IGain",
            Param::MotorDGain => "Motor DGain",
            Param::MotorDeadBand => "Motor Dead Band",
            Param::ServoOffset => "Servo Offset",
            Param::ServoGain => "Servo Gain",
            Param::ServoPGain => "Servo PGain",
            Param::ServoIGain => "Servo IGain",
            Param::ServoDGain => "Servo DGain",
            Param::ServoDeadBand => "Servo Dead Band",
        }
    }

    /// Range of the parameter's value.
    #[must_use]
    pub const fn range(self) -> (i16, i16) {
        if self.is_signed() {
            (-8192, 8191)
        } else {
            (0, 16383)
        }
    }
}

/// A parameter with a value in its range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ParamValue {
    param: Param,
    value: i16,
}

impl ParamValue {
    /// Checks the value against the parameter's signedness and width.
    pub const fn new(param: Param, value: i16) -> Result<Self, RangeError> {
        let (min, max) = param.range();
        if value < min || value > max {
            return Err(RangeError {
                field: Field::ParamValue,
                value: value as i64,
            });
        }
        Ok(Self { param, value })
    }

    /// The parameter.
    #[must_use]
    pub const fn param(self) -> Param {
        self.param
    }

    /// The value.
    #[must_use]
    pub const fn value(self) -> i16 {
        self.value
    }

    pub(crate) const fn raw(self) -> u32 {
        (self.value as u16 as u32) & 0x3FFF
    }

    pub(crate) const fn from_raw(param: Param, raw: u32) -> Self {
        let value = if param.is_signed() {
            crate::pack::sign_extend(raw, 14) as i16
        } else {
            (raw & 0x3FFF) as i16
        };
        Self { param, value }
    }
}

/// READ_BT reply: the two warning bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Warnings {
    /// Battery below the threshold (about 4.5 V).
    pub battery_low: bool,
    /// Chip above 65 degrees Celsius.
    pub over_temperature: bool,
}

/// Stream variable 15: chip temperature in the upper 7 bits, battery-low in bit 1,
/// over-temperature in bit 0; bits 6..2 are zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct ChipStatus {
    pub temperature: ChipTemperature,
    pub warnings: Warnings,
}

impl ChipStatus {
    /// The 14-bit wire form.
    #[must_use]
    pub const fn to_bits(self) -> u16 {
        ((self.temperature.0 as u16) << 7)
            | ((self.warnings.battery_low as u16) << 1)
            | self.warnings.over_temperature as u16
    }

    /// From the 14-bit wire form; the five middle bits are ignored.
    #[must_use]
    pub const fn from_bits(bits: u16) -> Self {
        Self {
            temperature: ChipTemperature(((bits >> 7) & 0x7F) as u8),
            warnings: Warnings {
                battery_low: bits & 0b10 != 0,
                over_temperature: bits & 1 != 0,
            },
        }
    }
}

/// CALB_ST reply: steering offset and gain (signed, as Servo Offset/Gain in Table 3-3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct SteeringCalibration {
    pub offset: I14,
    pub gain: I14,
}

/// CALB_GS reply: gyro offsets; `yaw` is absent in the 28-bit form of Table 3-2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct GyroOffsets {
    pub pitch: I14,
    pub roll: I14,
    pub yaw: Option<I14>,
}

/// READ_PRY reply: raw gyro readings minus the reference voltage reading (ADC counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct GyroRaw {
    pub pitch: I14,
    pub roll: I14,
    pub yaw: I14,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_checked() {
        assert!(XCoord::new(640).is_ok());
        assert_eq!(
            XCoord::new(641),
            Err(RangeError {
                field: Field::X,
                value: 641
            })
        );
        assert!(YCoord::new(961).is_err());
        assert!(SteeringAngle::new(-524).is_err());
        assert!(Heading::new(6284).is_err());
        assert!(UserRegister::new(0x1F).is_err());
        assert!(EepromAddress::new(0x40).is_err());
        assert!(Duty::new(11).is_err());
    }

    #[test]
    fn led_pattern_bits() {
        let p = LedPattern::new(LedRate::Blink5Hz, Duty::new(5).unwrap());
        assert_eq!(p.bits(), 0x25);
        assert_eq!(p.rate().hz(), 5);
        let off = LedPattern::from_bits(0x7C).unwrap();
        assert_eq!(off.rate(), LedRate::Dim100Hz);
        assert_eq!(off.duty(), Duty::OFF);
        assert_eq!(off.bits(), 0x7C);
        assert!(LedPattern::from_bits(0x80).is_err());
        assert_eq!(GpioPattern::from_bits(0x3A).unwrap().rate(), GpioRate::Hz10);
    }

    #[test]
    fn params_follow_table_3_3() {
        assert!(Param::ServoOffset.is_signed());
        assert!(!Param::ServoPGain.is_signed());
        assert_eq!(Param::from_number(12).unwrap(), Param::ServoDeadBand);
        assert!(Param::from_number(0).is_err());
        assert!(Param::from_number(13).is_err());
        assert_eq!(Param::MotorEncoderRatio.eeprom_address().get(), 0x04);
        assert_eq!(Param::ServoDeadBand.eeprom_address().get(), 0x0F);
        assert!(ParamValue::new(Param::MotorPGain, -1).is_err());
        assert!(ParamValue::new(Param::ServoGain, -1).is_ok());
        let v = ParamValue::new(Param::ServoOffset, -5).unwrap();
        assert_eq!(ParamValue::from_raw(Param::ServoOffset, v.raw()), v);
    }

    #[test]
    fn chip_status_packing() {
        let s = ChipStatus {
            temperature: ChipTemperature::new(40).unwrap(),
            warnings: Warnings {
                battery_low: true,
                over_temperature: false,
            },
        };
        assert_eq!(s.to_bits(), (40 << 7) | 0b10);
        assert_eq!(ChipStatus::from_bits(s.to_bits() | 0b1111100), s);
    }
}
