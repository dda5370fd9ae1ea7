//! Streaming format and STREAM data (seed 3.5.2, Table 3-4).
//!
//! Bit N of the 28-bit [`StreamFormat`] enables system variable N. A STREAM
//! message (header 0xFC) carries the enabled variables in ascending number order,
//! packed like any other data. Bits 5..7, 13, 14 and 21 are NOT IN USE (mask
//! 0x002060E0); a format with any of them set is invalid.
//!
//! Every variable is 14 or 28 bits wide, so STREAM data is a whole number of 14-bit units,
//! each exactly two 7-bit data bytes (high bits first) with no padding. Decoding reads
//! those byte pairs directly instead of going through the general bit reader: this is the
//! receive hot path of the UBC (see `docs/benchmarks.md`).

use crate::fields::{
    ChipStatus, Heading, Position, RangeError, SteerVelocity, SteeringAngle, Velocity, XCoord,
    YCoord, I14, I28, U14,
};
use crate::header::STREAM;
use crate::pack::{sign_extend, BitWriter};
use crate::wire::{emit_frame, pack_error, EncodeError};

/// Format bits that must never be set (NOT IN USE rows of Table 3-4).
pub const NOT_IN_USE_MASK: u32 = 0x0020_60E0;
/// Width of the format word.
pub const FORMAT_BITS: u8 = 28;
/// Format bits of the 28-bit variables (two 14-bit units each); the rest are 14 bits wide.
const WIDE_MASK: u32 = (1 << SystemVariable::Position as u32)
    | (1 << SystemVariable::SteerVelocity as u32)
    | (1 << SystemVariable::AdcGyroPitchRoll as u32)
    | (1 << SystemVariable::TargetPosition as u32)
    | (1 << SystemVariable::TargetSteerVelocity as u32)
    | (1 << SystemVariable::MotorPdError as u32)
    | (1 << SystemVariable::MotorIError as u32);
/// Bits of one unit on the wire.
const UNIT_BITS: usize = 14;

/// Which system variables a STREAM message carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[cfg_attr(feature = "serde", serde(transparent))]
pub struct StreamFormat(u32);

impl StreamFormat {
    /// No variables.
    pub const EMPTY: StreamFormat = StreamFormat(0);
    /// Every valid variable.
    pub const ALL: StreamFormat = StreamFormat(0x0FFF_FFFF & !NOT_IN_USE_MASK);

    /// Checks width (28 bits) and the NOT-IN-USE mask.
    pub const fn new(bits: u32) -> Result<Self, RangeError> {
        if bits >> FORMAT_BITS != 0 || bits & NOT_IN_USE_MASK != 0 {
            return Err(RangeError {
                field: crate::fields::Field::StreamFormat,
                value: bits as i64,
            });
        }
        Ok(Self(bits))
    }

    /// The format word.
    #[must_use]
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// True if `var` is enabled.
    #[must_use]
    pub const fn contains(self, var: SystemVariable) -> bool {
        self.0 & (1 << var as u32) != 0
    }

    /// This format with `var` enabled.
    #[must_use]
    pub const fn with(self, var: SystemVariable) -> Self {
        Self(self.0 | (1 << var as u32))
    }

    /// Enabled variables in stream order.
    pub fn variables(self) -> impl Iterator<Item = SystemVariable> {
        SystemVariable::ALL
            .iter()
            .copied()
            .filter(move |v| self.contains(*v))
    }

    /// Data bits of a STREAM message in this format.
    #[must_use]
    pub fn data_bits(self) -> usize {
        UNIT_BITS * self.units()
    }

    /// 14-bit units of a STREAM message in this format.
    const fn units(self) -> usize {
        (self.0.count_ones() + (self.0 & WIDE_MASK).count_ones()) as usize
    }

    /// Data bytes of a STREAM message in this format.
    #[must_use]
    pub fn data_len(self) -> usize {
        crate::pack::packed_len(self.data_bits())
    }
}

/// The system variables of Table 3-4; the discriminant is the variable number.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
#[repr(u8)]
pub enum SystemVariable {
    Id = 0,
    Position = 1,
    SteerVelocity = 2,
    AdjustedYaw = 3,
    Heading = 4,
    AdcSteering = 8,
    AdcRange = 9,
    AdcGyroReference = 10,
    AdcGyroPitchRoll = 11,
    AdcGyroYaw = 12,
    ChipStatus = 15,
    TargetPosition = 16,
    TargetSteerVelocity = 17,
    TargetYaw = 18,
    MotorPdError = 19,
    MotorIError = 20,
    User1 = 22,
    User2 = 23,
    User3 = 24,
    User4 = 25,
    User5 = 26,
    User6 = 27,
}

