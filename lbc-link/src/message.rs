//! Typed messages: commands (UBC to LBC) and everything the LBC sends back.
//!
//! Each type has `decode(header, data)` for untrusted input and `emit(out)` that
//! writes a complete message (header, packed data, checksum, terminator).
//! Widths follow Table 3-2 with the corrections in `docs/lbc-protocol.md`:
//! WRIT_EP and the READ_EP data message carry 7 + 16 = 23 bits; CALB_GS acks
//! carry three 14-bit offsets (42 bits) but 28-bit and empty acks are accepted.

use heapless::Vec;

use crate::fields::{
    EepromAddress, GpioPattern, GyroOffsets, GyroRaw, Heading, LedPattern, Param, ParamValue,
    Position, RangeError, SteerVelocity, SteeringAngle, SteeringCalibration, UserRegister,
    VehicleId, Velocity, Warnings, XCoord, YCoord, I14, U14,
};
use crate::header::{CommandKind, HeaderClass, CSER, STREAM, UNKCMD};
use crate::pack::{packed_len, BitWriter, UnpackError};
use crate::stream::{StreamError, StreamFormat, StreamSample};
use crate::wire::{emit_frame, emit_raw, pack_error, EncodeError, RawMessage, MAX_DATA_LEN};

/// Why a message could not be turned into a typed value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum DecodeError {
    /// The first byte is not a header.
    NotAHeader { byte: u8 },
    /// A reserved or NOT-IN-USE header.
    Unassigned { header: u8 },
    /// A valid header of a class this decoder does not take (e.g. CSER sent to the LBC).
    WrongClass { class: HeaderClass },
    /// The data length does not fit the message type.
    Length {
        header: u8,
        expected: usize,
        got: usize,
    },
    /// A field is out of range; for a command the LBC answers with the specific error.
    Field { header: u8, error: RangeError },
    /// An UNKCMD echo whose first byte does not restore to a header.
    BadEcho { byte: u8 },
    /// A data byte with bit 7 set (only possible when bypassing the deframer).
    BadDataByte { index: usize, byte: u8 },
}

fn check_data(data: &[u8]) -> Result<(), DecodeError> {
    match data.iter().enumerate().find(|(_, b)| **b >= 0x80) {
        Some((index, &byte)) => Err(DecodeError::BadDataByte { index, byte }),
        None => Ok(()),
    }
}

fn classify(header: u8, data: &[u8]) -> Result<HeaderClass, DecodeError> {
    check_data(data)?;
    match HeaderClass::classify(header) {
        None => Err(DecodeError::NotAHeader { byte: header }),
        Some(HeaderClass::Reserved(h) | HeaderClass::NotInUse(h)) => {
            Err(DecodeError::Unassigned { header: h })
        }
        Some(c) => Ok(c),
    }
}

fn fields<const N: usize>(
    header: u8,
    data: &[u8],
    widths: &[u8; N],
) -> Result<[u32; N], DecodeError> {
    let mut out = [0u32; N];
    fields_into(header, data, widths, &mut out)?;
    Ok(out)
}

// Out of line: inlined into each message's decoder it cost the firmware 296 bytes more
// (`docs/benchmarks.md` section 1), for a call once per message; one copy for every number
// of fields.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn fields_into(header: u8, data: &[u8], widths: &[u8], out: &mut [u32]) -> Result<(), DecodeError> {
    crate::pack::unpack_into(data, widths, out).map_err(|e| match e {
        UnpackError::LengthMismatch { expected, got } => DecodeError::Length {
            header,
            expected,
            got,
        },
        UnpackError::OutOfBits | UnpackError::WidthTooLarge { .. } => DecodeError::Length {
            header,
            expected: 0,
            got: data.len(),
        },
    })
}

fn field<T>(header: u8, r: Result<T, RangeError>) -> Result<T, DecodeError> {
    r.map_err(|error| DecodeError::Field { header, error })
}

fn position(header: u8, x: u32, y: u32) -> Result<Position, DecodeError> {
    Ok(Position {
        x: field(header, XCoord::try_from_i64(i64::from(x)))?,
        y: field(header, YCoord::try_from_i64(i64::from(y)))?,
    })
}

fn steer_velocity(header: u8, s: u32, v: u32) -> Result<SteerVelocity, DecodeError> {
    Ok(SteerVelocity {
        steering: field(
            header,
            SteeringAngle::try_from_i64(i64::from(crate::pack::sign_extend(s, 14))),
        )?,
        velocity: field(
            header,
            Velocity::try_from_i64(i64::from(crate::pack::sign_extend(v, 14))),
        )?,
    })
}

fn i14(raw: u32) -> I14 {
    I14::from_bits(raw)
}

type W<'a, 'b> = &'a mut BitWriter<'b>;

fn put(w: W<'_, '_>, value: u32, width: u8) -> Result<(), EncodeError> {
    w.write(value, width).map_err(pack_error)
}

fn put_signed(w: W<'_, '_>, value: i16, width: u8) -> Result<(), EncodeError> {
    w.write_signed(i32::from(value), width).map_err(pack_error)
}

/// A command from the UBC to the LBC (Table 3-2, bit 6 set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum Command {
    Stop,
    MoveXy(Position),
    MoveSv(SteerVelocity),
    CalbSt,
    CalbDm,
    CalbGs,
    WritEp {
        address: UserRegister,
        value: u16,
    },
    ReadEp(EepromAddress),
    WritLed {
        green: LedPattern,
        red: LedPattern,
    },
    WritGpo {
        gpio0: GpioPattern,
        gpio1: GpioPattern,
    },
    Init,
    Cmep,
    Rsep,
    Drds,
    Dren,
    Stds,
    Sten,
    ReadId,
    ReadXy,
    ReadSv,
    ReadAy,
    ReadPry,
    ReadBt,
    ReadRs,
    ReadHd,
    ReadSf,
    UpdSf(StreamFormat),
    ReadPar(Param),
    UpdPar(ParamValue),
}

impl Command {
    /// The command's kind (and header).
    // Never inlined: otherwise each crate calling it gets its own copy of it and its table.
    #[inline(never)]
    #[must_use]
    pub const fn kind(&self) -> CommandKind {
        use CommandKind as K;
        match self {
            Command::Stop => K::Stop,
            Command::MoveXy(_) => K::MoveXy,
            Command::MoveSv(_) => K::MoveSv,
            Command::CalbSt => K::CalbSt,
            Command::CalbDm => K::CalbDm,
            Command::CalbGs => K::CalbGs,
            Command::WritEp { .. } => K::WritEp,
            Command::ReadEp(_) => K::ReadEp,
            Command::WritLed { .. } => K::WritLed,
            Command::WritGpo { .. } => K::WritGpo,
            Command::Init => K::Init,
            Command::Cmep => K::Cmep,
            Command::Rsep => K::Rsep,
            Command::Drds => K::Drds,
            Command::Dren => K::Dren,
            Command::Stds => K::Stds,
            Command::Sten => K::Sten,
            Command::ReadId => K::ReadId,
            Command::ReadXy => K::ReadXy,
            Command::ReadSv => K::ReadSv,
            Command::ReadAy => K::ReadAy,
            Command::ReadPry => K::ReadPry,
            Command::ReadBt => K::ReadBt,
            Command::ReadRs => K::ReadRs,
            Command::ReadHd => K::ReadHd,
            Command::ReadSf => K::ReadSf,
            Command::UpdSf(_) => K::UpdSf,
            Command::ReadPar(_) => K::ReadPar,
            Command::UpdPar(_) => K::UpdPar,
        }
    }

    /// The header byte.
    #[must_use]
    pub const fn header(&self) -> u8 {
        self.kind().header()
    }

    /// Length of the complete message.
    #[must_use]
    pub const fn buffer_len(&self) -> usize {
        self.kind().command_len() + 3
    }

    /// The command with no data for `kind`, if it takes none.
    #[must_use]
    pub const fn without_data(kind: CommandKind) -> Option<Self> {
        use CommandKind as K;
        Some(match kind {
            K::Stop => Command::Stop,
            K::CalbSt => Command::CalbSt,
            K::CalbDm => Command::CalbDm,
            K::CalbGs => Command::CalbGs,
            K::Init => Command::Init,
            K::Cmep => Command::Cmep,
            K::Rsep => Command::Rsep,
            K::Drds => Command::Drds,
            K::Dren => Command::Dren,
            K::Stds => Command::Stds,
            K::Sten => Command::Sten,
            K::ReadId => Command::ReadId,
            K::ReadXy => Command::ReadXy,
            K::ReadSv => Command::ReadSv,
            K::ReadAy => Command::ReadAy,
            K::ReadPry => Command::ReadPry,
            K::ReadBt => Command::ReadBt,
            K::ReadRs => Command::ReadRs,
            K::ReadHd => Command::ReadHd,
            K::ReadSf => Command::ReadSf,
            _ => return None,
        })
    }

    /// Decodes a command message (as the LBC does).
    pub fn decode(header: u8, data: &[u8]) -> Result<Self, DecodeError> {
        match classify(header, data)? {
            HeaderClass::Command(kind) => Self::decode_kind(kind, data),
            class => Err(DecodeError::WrongClass { class }),
        }
    }