impl SystemVariable {
    /// All variables in stream order.
    pub const ALL: [SystemVariable; 22] = [
        SystemVariable::Id,
        SystemVariable::Position,
        SystemVariable::SteerVelocity,
        SystemVariable::AdjustedYaw,
        SystemVariable::Heading,
        SystemVariable::AdcSteering,
        SystemVariable::AdcRange,
        SystemVariable::AdcGyroReference,
        SystemVariable::AdcGyroPitchRoll,
        SystemVariable::AdcGyroYaw,
        SystemVariable::ChipStatus,
        SystemVariable::TargetPosition,
        SystemVariable::TargetSteerVelocity,
        SystemVariable::TargetYaw,
        SystemVariable::MotorPdError,
        SystemVariable::MotorIError,
        SystemVariable::User1,
        SystemVariable::User2,
        SystemVariable::User3,
        SystemVariable::User4,
        SystemVariable::User5,
        SystemVariable::User6,
    ];

    /// The variable with number `n`, if it is in use.
    #[must_use]
    pub const fn from_number(n: u8) -> Option<Self> {
        use SystemVariable as V;
        Some(match n {
            0 => V::Id,
            1 => V::Position,
            2 => V::SteerVelocity,
            3 => V::AdjustedYaw,
            4 => V::Heading,
            8 => V::AdcSteering,
            9 => V::AdcRange,
            10 => V::AdcGyroReference,
            11 => V::AdcGyroPitchRoll,
            12 => V::AdcGyroYaw,
            15 => V::ChipStatus,
            16 => V::TargetPosition,
            17 => V::TargetSteerVelocity,
            18 => V::TargetYaw,
            19 => V::MotorPdError,
            20 => V::MotorIError,
            22 => V::User1,
            23 => V::User2,
            24 => V::User3,
            25 => V::User4,
            26 => V::User5,
            27 => V::User6,
            _ => return None,
        })
    }

    /// Variable number (format bit).
    #[must_use]
    pub const fn number(self) -> u8 {
        self as u8
    }

    /// Width on the wire in bits.
    #[must_use]
    pub const fn width(self) -> u8 {
        match self {
            SystemVariable::Position
            | SystemVariable::SteerVelocity
            | SystemVariable::AdcGyroPitchRoll
            | SystemVariable::TargetPosition
            | SystemVariable::TargetSteerVelocity
            | SystemVariable::MotorPdError
            | SystemVariable::MotorIError => 28,
            _ => 14,
        }
    }

    /// Table 3-4 name.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            SystemVariable::Id => "ID",
            SystemVariable::Position => "X and Y coordinate",
            SystemVariable::SteerVelocity => "Steering Angle and Velocity",
            SystemVariable::AdjustedYaw => "Adjusted Yaw",
            SystemVariable::Heading => "Heading",
            SystemVariable::AdcSteering => "ADC Steering LP",
            SystemVariable::AdcRange => "ADC Range Sensor Reading",
            SystemVariable::AdcGyroReference => "ADC Gyro Reference Voltage",
            SystemVariable::AdcGyroPitchRoll => "ADC Raw Gyro Pitch and Roll",
            SystemVariable::AdcGyroYaw => "ADC Raw Gyro Yaw",
            SystemVariable::ChipStatus => "Chip Temperature and Warnings",
            SystemVariable::TargetPosition => "Target X and Y coordinate",
            SystemVariable::TargetSteerVelocity => "Target Steering Angle and Velocity",
            SystemVariable::TargetYaw => "Target Yaw",
            SystemVariable::MotorPdError => "Motor Proportional and Differential Errors",
            SystemVariable::MotorIError => "Motor Integral Error",
            SystemVariable::User1 => "User Variable 1",
            SystemVariable::User2 => "User Variable 2",
            SystemVariable::User3 => "User Variable 3",
            SystemVariable::User4 => "User Variable 4",
            SystemVariable::User5 => "User Variable 5",
            SystemVariable::User6 => "User Variable 6",
        }
    }
}

/// Why STREAM data could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum StreamError {
    /// The data length does not match the format.
    Length { expected: usize, got: usize },
    /// A variable is outside its range.
    Field(RangeError),
    /// No streaming format is known yet (the client has seen no UPD_SF/READ_SF).
    UnknownFormat,
}

impl From<RangeError> for StreamError {
    fn from(e: RangeError) -> Self {
        StreamError::Field(e)
    }
}