    /// Decodes a deframed message.
    pub fn parse(msg: &RawMessage<'_>) -> Result<Self, DecodeError> {
        Self::decode(msg.header, msg.data)
    }

    fn decode_kind(kind: CommandKind, data: &[u8]) -> Result<Self, DecodeError> {
        use CommandKind as K;
        let h = kind.header();
        if let Some(cmd) = Self::without_data(kind) {
            fields(h, data, &[])?;
            return Ok(cmd);
        }
        Ok(match kind {
            K::MoveXy => {
                let [x, y] = fields(h, data, &[14, 14])?;
                Command::MoveXy(position(h, x, y)?)
            }
            K::MoveSv => {
                let [s, v] = fields(h, data, &[14, 14])?;
                Command::MoveSv(steer_velocity(h, s, v)?)
            }
            K::WritEp => {
                let [a, v] = fields(h, data, &[7, 16])?;
                Command::WritEp {
                    address: field(h, UserRegister::try_from_i64(i64::from(a)))?,
                    value: v as u16,
                }
            }
            K::ReadEp => {
                let [a] = fields(h, data, &[7])?;
                Command::ReadEp(field(h, EepromAddress::try_from_i64(i64::from(a)))?)
            }
            K::WritLed => {
                let [g, r] = fields(h, data, &[7, 7])?;
                Command::WritLed {
                    green: field(h, LedPattern::from_bits(g as u8))?,
                    red: field(h, LedPattern::from_bits(r as u8))?,
                }
            }
            K::WritGpo => {
                let [a, b] = fields(h, data, &[7, 7])?;
                Command::WritGpo {
                    gpio0: field(h, GpioPattern::from_bits(a as u8))?,
                    gpio1: field(h, GpioPattern::from_bits(b as u8))?,
                }
            }
            K::UpdSf => {
                let [f] = fields(h, data, &[28])?;
                Command::UpdSf(field(h, StreamFormat::new(f))?)
            }
            K::ReadPar => {
                let [n] = fields(h, data, &[7])?;
                Command::ReadPar(field(h, Param::from_number(n as u8))?)
            }
            K::UpdPar => {
                let [n, v] = fields(h, data, &[7, 14])?;
                let param = field(h, Param::from_number(n as u8))?;
                Command::UpdPar(ParamValue::from_raw(param, v))
            }
            // Every other kind has no data and was handled above.
            _ => {
                return Err(DecodeError::Length {
                    header: h,
                    expected: kind.command_len(),
                    got: data.len(),
                })
            }
        })
    }

    fn write(&self, w: W<'_, '_>) -> Result<(), EncodeError> {
        match *self {
            Command::MoveXy(p) => {
                put(w, u32::from(p.x.get()), 14)?;
                put(w, u32::from(p.y.get()), 14)
            }
            Command::MoveSv(sv) => {
                put_signed(w, sv.steering.get(), 14)?;
                put_signed(w, sv.velocity.get(), 14)
            }
            Command::WritEp { address, value } => {
                put(w, u32::from(address.get()), 7)?;
                put(w, u32::from(value), 16)
            }
            Command::ReadEp(a) => put(w, u32::from(a.get()), 7),
            Command::WritLed { green, red } => {
                put(w, u32::from(green.bits()), 7)?;
                put(w, u32::from(red.bits()), 7)
            }
            Command::WritGpo { gpio0, gpio1 } => {
                put(w, u32::from(gpio0.bits()), 7)?;
                put(w, u32::from(gpio1.bits()), 7)
            }
            Command::UpdSf(f) => put(w, f.bits(), 28),
            Command::ReadPar(p) => put(w, u32::from(p.number()), 7),
            Command::UpdPar(pv) => {
                put(w, u32::from(pv.param().number()), 7)?;
                put(w, pv.raw(), 14)
            }
            _ => Ok(()),
        }
    }

    /// Writes the complete message; returns its length.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        // The same bytes as the LBC's echo of it: one copy of the frame writer serves both.
        Reply::Echo(*self).emit(out)
    }
}

/// A positive acknowledgement from the LBC.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum Reply {
    /// The LBC repeated the command ("the exact same message"); also READ_EP's
    /// first reply and bare CALB_ST/CALB_GS acks.
    Echo(Command),
    /// CALB_ST: steering offset and gain.
    CalbSt(SteeringCalibration),
    /// CALB_GS: gyro offsets.
    CalbGs(GyroOffsets),
    /// READ_EP's second message: address and register value.
    ReadEpData {
        address: EepromAddress,
        value: u16,
    },
    ReadId(VehicleId),
    ReadXy(Position),
    ReadSv(SteerVelocity),
    ReadAy(Heading),
    ReadPry(GyroRaw),
    ReadBt(Warnings),
    ReadRs(U14),
    ReadHd(Heading),
    ReadSf(StreamFormat),
    ReadPar(ParamValue),
}

impl Reply {
    /// The command this reply answers.
    #[must_use]
    pub const fn kind(&self) -> CommandKind {
        use CommandKind as K;
        match self {
            Reply::Echo(c) => c.kind(),
            Reply::CalbSt(_) => K::CalbSt,
            Reply::CalbGs(_) => K::CalbGs,
            Reply::ReadEpData { .. } => K::ReadEp,
            Reply::ReadId(_) => K::ReadId,
            Reply::ReadXy(_) => K::ReadXy,
            Reply::ReadSv(_) => K::ReadSv,
            Reply::ReadAy(_) => K::ReadAy,
            Reply::ReadPry(_) => K::ReadPry,
            Reply::ReadBt(_) => K::ReadBt,
            Reply::ReadRs(_) => K::ReadRs,
            Reply::ReadHd(_) => K::ReadHd,
            Reply::ReadSf(_) => K::ReadSf,
            Reply::ReadPar(_) => K::ReadPar,
        }
    }

    /// Decodes a reply to a command of `kind` (header = `kind.header()`).
    pub fn decode(kind: CommandKind, data: &[u8]) -> Result<Self, DecodeError> {
        use CommandKind as K;
        check_data(data)?;
        let h = kind.header();
        let len_err = || DecodeError::Length {
            header: h,
            expected: packed_len(kind.ack_bits()),
            got: data.len(),
        };
        Ok(match kind {
            K::CalbSt => match data.len() {
                0 => Reply::Echo(Command::CalbSt),
                4 => {
                    let [o, g] = fields(h, data, &[14, 14])?;
                    Reply::CalbSt(SteeringCalibration {
                        offset: i14(o),
                        gain: i14(g),
                    })
                }
                _ => return Err(len_err()),
            },
            K::CalbGs => match data.len() {
                0 => Reply::Echo(Command::CalbGs),
                4 => {
                    let [p, r] = fields(h, data, &[14, 14])?;
                    Reply::CalbGs(GyroOffsets {
                        pitch: i14(p),
                        roll: i14(r),
                        yaw: None,
                    })
                }
                6 => {
                    let [p, r, y] = fields(h, data, &[14, 14, 14])?;
                    Reply::CalbGs(GyroOffsets {
                        pitch: i14(p),
                        roll: i14(r),
                        yaw: Some(i14(y)),
                    })
                }
                _ => return Err(len_err()),
            },
            K::ReadEp => match data.len() {
                1 => Reply::Echo(Command::decode_kind(kind, data)?),
                4 => {
                    let [a, v] = fields(h, data, &[7, 16])?;
                    Reply::ReadEpData {
                        address: field(h, EepromAddress::try_from_i64(i64::from(a)))?,
                        value: v as u16,
                    }
                }
                _ => return Err(len_err()),
            },
            K::ReadId => {
                let [id] = fields(h, data, &[7])?;
                Reply::ReadId(field(h, VehicleId::try_from_i64(i64::from(id)))?)
            }
            K::ReadXy => {
                let [x, y] = fields(h, data, &[14, 14])?;
                Reply::ReadXy(position(h, x, y)?)
            }
            K::ReadSv => {
                let [s, v] = fields(h, data, &[14, 14])?;
                Reply::ReadSv(steer_velocity(h, s, v)?)
            }
            K::ReadAy | K::ReadHd => {
                let [v] = fields(h, data, &[14])?;
                let heading = field(h, Heading::try_from_i64(i64::from(v)))?;
                if kind == K::ReadAy {
                    Reply::ReadAy(heading)
                } else {
                    Reply::ReadHd(heading)
                }
            }
            K::ReadPry => {
                let [p, r, y] = fields(h, data, &[14, 14, 14])?;
                Reply::ReadPry(GyroRaw {
                    pitch: i14(p),
                    roll: i14(r),
                    yaw: i14(y),
                })
            }
            K::ReadBt => {
                let [b, t] = fields(h, data, &[1, 1])?;
                Reply::ReadBt(Warnings {
                    battery_low: b != 0,
                    over_temperature: t != 0,
                })
            }
            K::ReadRs => {
                let [v] = fields(h, data, &[14])?;
                Reply::ReadRs(field(h, U14::try_from_i64(i64::from(v)))?)
            }
            K::ReadSf => {
                let [f] = fields(h, data, &[28])?;
                Reply::ReadSf(field(h, StreamFormat::new(f))?)
            }
            K::ReadPar => {
                let [n, v] = fields(h, data, &[7, 14])?;
                let param = field(h, Param::from_number(n as u8))?;
                Reply::ReadPar(ParamValue::from_raw(param, v))
            }
            // All other acks repeat the command.
            _ => Reply::Echo(Command::decode_kind(kind, data)?),
        })
    }