/// Reads STREAM data as 14-bit units: byte pairs, 7 data bits each, high bits first.
#[derive(Debug, Clone)]
struct Units<'a> {
    data: &'a [u8],
}

impl<'a> Units<'a> {
    /// Checks that `data` holds exactly the units of `format`.
    fn new(format: StreamFormat, data: &'a [u8]) -> Result<Self, StreamError> {
        let expected = 2 * format.units();
        if data.len() != expected {
            return Err(StreamError::Length {
                expected,
                got: data.len(),
            });
        }
        Ok(Self { data })
    }

    /// The next unit, unsigned. The length was checked against the format, so every read
    /// finds its unit: the `0` past the end is never returned.
    #[inline]
    fn unit(&mut self) -> u16 {
        match *self.data {
            [hi, lo, ref rest @ ..] => {
                self.data = rest;
                (u16::from(hi & 0x7F) << 7) | u16::from(lo & 0x7F)
            }
            _ => 0,
        }
    }

    /// The next unit as 14-bit two's complement.
    #[inline]
    fn signed(&mut self) -> i32 {
        sign_extend(u32::from(self.unit()), 14)
    }
}

/// One decoded stream variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum SystemValue {
    Id(U14),
    Position(Position),
    SteerVelocity(SteerVelocity),
    AdjustedYaw(Heading),
    Heading(Heading),
    AdcSteering(U14),
    AdcRange(U14),
    AdcGyroReference(U14),
    AdcGyroPitchRoll {
        pitch: I14,
        roll: I14,
    },
    AdcGyroYaw(I14),
    ChipStatus(ChipStatus),
    TargetPosition(Position),
    TargetSteerVelocity(SteerVelocity),
    TargetYaw(Heading),
    MotorPdError {
        proportional: I14,
        differential: I14,
    },
    MotorIError(I28),
    /// User variable 1..=6 (lower 14 bits of what the user points at).
    User {
        index: u8,
        value: U14,
    },
}

// `inline`: at the firmware's inlining threshold (33) the position reader would call it
// twice and save registers around the calls, 0.9 more instructions per received byte.
#[inline]
fn read_u14(r: &mut Units<'_>) -> u16 {
    r.unit()
}

fn read_unsigned(r: &mut Units<'_>) -> Result<U14, StreamError> {
    Ok(U14::new(r.unit())?)
}

fn read_heading(r: &mut Units<'_>) -> Result<Heading, StreamError> {
    Ok(Heading::new(r.unit())?)
}

fn read_i28(r: &mut Units<'_>) -> Result<I28, StreamError> {
    let high = u32::from(r.unit());
    let low = u32::from(r.unit());
    Ok(I28::try_from_i64(i64::from(sign_extend(
        (high << 14) | low,
        28,
    )))?)
}

fn read_i14(r: &mut Units<'_>) -> Result<I14, StreamError> {
    let v = r.signed();
    Ok(I14::try_from_i64(i64::from(v))?)
}

fn read_position(r: &mut Units<'_>) -> Result<Position, StreamError> {
    let x = XCoord::new(read_u14(r))?;
    let y = YCoord::new(read_u14(r))?;
    Ok(Position { x, y })
}

fn read_steer_velocity(r: &mut Units<'_>) -> Result<SteerVelocity, StreamError> {
    let s = r.signed();
    let v = r.signed();
    Ok(SteerVelocity {
        steering: SteeringAngle::try_from_i64(i64::from(s))?,
        velocity: Velocity::try_from_i64(i64::from(v))?,
    })
}

impl SystemValue {
    /// The variable this value belongs to.
    #[must_use]
    pub fn variable(&self) -> SystemVariable {
        use SystemVariable as V;
        match self {
            SystemValue::Id(_) => V::Id,
            SystemValue::Position(_) => V::Position,
            SystemValue::SteerVelocity(_) => V::SteerVelocity,
            SystemValue::AdjustedYaw(_) => V::AdjustedYaw,
            SystemValue::Heading(_) => V::Heading,
            SystemValue::AdcSteering(_) => V::AdcSteering,
            SystemValue::AdcRange(_) => V::AdcRange,
            SystemValue::AdcGyroReference(_) => V::AdcGyroReference,
            SystemValue::AdcGyroPitchRoll { .. } => V::AdcGyroPitchRoll,
            SystemValue::AdcGyroYaw(_) => V::AdcGyroYaw,
            SystemValue::ChipStatus(_) => V::ChipStatus,
            SystemValue::TargetPosition(_) => V::TargetPosition,
            SystemValue::TargetSteerVelocity(_) => V::TargetSteerVelocity,
            SystemValue::TargetYaw(_) => V::TargetYaw,
            SystemValue::MotorPdError { .. } => V::MotorPdError,
            SystemValue::MotorIError(_) => V::MotorIError,
            SystemValue::User { index, .. } => match index {
                1 => V::User1,
                2 => V::User2,
                3 => V::User3,
                4 => V::User4,
                5 => V::User5,
                _ => V::User6,
            },
        }
    }

    fn read(var: SystemVariable, r: &mut Units<'_>) -> Result<Self, StreamError> {
        use SystemVariable as V;
        Ok(match var {
            V::Id => SystemValue::Id(read_unsigned(r)?),
            V::Position => SystemValue::Position(read_position(r)?),
            V::SteerVelocity => SystemValue::SteerVelocity(read_steer_velocity(r)?),
            V::AdjustedYaw => SystemValue::AdjustedYaw(read_heading(r)?),
            V::Heading => SystemValue::Heading(read_heading(r)?),
            V::AdcSteering => SystemValue::AdcSteering(read_unsigned(r)?),
            V::AdcRange => SystemValue::AdcRange(read_unsigned(r)?),
            V::AdcGyroReference => SystemValue::AdcGyroReference(read_unsigned(r)?),
            V::AdcGyroPitchRoll => SystemValue::AdcGyroPitchRoll {
                pitch: read_i14(r)?,
                roll: read_i14(r)?,
            },
            V::AdcGyroYaw => SystemValue::AdcGyroYaw(read_i14(r)?),
            V::ChipStatus => SystemValue::ChipStatus(ChipStatus::from_bits(read_u14(r))),
            V::TargetPosition => SystemValue::TargetPosition(read_position(r)?),
            V::TargetSteerVelocity => SystemValue::TargetSteerVelocity(read_steer_velocity(r)?),
            V::TargetYaw => SystemValue::TargetYaw(read_heading(r)?),
            V::MotorPdError => SystemValue::MotorPdError {
                proportional: read_i14(r)?,
                differential: read_i14(r)?,
            },
            V::MotorIError => SystemValue::MotorIError(read_i28(r)?),
            V::User1 | V::User2 | V::User3 | V::User4 | V::User5 | V::User6 => SystemValue::User {
                index: var as u8 - V::User1 as u8 + 1,
                value: read_unsigned(r)?,
            },
        })
    }

    fn write(&self, w: &mut BitWriter<'_>) -> Result<(), EncodeError> {
        let u = |w: &mut BitWriter<'_>, v: u16| w.write(u32::from(v), 14).map_err(pack_error);
        let s =
            |w: &mut BitWriter<'_>, v: i16| w.write_signed(i32::from(v), 14).map_err(pack_error);
        match *self {
            SystemValue::Id(v)
            | SystemValue::AdcSteering(v)
            | SystemValue::AdcRange(v)
            | SystemValue::AdcGyroReference(v)
            | SystemValue::User { value: v, .. } => u(w, v.get()),
            SystemValue::Position(p) | SystemValue::TargetPosition(p) => {
                u(w, p.x.get())?;
                u(w, p.y.get())
            }
            SystemValue::SteerVelocity(sv) | SystemValue::TargetSteerVelocity(sv) => {
                s(w, sv.steering.get())?;
                s(w, sv.velocity.get())
            }
            SystemValue::AdjustedYaw(h) | SystemValue::Heading(h) | SystemValue::TargetYaw(h) => {
                u(w, h.get())
            }
            SystemValue::AdcGyroPitchRoll { pitch: a, roll: b }
            | SystemValue::MotorPdError {
                proportional: a,
                differential: b,
            } => {
                s(w, a.get())?;
                s(w, b.get())
            }
            SystemValue::AdcGyroYaw(v) => s(w, v.get()),
            SystemValue::ChipStatus(c) => u(w, c.to_bits()),
            SystemValue::MotorIError(v) => w.write_signed(v.get(), 28).map_err(pack_error),
        }
    }
}

/// Iterator over the variables of one STREAM message, in stream order.
#[derive(Debug, Clone)]
pub struct StreamValues<'a> {
    reader: Units<'a>,
    remaining: u32,
    failed: bool,
}

impl<'a> StreamValues<'a> {
    /// Checks the data length against `format` and iterates its variables.
    pub fn new(format: StreamFormat, data: &'a [u8]) -> Result<Self, StreamError> {
        let reader = Units::new(format, data)?;
        Ok(Self {
            reader,
            remaining: format.bits(),
            failed: false,
        })
    }
}