    fn write(&self, w: W<'_, '_>) -> Result<(), EncodeError> {
        match *self {
            Reply::Echo(c) => c.write(w),
            Reply::CalbSt(c) => {
                put_signed(w, c.offset.get(), 14)?;
                put_signed(w, c.gain.get(), 14)
            }
            Reply::CalbGs(g) => {
                put_signed(w, g.pitch.get(), 14)?;
                put_signed(w, g.roll.get(), 14)?;
                match g.yaw {
                    Some(y) => put_signed(w, y.get(), 14),
                    None => Ok(()),
                }
            }
            Reply::ReadEpData { address, value } => {
                put(w, u32::from(address.get()), 7)?;
                put(w, u32::from(value), 16)
            }
            Reply::ReadId(id) => put(w, u32::from(id.get()), 7),
            Reply::ReadXy(p) => Command::MoveXy(p).write(w),
            Reply::ReadSv(sv) => Command::MoveSv(sv).write(w),
            Reply::ReadAy(h) | Reply::ReadHd(h) => put(w, u32::from(h.get()), 14),
            Reply::ReadPry(g) => {
                put_signed(w, g.pitch.get(), 14)?;
                put_signed(w, g.roll.get(), 14)?;
                put_signed(w, g.yaw.get(), 14)
            }
            Reply::ReadBt(b) => {
                put(w, u32::from(b.battery_low), 1)?;
                put(w, u32::from(b.over_temperature), 1)
            }
            Reply::ReadRs(v) => put(w, u32::from(v.get()), 14),
            Reply::ReadSf(f) => put(w, f.bits(), 28),
            Reply::ReadPar(pv) => Command::UpdPar(pv).write(w),
        }
    }

    /// Writes the complete message; returns its length.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        emit_frame(self.kind().header(), out, |w| self.write(w))
    }
}

/// Longest message an UNKCMD can echo in full: its 7-bit header plus the data
/// must fit in [`MAX_DATA_LEN`] bytes.
pub const MAX_ECHO_DATA: usize = MAX_DATA_LEN - 1;

/// The message an UNKCMD reports as not understood.
///
/// On the wire the echo is `header & 0x7F` followed by the data bytes: every
/// header has bit 7 set, so that bit is dropped and restored by the reader.
/// Data beyond [`MAX_ECHO_DATA`] bytes is cut off.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Echo {
    /// Header of the rejected message.
    pub header: u8,
    /// Its data bytes.
    pub data: Vec<u8, MAX_ECHO_DATA>,
}

impl Echo {
    /// Echo of a received message, truncated to [`MAX_ECHO_DATA`] data bytes.
    #[must_use]
    pub fn of(msg: &RawMessage<'_>) -> Self {
        let n = msg.data.len().min(MAX_ECHO_DATA);
        let mut data = Vec::new();
        // Cannot fail: n <= capacity.
        let _ = data.extend_from_slice(&msg.data[..n]);
        Self {
            header: msg.header,
            data,
        }
    }
}

/// Raw STREAM data, decoded later with the streaming format in force.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StreamData(pub Vec<u8, MAX_DATA_LEN>);

impl StreamData {
    /// Decodes the variables with `format`.
    pub fn decode(&self, format: StreamFormat) -> Result<StreamSample, StreamError> {
        StreamSample::decode(format, &self.0)
    }
}

/// Anything the LBC sends.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum LbcMessage {
    /// A positive acknowledgement (header with bit 6 set).
    Reply(Reply),
    /// A command's specific error (header with bit 6 cleared, no data).
    Error(CommandKind),
    /// UNKCMD: the LBC did not understand a message; `None` if it sent no echo.
    UnknownCommand(Option<Echo>),
    /// CSER: the LBC received a message with a bad checksum.
    ChecksumError,
    /// STREAM data.
    Stream(StreamData),
}

impl LbcMessage {
    /// Decodes a message from the LBC.
    pub fn decode(header: u8, data: &[u8]) -> Result<Self, DecodeError> {
        let empty = |expected_header: u8| {
            if data.is_empty() {
                Ok(())
            } else {
                Err(DecodeError::Length {
                    header: expected_header,
                    expected: 0,
                    got: data.len(),
                })
            }
        };
        Ok(match classify(header, data)? {
            HeaderClass::Command(kind) => LbcMessage::Reply(Reply::decode(kind, data)?),
            HeaderClass::SpecificError(kind) => {
                empty(header)?;
                LbcMessage::Error(kind)
            }
            HeaderClass::ChecksumError => {
                empty(header)?;
                LbcMessage::ChecksumError
            }
            HeaderClass::UnknownCommand => match data.split_first() {
                None => LbcMessage::UnknownCommand(None),
                Some((&first, rest)) => {
                    let echoed = first | 0x80;
                    if HeaderClass::classify(echoed).is_none() || rest.len() > MAX_ECHO_DATA {
                        return Err(DecodeError::BadEcho { byte: first });
                    }
                    let mut v = Vec::new();
                    let _ = v.extend_from_slice(rest);
                    LbcMessage::UnknownCommand(Some(Echo {
                        header: echoed,
                        data: v,
                    }))
                }
            },
            HeaderClass::Stream => {
                let mut v = Vec::new();
                v.extend_from_slice(data).map_err(|_| DecodeError::Length {
                    header,
                    expected: MAX_DATA_LEN,
                    got: data.len(),
                })?;
                LbcMessage::Stream(StreamData(v))
            }
            class @ (HeaderClass::Reserved(_) | HeaderClass::NotInUse(_)) => {
                return Err(DecodeError::WrongClass { class })
            }
        })
    }

    /// Decodes a deframed message.
    pub fn parse(msg: &RawMessage<'_>) -> Result<Self, DecodeError> {
        Self::decode(msg.header, msg.data)
    }