impl Iterator for StreamValues<'_> {
    type Item = Result<SystemValue, StreamError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed || self.remaining == 0 {
            return None;
        }
        let n = self.remaining.trailing_zeros() as u8;
        self.remaining &= self.remaining - 1;
        let var = SystemVariable::from_number(n)?;
        let v = SystemValue::read(var, &mut self.reader);
        self.failed = v.is_err();
        Some(v)
    }
}

/// All variables of one STREAM message; `None` where the format leaves one out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StreamSample {
    pub id: Option<U14>,
    pub position: Option<Position>,
    pub steer_velocity: Option<SteerVelocity>,
    pub adjusted_yaw: Option<Heading>,
    pub heading: Option<Heading>,
    pub adc_steering: Option<U14>,
    pub adc_range: Option<U14>,
    pub adc_gyro_reference: Option<U14>,
    pub adc_gyro_pitch: Option<I14>,
    pub adc_gyro_roll: Option<I14>,
    pub adc_gyro_yaw: Option<I14>,
    pub chip_status: Option<ChipStatus>,
    pub target_position: Option<Position>,
    pub target_steer_velocity: Option<SteerVelocity>,
    pub target_yaw: Option<Heading>,
    pub motor_p_error: Option<I14>,
    pub motor_d_error: Option<I14>,
    pub motor_i_error: Option<I28>,
    pub user: [Option<U14>; 6],
}

impl StreamSample {
    /// Decodes STREAM data in `format`. Same result as collecting [`StreamValues`] with
    /// [`set`](Self::set), written out variable by variable because it is the receive hot
    /// path: the reader stays in registers and no intermediate [`SystemValue`] is built.
    // Out of line on the firmware, one call per STREAM message: inlined into the client's
    // message handling it cost 208 bytes more.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    pub fn decode(format: StreamFormat, data: &[u8]) -> Result<Self, StreamError> {
        use SystemVariable as V;
        let mut r = Units::new(format, data)?;
        let on = |var: V| format.contains(var);
        let mut s = StreamSample::default();
        if on(V::Id) {
            s.id = Some(read_unsigned(&mut r)?);
        }
        if on(V::Position) {
            s.position = Some(read_position(&mut r)?);
        }
        if on(V::SteerVelocity) {
            s.steer_velocity = Some(read_steer_velocity(&mut r)?);
        }
        if on(V::AdjustedYaw) {
            s.adjusted_yaw = Some(read_heading(&mut r)?);
        }
        if on(V::Heading) {
            s.heading = Some(read_heading(&mut r)?);
        }
        if on(V::AdcSteering) {
            s.adc_steering = Some(read_unsigned(&mut r)?);
        }
        if on(V::AdcRange) {
            s.adc_range = Some(read_unsigned(&mut r)?);
        }
        if on(V::AdcGyroReference) {
            s.adc_gyro_reference = Some(read_unsigned(&mut r)?);
        }
        if on(V::AdcGyroPitchRoll) {
            s.adc_gyro_pitch = Some(read_i14(&mut r)?);
            s.adc_gyro_roll = Some(read_i14(&mut r)?);
        }
        if on(V::AdcGyroYaw) {
            s.adc_gyro_yaw = Some(read_i14(&mut r)?);
        }
        if on(V::ChipStatus) {
            s.chip_status = Some(ChipStatus::from_bits(r.unit()));
        }
        if on(V::TargetPosition) {
            s.target_position = Some(read_position(&mut r)?);
        }
        if on(V::TargetSteerVelocity) {
            s.target_steer_velocity = Some(read_steer_velocity(&mut r)?);
        }
        if on(V::TargetYaw) {
            s.target_yaw = Some(read_heading(&mut r)?);
        }
        if on(V::MotorPdError) {
            s.motor_p_error = Some(read_i14(&mut r)?);
            s.motor_d_error = Some(read_i14(&mut r)?);
        }
        if on(V::MotorIError) {
            s.motor_i_error = Some(read_i28(&mut r)?);
        }
        let first_user = V::User1 as u32;
        for (i, slot) in (first_user..).zip(s.user.iter_mut()) {
            if format.bits() & (1 << i) != 0 {
                *slot = Some(read_unsigned(&mut r)?);
            }
        }
        Ok(s)
    }

    /// Stores one value.
    pub fn set(&mut self, value: SystemValue) {
        match value {
            SystemValue::Id(v) => self.id = Some(v),
            SystemValue::Position(v) => self.position = Some(v),
            SystemValue::SteerVelocity(v) => self.steer_velocity = Some(v),
            SystemValue::AdjustedYaw(v) => self.adjusted_yaw = Some(v),
            SystemValue::Heading(v) => self.heading = Some(v),
            SystemValue::AdcSteering(v) => self.adc_steering = Some(v),
            SystemValue::AdcRange(v) => self.adc_range = Some(v),
            SystemValue::AdcGyroReference(v) => self.adc_gyro_reference = Some(v),
            SystemValue::AdcGyroPitchRoll { pitch, roll } => {
                self.adc_gyro_pitch = Some(pitch);
                self.adc_gyro_roll = Some(roll);
            }
            SystemValue::AdcGyroYaw(v) => self.adc_gyro_yaw = Some(v),
            SystemValue::ChipStatus(v) => self.chip_status = Some(v),
            SystemValue::TargetPosition(v) => self.target_position = Some(v),
            SystemValue::TargetSteerVelocity(v) => self.target_steer_velocity = Some(v),
            SystemValue::TargetYaw(v) => self.target_yaw = Some(v),
            SystemValue::MotorPdError {
                proportional,
                differential,
            } => {
                self.motor_p_error = Some(proportional);
                self.motor_d_error = Some(differential);
            }
            SystemValue::MotorIError(v) => self.motor_i_error = Some(v),
            SystemValue::User { index, value } => {
                if let Some(slot) = self.user.get_mut(usize::from(index.wrapping_sub(1))) {
                    *slot = Some(value);
                }
            }
        }
    }

    /// The value of one variable, if present.
    #[must_use]
    pub fn get(&self, var: SystemVariable) -> Option<SystemValue> {
        use SystemVariable as V;
        let user = |i: u8| {
            self.user[usize::from(i - 1)].map(|value| SystemValue::User { index: i, value })
        };
        match var {
            V::Id => self.id.map(SystemValue::Id),
            V::Position => self.position.map(SystemValue::Position),
            V::SteerVelocity => self.steer_velocity.map(SystemValue::SteerVelocity),
            V::AdjustedYaw => self.adjusted_yaw.map(SystemValue::AdjustedYaw),
            V::Heading => self.heading.map(SystemValue::Heading),
            V::AdcSteering => self.adc_steering.map(SystemValue::AdcSteering),
            V::AdcRange => self.adc_range.map(SystemValue::AdcRange),
            V::AdcGyroReference => self.adc_gyro_reference.map(SystemValue::AdcGyroReference),
            V::AdcGyroPitchRoll => match (self.adc_gyro_pitch, self.adc_gyro_roll) {
                (Some(pitch), Some(roll)) => Some(SystemValue::AdcGyroPitchRoll { pitch, roll }),
                _ => None,
            },
            V::AdcGyroYaw => self.adc_gyro_yaw.map(SystemValue::AdcGyroYaw),
            V::ChipStatus => self.chip_status.map(SystemValue::ChipStatus),
            V::TargetPosition => self.target_position.map(SystemValue::TargetPosition),
            V::TargetSteerVelocity => self
                .target_steer_velocity
                .map(SystemValue::TargetSteerVelocity),
            V::TargetYaw => self.target_yaw.map(SystemValue::TargetYaw),
            V::MotorPdError => match (self.motor_p_error, self.motor_d_error) {
                (Some(proportional), Some(differential)) => Some(SystemValue::MotorPdError {
                    proportional,
                    differential,
                }),
                _ => None,
            },
            V::MotorIError => self.motor_i_error.map(SystemValue::MotorIError),
            V::User1 => user(1),
            V::User2 => user(2),
            V::User3 => user(3),
            V::User4 => user(4),
            V::User5 => user(5),
            V::User6 => user(6),
        }
    }

    /// Writes a complete STREAM message carrying the variables `format` enables.
    pub fn emit(&self, format: StreamFormat, out: &mut [u8]) -> Result<usize, EncodeError> {
        emit_frame(STREAM, out, |w| {
            for var in format.variables() {
                let value = self.get(var).ok_or(EncodeError::MissingVariable {
                    number: var.number(),
                })?;
                value.write(w)?;
            }
            Ok(())
        })
    }
}