    /// Writes the complete message; returns its length.
    pub fn emit(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        match self {
            LbcMessage::Reply(r) => r.emit(out),
            LbcMessage::Error(kind) => emit_raw(kind.error_header(), &[], out),
            LbcMessage::ChecksumError => emit_raw(CSER, &[], out),
            LbcMessage::UnknownCommand(None) => emit_raw(UNKCMD, &[], out),
            LbcMessage::UnknownCommand(Some(echo)) => {
                let len = echo.data.len() + 4;
                let dst = out
                    .get_mut(..len)
                    .ok_or(EncodeError::BufferTooSmall { needed: len })?;
                dst[0] = UNKCMD;
                dst[1] = echo.header & 0x7F;
                for (d, s) in dst[2..].iter_mut().zip(echo.data.iter()) {
                    *d = s & 0x7F;
                }
                crate::wire::Frame::new_unchecked(dst).fill_checksum();
                Ok(len)
            }
            LbcMessage::Stream(data) => emit_raw(STREAM, &data.0, out),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fields::{Duty, GpioRate, LedRate};
    use crate::stream::tests::{arb_format, arb_heading, arb_position, arb_sv};
    use crate::Deframer;
    use proptest::prelude::*;

    fn arb_i14() -> impl Strategy<Value = I14> {
        (-8192i16..=8191).prop_map(|v| I14::new(v).unwrap())
    }

    fn arb_param_value() -> impl Strategy<Value = ParamValue> {
        (1u8..=12, any::<i16>()).prop_map(|(n, v)| {
            let p = Param::from_number(n).unwrap();
            let (lo, hi) = p.range();
            ParamValue::new(p, v.clamp(lo, hi)).unwrap()
        })
    }

    pub(crate) fn arb_command() -> impl Strategy<Value = Command> {
        let no_data = proptest::sample::select(
            CommandKind::ALL
                .iter()
                .filter_map(|k| Command::without_data(*k))
                .collect::<std::vec::Vec<_>>(),
        );
        prop_oneof![
            no_data,
            arb_position().prop_map(Command::MoveXy),
            arb_sv().prop_map(Command::MoveSv),
            (0x20u8..=0x3F, any::<u16>()).prop_map(|(a, value)| Command::WritEp {
                address: UserRegister::new(a).unwrap(),
                value
            }),
            (0u8..=0x3F).prop_map(|a| Command::ReadEp(EepromAddress::new(a).unwrap())),
            (0u8..=0x7F, 0u8..=0x7F).prop_map(|(g, r)| Command::WritLed {
                green: LedPattern::from_bits(g).unwrap(),
                red: LedPattern::from_bits(r).unwrap()
            }),
            (0u8..=0x7F, 0u8..=0x7F).prop_map(|(a, b)| Command::WritGpo {
                gpio0: GpioPattern::from_bits(a).unwrap(),
                gpio1: GpioPattern::from_bits(b).unwrap()
            }),
            arb_format().prop_map(Command::UpdSf),
            (1u8..=12).prop_map(|n| Command::ReadPar(Param::from_number(n).unwrap())),
            arb_param_value().prop_map(Command::UpdPar),
        ]
    }

    fn arb_reply() -> impl Strategy<Value = Reply> {
        prop_oneof![
            arb_command()
                .prop_filter("ack repeats the command", |c| {
                    let k = c.kind();
                    k.ack_bits() == k.command_bits()
                        || matches!(
                            k,
                            CommandKind::ReadEp | CommandKind::CalbSt | CommandKind::CalbGs
                        )
                })
                .prop_map(Reply::Echo),
            (arb_i14(), arb_i14())
                .prop_map(|(offset, gain)| Reply::CalbSt(SteeringCalibration { offset, gain })),
            (arb_i14(), arb_i14(), proptest::option::of(arb_i14()))
                .prop_map(|(pitch, roll, yaw)| Reply::CalbGs(GyroOffsets { pitch, roll, yaw })),
            (0u8..=0x3F, any::<u16>()).prop_map(|(a, value)| Reply::ReadEpData {
                address: EepromAddress::new(a).unwrap(),
                value
            }),
            (0u8..=127).prop_map(|v| Reply::ReadId(VehicleId::new(v).unwrap())),
            arb_position().prop_map(Reply::ReadXy),
            arb_sv().prop_map(Reply::ReadSv),
            arb_heading().prop_map(Reply::ReadAy),
            (arb_i14(), arb_i14(), arb_i14())
                .prop_map(|(pitch, roll, yaw)| Reply::ReadPry(GyroRaw { pitch, roll, yaw })),
            (any::<bool>(), any::<bool>()).prop_map(|(battery_low, over_temperature)| {
                Reply::ReadBt(Warnings {
                    battery_low,
                    over_temperature,
                })
            }),
            (0u16..=0x3FFF).prop_map(|v| Reply::ReadRs(U14::new(v).unwrap())),
            arb_heading().prop_map(Reply::ReadHd),
            arb_format().prop_map(Reply::ReadSf),
            arb_param_value().prop_map(Reply::ReadPar),
        ]
    }

    fn arb_lbc_message() -> impl Strategy<Value = LbcMessage> {
        prop_oneof![
            arb_reply().prop_map(LbcMessage::Reply),
            proptest::sample::select(CommandKind::ALL).prop_map(LbcMessage::Error),
            Just(LbcMessage::ChecksumError),
            Just(LbcMessage::UnknownCommand(None)),
            (
                0x80u8..=0xFE,
                proptest::collection::vec(0u8..=0x7F, 0..=MAX_ECHO_DATA)
            )
                .prop_map(|(header, data)| LbcMessage::UnknownCommand(Some(Echo {
                    header,
                    data: Vec::from_slice(&data).unwrap()
                }))),
            proptest::collection::vec(0u8..=0x7F, 0..=MAX_DATA_LEN)
                .prop_map(|d| LbcMessage::Stream(StreamData(Vec::from_slice(&d).unwrap()))),
        ]
    }

    /// Emits with `emit`, deframes, and returns header and data.
    fn through_wire(
        emit: impl Fn(&mut [u8]) -> Result<usize, EncodeError>,
    ) -> (u8, std::vec::Vec<u8>) {
        let mut buf = [0u8; crate::MAX_FRAME_LEN];
        let n = emit(&mut buf).unwrap();
        let mut d = Deframer::new();
        let mut got = None;
        for &b in &buf[..n] {
            if let Some(r) = d.push(b) {
                let m = r.unwrap();
                got = Some((m.header, m.data.to_vec()));
            }
        }
        got.unwrap()
    }

    proptest! {
        #[test]
        fn commands_round_trip(cmd in arb_command()) {
            let (h, data) = through_wire(|b| cmd.emit(b));
            prop_assert_eq!(h, cmd.header());
            prop_assert_eq!(data.len() + 3, cmd.buffer_len());
            prop_assert_eq!(Command::decode(h, &data), Ok(cmd));
        }

        #[test]
        fn lbc_messages_round_trip(msg in arb_lbc_message()) {
            let (h, data) = through_wire(|b| msg.emit(b));
            prop_assert_eq!(LbcMessage::decode(h, &data), Ok(msg));
        }

        #[test]
        fn decoders_never_panic(header in any::<u8>(), data in proptest::collection::vec(any::<u8>(), 0..70)) {
            let _ = Command::decode(header, &data);
            if let Ok(m) = LbcMessage::decode(header, &data) {
                let (h, d) = through_wire(|b| m.emit(b));
                prop_assert_eq!(LbcMessage::decode(h, &d), Ok(m));
            }
        }
    }

    #[test]
    fn move_xy_bytes() {
        let cmd = Command::MoveXy(Position::new(320, 480).unwrap());
        let mut b = [0u8; 8];
        let n = cmd.emit(&mut b).unwrap();
        assert_eq!(&b[..n], &[0xC1, 0x02, 0x40, 0x03, 0x60, 0x60, 0xFF]);
    }

    #[test]
    fn move_sv_negative_values_are_twos_complement() {
        let sv = SteerVelocity {
            steering: SteeringAngle::new(-1).unwrap(),
            velocity: Velocity::new(-8192).unwrap(),
        };
        let mut b = [0u8; 8];
        let n = Command::MoveSv(sv).emit(&mut b).unwrap();
        // -1 = 11111111111111, -8192 = 10000000000000
        assert_eq!(&b[1..n - 2], &[0x7F, 0x7F, 0x40, 0x00]);
    }

    #[test]
    fn writ_led_bytes() {
        let cmd = Command::WritLed {
            green: LedPattern::from_bits(0x35).unwrap(),
            red: LedPattern::new(LedRate::Blink1Hz, Duty::ON),
        };
        let mut b = [0u8; 8];
        let n = cmd.emit(&mut b).unwrap();
        assert_eq!(
            &b[..n],
            &[0xD2, 0x35, 0x0A, (0xD2 ^ 0x35 ^ 0x0A) & 0x7F, 0xFF]
        );
        let gpo = Command::WritGpo {
            gpio0: GpioPattern::new(GpioRate::Hz100, Duty::OFF),
            gpio1: GpioPattern::from_bits(0x05).unwrap(),
        };
        let n = gpo.emit(&mut b).unwrap();
        assert_eq!(&b[1..n - 2], &[0x70, 0x05]);
    }

    #[test]
    fn read_bt_bits_follow_stream_variable_15() {
        let r = Reply::ReadBt(Warnings {
            battery_low: true,
            over_temperature: false,
        });
        let mut b = [0u8; 8];
        let n = r.emit(&mut b).unwrap();
        assert_eq!(&b[..n], &[0xED, 0x02, 0x6F, 0xFF]);
    }

    #[test]
    fn upd_par_is_21_bits() {
        let pv = ParamValue::new(Param::ServoOffset, -2).unwrap();
        let mut b = [0u8; 8];
        let n = Command::UpdPar(pv).emit(&mut b).unwrap();
        // 0000111 11111111111110
        assert_eq!(&b[1..n - 2], &[0x07, 0x7F, 0x7E]);
    }

    #[test]
    fn field_errors_name_the_header() {
        // WRIT_EP to the non-user register 0x05
        let mut b = [0u8; 8];
        let n = crate::wire::emit_frame(0xD0, &mut b, |w| {
            w.write(0x05, 7).map_err(pack_error)?;
            w.write(1, 16).map_err(pack_error)
        })
        .unwrap();
        assert_eq!(
            Command::decode(0xD0, &b[1..n - 2]),
            Err(DecodeError::Field {
                header: 0xD0,
                error: RangeError {
                    field: crate::fields::Field::UserRegister,
                    value: 5
                }
            })
        );
        assert_eq!(
            Command::decode(0xF1, &[0x00, 0x00, 0x01, 0x60]),
            Err(DecodeError::Field {
                header: 0xF1,
                error: RangeError {
                    field: crate::fields::Field::StreamFormat,
                    value: 0xE0
                }
            })
        );
    }

    #[test]
    fn lenient_calibration_acks() {
        assert_eq!(
            Reply::decode(CommandKind::CalbSt, &[]),
            Ok(Reply::Echo(Command::CalbSt))
        );
        assert!(matches!(
            Reply::decode(CommandKind::CalbGs, &[0, 0, 0, 1]),
            Ok(Reply::CalbGs(GyroOffsets { yaw: None, .. }))
        ));
        assert!(matches!(
            Reply::decode(CommandKind::CalbGs, &[0, 0, 0, 0, 0]),
            Err(DecodeError::Length {
                expected: 6,
                got: 5,
                ..
            })
        ));
    }

    #[test]
    fn wrong_class_and_unassigned_headers() {
        assert_eq!(
            Command::decode(0xBD, &[]),
            Err(DecodeError::WrongClass {
                class: HeaderClass::ChecksumError
            })
        );
        assert_eq!(
            Command::decode(0xC3, &[]),
            Err(DecodeError::Unassigned { header: 0xC3 })
        );
        assert_eq!(
            LbcMessage::decode(0xBC, &[0x7F]),
            Err(DecodeError::BadEcho { byte: 0x7F })
        );
    }
}