/// Decodes every STREAM message found in `bytes` with `format` and returns how
/// many decoded cleanly. Meant for on-target benchmarks (count cycles around it).
pub fn decode_all(bytes: &[u8], deframer: &mut crate::Deframer, format: StreamFormat) -> usize {
    let mut decoded = 0;
    let mut input = bytes;
    while !input.is_empty() {
        if let Some(Ok(msg)) = deframer.push_slice(&mut input) {
            if msg.header == STREAM && StreamSample::decode(format, msg.data).is_ok() {
                decoded += 1;
            }
        }
    }
    decoded
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::fields::{ChipTemperature, Warnings};
    use proptest::prelude::*;

    #[test]
    fn validity_mask_rejects_not_in_use_bits() {
        for bit in [5, 6, 7, 13, 14, 21] {
            assert!(StreamFormat::new(1 << bit).is_err(), "bit {bit}");
        }
        assert!(StreamFormat::new(1 << 28).is_err());
        assert_eq!(StreamFormat::ALL.bits(), 0x0FDF_9F1F);
        assert!(StreamFormat::new(StreamFormat::ALL.bits()).is_ok());
    }

    #[test]
    fn full_format_is_58_bytes() {
        assert_eq!(StreamFormat::ALL.data_bits(), 406);
        assert_eq!(StreamFormat::ALL.data_len(), 58);
    }

    #[test]
    fn position_and_chip_status_frame() {
        let format = StreamFormat::EMPTY
            .with(SystemVariable::Position)
            .with(SystemVariable::ChipStatus);
        let sample = StreamSample {
            position: Some(Position::new(320, 480).unwrap()),
            chip_status: Some(ChipStatus {
                temperature: ChipTemperature::new(66).unwrap(),
                warnings: Warnings {
                    battery_low: false,
                    over_temperature: true,
                },
            }),
            ..StreamSample::default()
        };
        let mut buf = [0u8; 16];
        let n = sample.emit(format, &mut buf).unwrap();
        // 28 + 14 bits: 320, 480, then 66 << 7 | 1 = 0b10000100000001
        assert_eq!(
            &buf[..n],
            &[0xFC, 0x02, 0x40, 0x03, 0x60, 0x42, 0x01, 0x1E, 0xFF]
        );
        assert_eq!(StreamSample::decode(format, &buf[1..7]).unwrap(), sample);
    }

    #[test]
    fn missing_variable_is_an_encode_error() {
        let format = StreamFormat::EMPTY.with(SystemVariable::Heading);
        let mut buf = [0u8; 16];
        assert_eq!(
            StreamSample::default().emit(format, &mut buf),
            Err(EncodeError::MissingVariable { number: 4 })
        );
    }

    #[test]
    fn wrong_length_is_reported() {
        let format = StreamFormat::EMPTY.with(SystemVariable::Heading);
        assert_eq!(
            StreamSample::decode(format, &[0, 0, 0]),
            Err(StreamError::Length {
                expected: 2,
                got: 3
            })
        );
    }

    #[test]
    fn values_iterate_in_table_order() {
        let format = StreamFormat::EMPTY
            .with(SystemVariable::User6)
            .with(SystemVariable::Id);
        let data = [0x00, 0x05, 0x00, 0x07];
        let vars: std::vec::Vec<_> = StreamValues::new(format, &data)
            .unwrap()
            .map(|v| v.unwrap())
            .collect();
        assert_eq!(
            vars,
            [
                SystemValue::Id(U14::new(5).unwrap()),
                SystemValue::User {
                    index: 6,
                    value: U14::new(7).unwrap()
                }
            ]
        );
    }

    pub(crate) fn arb_i14() -> impl Strategy<Value = I14> {
        (-8192i16..=8191).prop_map(|v| I14::new(v).unwrap())
    }
    pub(crate) fn arb_u14() -> impl Strategy<Value = U14> {
        (0u16..=0x3FFF).prop_map(|v| U14::new(v).unwrap())
    }
    pub(crate) fn arb_position() -> impl Strategy<Value = Position> {
        (0u16..=640, 0u16..=960).prop_map(|(x, y)| Position::new(x, y).unwrap())
    }
    pub(crate) fn arb_sv() -> impl Strategy<Value = SteerVelocity> {
        (-523i16..=523, -8192i16..=8191).prop_map(|(s, v)| SteerVelocity {
            steering: SteeringAngle::new(s).unwrap(),
            velocity: Velocity::new(v).unwrap(),
        })
    }
    pub(crate) fn arb_heading() -> impl Strategy<Value = Heading> {
        (0u16..=6283).prop_map(|v| Heading::new(v).unwrap())
    }

    prop_compose! {
        pub(crate) fn arb_full_sample()(
            id in arb_u14(), pos in arb_position(), sv in arb_sv(), ay in arb_heading(),
            hd in arb_heading(), a in proptest::array::uniform3(arb_u14()),
            g in proptest::array::uniform3(arb_i14()), t in 0u8..=127, bl in any::<bool>(),
            ot in any::<bool>(), tp in arb_position(), tsv in arb_sv(), ty in arb_heading(),
            pd in proptest::array::uniform2(arb_i14()),
            ie in (-(1i32 << 27))..(1i32 << 27), user in proptest::array::uniform6(arb_u14()),
        ) -> StreamSample {
            StreamSample {
                id: Some(id), position: Some(pos), steer_velocity: Some(sv),
                adjusted_yaw: Some(ay), heading: Some(hd), adc_steering: Some(a[0]),
                adc_range: Some(a[1]), adc_gyro_reference: Some(a[2]),
                adc_gyro_pitch: Some(g[0]), adc_gyro_roll: Some(g[1]), adc_gyro_yaw: Some(g[2]),
                chip_status: Some(ChipStatus {
                    temperature: ChipTemperature::new(t).unwrap(),
                    warnings: Warnings { battery_low: bl, over_temperature: ot },
                }),
                target_position: Some(tp), target_steer_velocity: Some(tsv), target_yaw: Some(ty),
                motor_p_error: Some(pd[0]), motor_d_error: Some(pd[1]),
                motor_i_error: Some(I28::new(ie).unwrap()),
                user: user.map(Some),
            }
        }
    }

    pub(crate) fn arb_format() -> impl Strategy<Value = StreamFormat> {
        any::<u32>().prop_map(|b| StreamFormat::new(b & StreamFormat::ALL.bits()).unwrap())
    }

    #[test]
    fn unit_counts_match_widths() {
        for bits in [0, 1, 0b110, StreamFormat::ALL.bits(), 1 << 20, 1 << 27] {
            let format = StreamFormat::new(bits).unwrap();
            let widths: usize = format.variables().map(|v| usize::from(v.width())).sum();
            assert_eq!(format.data_bits(), widths, "{bits:#x}");
        }
    }

    #[test]
    fn negative_integral_error_decodes() {
        let format = StreamFormat::EMPTY.with(SystemVariable::MotorIError);
        // -2 in 28 bits: 0xFFFFFFE, units 0x3FFF and 0x3FFE.
        let data = [0x7F, 0x7F, 0x7F, 0x7E];
        let sample = StreamSample::decode(format, &data).unwrap();
        assert_eq!(sample.motor_i_error, Some(I28::new(-2).unwrap()));
    }

    proptest! {
        /// The 14-bit unit reader agrees with the general bit reader on any bytes.
        #[test]
        fn units_match_bit_reader(data in proptest::collection::vec(any::<u8>(), 0..30)) {
            let data = &data[..data.len() & !1];
            let mut reader = crate::pack::BitReader::new(data, 7 * data.len()).unwrap();
            let mut units = Units { data };
            for _ in 0..data.len() / 2 {
                prop_assert_eq!(u32::from(units.unit()), reader.read(14).unwrap());
            }
            prop_assert!(units.data.is_empty());
        }

        /// `decode` and the `StreamValues` iterator agree on any data, errors included.
        #[test]
        fn decode_matches_values(
            format in arb_format(),
            bytes in proptest::collection::vec(0u8..0x80, 58),
            extra in 0usize..2,
        ) {
            let data = &bytes[..(format.data_len() + extra).min(bytes.len())];
            let via_values = StreamValues::new(format, data).and_then(|values| {
                let mut sample = StreamSample::default();
                for value in values {
                    sample.set(value?);
                }
                Ok(sample)
            });
            prop_assert_eq!(StreamSample::decode(format, data), via_values);
        }

        #[test]
        fn stream_round_trips(sample in arb_full_sample(), format in arb_format()) {
            let mut buf = [0u8; crate::wire::MAX_FRAME_LEN];
            let n = sample.emit(format, &mut buf).unwrap();
            prop_assert_eq!(n, format.data_len() + 3);
            let mut d = crate::Deframer::new();
            let mut got = None;
            for &b in &buf[..n] {
                if let Some(r) = d.push(b) {
                    let m = r.unwrap();
                    got = Some(StreamSample::decode(format, m.data).unwrap());
                }
            }
            let got = got.unwrap();
            for var in SystemVariable::ALL {
                let expected = if format.contains(var) { sample.get(var) } else { None };
                prop_assert_eq!(got.get(var), expected);
            }
        }
    }
}
