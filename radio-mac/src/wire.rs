//! Frame formats on the radio byte stream.
//!
//! A raw frame is `header | src | body | crc16`; on air it is COBS-encoded and followed by a
//! `0x00` delimiter, so a receiver that lost bytes or heard garbage resynchronises at the next
//! zero. The header carries a 3-bit protocol version, so a car running other firmware is
//! reported as [`FrameError::UnsupportedVersion`] rather than as noise. Multi-byte fields are
//! little-endian. Field tables: `docs/radio-protocol.md`.

use crate::addr::{Address, CarId};
use crc::{Crc, CRC_16_IBM_3740};
use heapless::Vec;

/// Protocol version carried in the top three bits of every header byte. Version 2 added the
/// ground station's sessions (kinds 7..=9; the session epoch in the MAC of kind 6) and made
/// the ground station's heartbeat authenticated (kind 7 instead of kind 2).
pub const VERSION: u8 = 2;
/// Largest opaque payload of a request, reply or authenticated command.
pub const MAX_PAYLOAD: usize = 32;
/// Length of the truncated SipHash-2-4 tag on authenticated commands.
pub const AUTH_TAG_LEN: usize = 8;
/// CRC length at the end of every raw frame.
pub const CRC_LEN: usize = 2;
/// Smallest raw frame: header, source, CRC.
pub const MIN_RAW: usize = 2 + CRC_LEN;
/// Largest raw frame (an authenticated command with a full payload).
pub const MAX_RAW: usize = 2 + 6 + MAX_PAYLOAD + AUTH_TAG_LEN + CRC_LEN;
/// The byte that ends every frame on air (COBS leaves no other zero).
pub const DELIMITER: u8 = 0x00;
/// Largest frame on air: COBS adds one byte below 254 bytes, plus the `0x00` delimiter.
pub const MAX_ENCODED: usize = MAX_RAW + 2;
/// Bytes on air for one state broadcast, all framing included.
pub const STATE_FRAME_LEN: usize = 16;
/// Largest X or Y in tracking units (14-bit field).
pub const MAX_COORD: u16 = 0x3FFF;
/// Largest heading in milliradians.
pub const MAX_HEADING_MRAD: u16 = 6283;

/// CRC-16/IBM-3740 (a.k.a. CCITT-FALSE): poly 0x1021, init 0xFFFF, check value 0x29B1,
/// through the `crc` crate and its 256-entry table: the reference [`crc16`] is tested against.
pub const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

/// The frames' CRC, the same value as [`CRC16`]'s, computed a byte at a time without a
/// table: a dozen shifts and XORs per byte instead of a lookup in the crate's 512-byte table.
/// With `x` the byte XOR the register's high byte, folded once (`x ^= x >> 4`), the register
/// advances by `x`'s multiples of the polynomial 0x1021 = x^12 + x^5 + 1.
#[must_use]
pub fn crc16(data: &[u8]) -> u16 {
    // In a 32-bit register, masked once per byte.
    let mut crc = 0xFFFF_u32;
    for &b in data {
        let mut x = ((crc >> 8) ^ u32::from(b)) & 0xFF;
        x ^= x >> 4;
        crc = ((crc << 8) ^ (x << 12) ^ (x << 5) ^ x) & 0xFFFF;
    }
    crc as u16
}

/// Opaque command or reply bytes.
pub type Payload = Vec<u8, MAX_PAYLOAD>;

/// Frame kinds (low five bits of the header byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Kind {
    /// Periodic pose broadcast of a car.
    State = 1,
    /// Liveness beacon.
    Heartbeat = 2,
    /// Acknowledged unicast command (answered by a [`Kind::Reply`]).
    Request = 3,
    /// Answer to a request or an authenticated command; doubles as the acknowledgement.
    Reply = 4,
    /// Typed maneuver message.
    Group = 5,
    /// Ground-station command with a keyed MAC.
    AuthCommand = 6,
    /// The ground station's authenticated heartbeat.
    GroundBeat = 7,
    /// A car asks the ground station for a session.
    Hello = 8,
    /// The ground station opens a session with one car.
    SessionOpen = 9,
}

impl Kind {
    fn from_bits(v: u8) -> Result<Self, FrameError> {
        Ok(match v {
            1 => Kind::State,
            2 => Kind::Heartbeat,
            3 => Kind::Request,
            4 => Kind::Reply,
            5 => Kind::Group,
            6 => Kind::AuthCommand,
            7 => Kind::GroundBeat,
            8 => Kind::Hello,
            9 => Kind::SessionOpen,
            kind => return Err(FrameError::UnknownKind { kind }),
        })
    }
}

/// A field whose value lies outside its range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Field {
    /// X coordinate (14 bits).
    X,
    /// Y coordinate (14 bits).
    Y,
    /// Heading, 0..=6283 mrad.
    Heading,
    /// Maneuver phase, 0..=15.
    Phase,
    /// Role nibble.
    Role,
}

/// Why bytes from the radio were not a valid frame. Every variant has a drop counter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// More bytes than [`MAX_ENCODED`] before a delimiter.
    Oversize,
    /// The COBS code bytes do not describe the frame.
    Cobs,
    /// Decoded frame shorter than the minimum for its kind.
    TooShort {
        /// Decoded length.
        len: usize,
    },
    /// CRC over the frame does not match the trailer.
    ChecksumMismatch {
        /// CRC computed over the received bytes.
        expected: u16,
        /// CRC carried in the frame.
        got: u16,
    },
    /// Header carries another protocol version (mixed firmware).
    UnsupportedVersion {
        /// Version found.
        got: u8,
    },
    /// Header kind not defined in this version.
    UnknownKind {
        /// Kind bits found.
        kind: u8,
    },
    /// Body length does not fit the kind.
    BadLength {
        /// Kind of the frame.
        kind: Kind,
        /// Raw frame length.
        len: usize,
    },
    /// Address byte with bit 7 set.
    InvalidAddress {
        /// Byte found.
        value: u8,
    },
    /// Source address not allowed for this kind.
    InvalidSource,
    /// Destination address not allowed for this kind.
    InvalidDestination,
    /// A field value outside its range.
    FieldOutOfRange {
        /// Which field.
        field: Field,
    },
    /// Unknown group message type.
    UnknownGroupMsg {
        /// Type byte found.
        value: u8,
    },
}

/// Why a frame could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// Output buffer too small.
    BufferTooSmall,
    /// A field value outside its range.
    FieldOutOfRange {
        /// Which field.
        field: Field,
    },
    /// Source address not allowed for this kind.
    InvalidSource,
    /// Destination address not allowed for this kind.
    InvalidDestination,
}

/// Maneuver role of a car.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Role {
    /// Not in a maneuver.
    #[default]
    Idle = 0,
    /// Leads a group.
    Leader = 1,
    /// Follows a leader.
    Follower = 2,
    /// Forwards messages for a group.
    Relay = 3,
}

impl Role {
    fn from_bits(v: u8) -> Result<Self, Field> {
        Ok(match v {
            0 => Role::Idle,
            1 => Role::Leader,
            2 => Role::Follower,
            3 => Role::Relay,
            _ => return Err(Field::Role),
        })
    }
}

/// Role and maneuver phase, one byte on air (role in the high nibble).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Mode {
    /// Role in the current maneuver.
    pub role: Role,
    /// Application-defined maneuver phase, 0..=15.
    pub phase: u8,
}

impl Mode {
    fn to_byte(self) -> Result<u8, EncodeError> {
        if self.phase > 15 {
            return Err(EncodeError::FieldOutOfRange {
                field: Field::Phase,
            });
        }
        Ok(((self.role as u8) << 4) | self.phase)
    }

    fn from_byte(b: u8) -> Result<Self, FrameError> {
        let role =
            Role::from_bits(b >> 4).map_err(|field| FrameError::FieldOutOfRange { field })?;
        Ok(Mode {
            role,
            phase: b & 0x0F,
        })
    }
}

/// Pose and motion of a car as broadcast at 30 Hz.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarState {
    /// X in tracking units (2.5 mm), 0..=16383 on air (0..=640 from the tracking system).
    pub x: u16,
    /// Y in tracking units (2.5 mm), 0..=16383 on air (0..=960 from the tracking system).
    pub y: u16,
    /// Heading in milliradians, counter-clockwise from +X, 0..=6283.
    pub heading_mrad: u16,
    /// Signed forward velocity in mm/s.
    pub velocity_mm_s: i16,
    /// Role and maneuver phase.
    pub mode: Mode,
}

/// Liveness beacon contents.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Heartbeat {
    /// Role and maneuver phase.
    pub mode: Mode,
    /// Number of fresh entries in the sender's neighbour table.
    pub neighbours: u8,
    /// Seconds since the sender started (wraps).
    pub uptime_s: u16,
}

/// Typed maneuver messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GroupMsg {
    /// Take this role.
    Role {
        /// Role to take.
        role: Role,
    },
    /// Take position `slot` of `count` in the formation.
    Slot {
        /// Zero-based position.
        slot: u8,
        /// Group size.
        count: u8,
    },
    /// Drive to this pose (tracking units, mrad).
    Target {
        /// X in tracking units.
        x: u16,
        /// Y in tracking units.
        y: u16,
        /// Heading in mrad.
        heading_mrad: u16,
    },
    /// Start the maneuver after this many milliseconds.
    Start {
        /// Delay in ms.
        delay_ms: u16,
    },
    /// Stop the maneuver now.
    Stop,
}

impl GroupMsg {
    fn type_byte(&self) -> u8 {
        match self {
            GroupMsg::Role { .. } => 1,
            GroupMsg::Slot { .. } => 2,
            GroupMsg::Target { .. } => 3,
            GroupMsg::Start { .. } => 4,
            GroupMsg::Stop => 5,
        }
    }
}

/// A parsed radio frame.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Frame {
    /// Periodic pose broadcast; always to everybody.
    State {
        /// Sending car.
        src: CarId,
        /// Sender's state counter (wraps), lets receivers count missed broadcasts.
        seq: u8,
        /// Pose and motion.
        state: CarState,
    },
    /// Liveness beacon; always to everybody.
    Heartbeat {
        /// Sender (car or ground station).
        src: Address,
        /// Contents.
        beat: Heartbeat,
    },
    /// Acknowledged unicast command.
    Request {
        /// Sender (car or ground station).
        src: Address,
        /// Receiver (car or ground station, never broadcast).
        dst: Address,
        /// Sender's sequence number.
        seq: u16,
        /// Application type tag.
        tag: u8,
        /// Opaque request bytes.
        payload: Payload,
    },
    /// Answer to a request (same `seq`) or to an authenticated command (low 16 bits of its counter).
    Reply {
        /// Sender.
        src: Address,
        /// Receiver (never broadcast).
        dst: Address,
        /// Sequence number being answered.
        seq: u16,
        /// Application type tag.
        tag: u8,
        /// Opaque reply bytes.
        payload: Payload,
    },
    /// Typed maneuver message, unicast or broadcast, sent a few times and deduplicated by `gseq`.
    Group {
        /// Sender.
        src: Address,
        /// Receiver or broadcast.
        dst: Address,
        /// Group number chosen by the application.
        group: u8,
        /// Sender's group-message counter (wraps).
        gseq: u8,
        /// The message.
        msg: GroupMsg,
    },
    /// Ground-station command with a keyed MAC over everything before the tag.
    AuthCommand {
        /// One car or broadcast.
        dst: Address,
        /// Monotonic counter (replay protection and reply correlation).
        counter: u32,
        /// Application type tag.
        tag: u8,
        /// Opaque command bytes.
        payload: Payload,
        /// Truncated SipHash-2-4 tag.
        mac: [u8; AUTH_TAG_LEN],
    },
    /// The ground station's heartbeat, authenticated and counted, to every car.
    GroundBeat {
        /// The ground station's session epoch.
        epoch: u32,
        /// Heartbeat counter of that epoch (replay protection).
        beat: u32,
        /// Truncated SipHash-2-4 tag.
        mac: [u8; AUTH_TAG_LEN],
    },
    /// A car asks the ground station to open a session; signed by the car.
    Hello {
        /// The car.
        src: CarId,
        /// Single-use nonce: the car's boot counter in the high 32 bits, a Hello counter in
        /// the low 32 bits.
        nonce: u64,
        /// Truncated SipHash-2-4 tag.
        mac: [u8; AUTH_TAG_LEN],
    },
    /// The ground station's answer to a [`Frame::Hello`]: the session the car joins.
    SessionOpen {
        /// The car.
        dst: CarId,
        /// The nonce of the car's Hello.
        nonce: u64,
        /// The ground station's session epoch.
        epoch: u32,
        /// Lowest command counter the car may accept in this session.
        command_min: u32,
        /// Lowest heartbeat counter the car may accept in this session.
        beat_min: u32,
        /// Truncated SipHash-2-4 tag.
        mac: [u8; AUTH_TAG_LEN],
    },
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// The next `N` bytes, with one bounds check (a field read byte by byte costs a check
    /// and a branch per byte, in every place it is inlined).
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let b = *self.buf.get(self.pos..)?.first_chunk::<N>()?;
        self.pos += N;
        Some(b)
    }
    fn u8(&mut self) -> Option<u8> {
        let b = *self.buf.get(self.pos)?;
        self.pos += 1;
        Some(b)
    }
    fn u16(&mut self) -> Option<u16> {
        self.take().map(u16::from_le_bytes)
    }
    fn u32(&mut self) -> Option<u32> {
        self.take().map(u32::from_le_bytes)
    }
    fn u64(&mut self) -> Option<u64> {
        self.take().map(u64::from_le_bytes)
    }
    fn mac(&mut self) -> Option<[u8; AUTH_TAG_LEN]> {
        self.take()
    }
    fn rest(&self) -> &'a [u8] {
        self.buf.get(self.pos..).unwrap_or(&[])
    }
}

/// A raw frame being written. Every frame fits in its [`MAX_RAW`] bytes, so the writes at
/// fixed offsets need no bounds check of their own.
pub(crate) struct Writer {
    pub(crate) buf: [u8; MAX_RAW],
    pub(crate) pos: usize,
}

impl Writer {
    pub(crate) fn new() -> Self {
        Writer {
            buf: [0; MAX_RAW],
            pos: 0,
        }
    }
    fn written(&self) -> &[u8] {
        self.buf.get(..self.pos).unwrap_or(&[])
    }
    fn bytes(&mut self, data: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + data.len();
        self.buf
            .get_mut(self.pos..end)
            .ok_or(EncodeError::BufferTooSmall)?
            .copy_from_slice(data);
        self.pos = end;
        Ok(())
    }
    fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.bytes(&[v])
    }
    fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
}

fn check_coord(v: u16, field: Field) -> Result<u16, EncodeError> {
    if v > MAX_COORD {
        Err(EncodeError::FieldOutOfRange { field })
    } else {
        Ok(v)
    }
}

fn check_heading(v: u16) -> Result<u16, EncodeError> {
    if v > MAX_HEADING_MRAD {
        Err(EncodeError::FieldOutOfRange {
            field: Field::Heading,
        })
    } else {
        Ok(v)
    }
}

/// A received pose's ranges, X first, then Y and heading.
fn check_pose(x: u16, y: u16, heading_mrad: u16) -> Result<(), FrameError> {
    let field = if x > MAX_COORD {
        Field::X
    } else if y > MAX_COORD {
        Field::Y
    } else if heading_mrad > MAX_HEADING_MRAD {
        Field::Heading
    } else {
        return Ok(());
    };
    Err(FrameError::FieldOutOfRange { field })
}

fn sender(src: Address) -> Result<Address, FrameError> {
    if src == Address::Broadcast {
        Err(FrameError::InvalidSource)
    } else {
        Ok(src)
    }
}

impl Frame {
    /// The frame's kind.
    pub fn kind(&self) -> Kind {
        match self {
            Frame::State { .. } => Kind::State,
            Frame::Heartbeat { .. } => Kind::Heartbeat,
            Frame::Request { .. } => Kind::Request,
            Frame::Reply { .. } => Kind::Reply,
            Frame::Group { .. } => Kind::Group,
            Frame::AuthCommand { .. } => Kind::AuthCommand,
            Frame::GroundBeat { .. } => Kind::GroundBeat,
            Frame::Hello { .. } => Kind::Hello,
            Frame::SessionOpen { .. } => Kind::SessionOpen,
        }
    }

    /// The sending address.
    pub fn src(&self) -> Address {
        match self {
            Frame::State { src, .. } => Address::Car(*src),
            Frame::Heartbeat { src, .. }
            | Frame::Request { src, .. }
            | Frame::Reply { src, .. }
            | Frame::Group { src, .. } => *src,
            Frame::Hello { src, .. } => Address::Car(*src),
            Frame::AuthCommand { .. } | Frame::GroundBeat { .. } | Frame::SessionOpen { .. } => {
                Address::Ground
            }
        }
    }

    /// Parse a raw (COBS-decoded) frame: CRC first, then version, kind and fields.
    ///
    /// The CRC algorithm is fixed for every protocol version, so a version error means
    /// "intact frame from other firmware", never line noise.
    // Out of line on the firmware (one call per frame heard): inlined into the radio's
    // intake it cost 396 bytes more.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    pub fn parse(raw: &[u8]) -> Result<Frame, FrameError> {
        let len = raw.len();
        if len < MIN_RAW {
            return Err(FrameError::TooShort { len });
        }
        let (data, trailer) = raw.split_at(len - CRC_LEN);
        let got = u16::from_le_bytes([trailer[0], trailer[1]]);
        let expected = crc16(data);
        if expected != got {
            return Err(FrameError::ChecksumMismatch { expected, got });
        }
        let version = data[0] >> 5;
        if version != VERSION {
            return Err(FrameError::UnsupportedVersion { got: version });
        }
        let kind = Kind::from_bits(data[0] & 0x1F)?;
        let src = Address::from_byte(data[1])?;
        let mut r = Reader { buf: data, pos: 2 };
        let bad = FrameError::BadLength { kind, len };
        let frame = match kind {
            Kind::State => {
                let src = match src {
                    Address::Car(id) => id,
                    _ => return Err(FrameError::InvalidSource),
                };
                let seq = r.u8().ok_or(bad)?;
                let x = r.u16().ok_or(bad)?;
                let y = r.u16().ok_or(bad)?;
                let heading_mrad = r.u16().ok_or(bad)?;
                let velocity_mm_s = r.u16().ok_or(bad)? as i16;
                let mode = Mode::from_byte(r.u8().ok_or(bad)?)?;
                check_pose(x, y, heading_mrad)?;
                Frame::State {
                    src,
                    seq,
                    state: CarState {
                        x,
                        y,
                        heading_mrad,
                        velocity_mm_s,
                        mode,
                    },
                }
            }
            Kind::Heartbeat => {
                let mode = Mode::from_byte(r.u8().ok_or(bad)?)?;
                let neighbours = r.u8().ok_or(bad)?;
                let uptime_s = r.u16().ok_or(bad)?;
                // The ground station's heartbeat is a GroundBeat: a plain one from address
                // 0x00 is what anybody could send.
                if src == Address::Ground {
                    return Err(FrameError::InvalidSource);
                }
                Frame::Heartbeat {
                    src: sender(src)?,
                    beat: Heartbeat {
                        mode,
                        neighbours,
                        uptime_s,
                    },
                }
            }
            Kind::Request | Kind::Reply | Kind::AuthCommand => {
                // One layout: destination, sequence number (a command's 32-bit counter), tag,
                // payload, and a command's MAC.
                let auth = kind == Kind::AuthCommand;
                if auth && src != Address::Ground {
                    return Err(FrameError::InvalidSource);
                }
                let dst = Address::from_byte(r.u8().ok_or(bad)?)?;
                // Requests and replies are unicast; commands go to cars.
                let never = if auth {
                    Address::Ground
                } else {
                    Address::Broadcast
                };
                if dst == never {
                    return Err(FrameError::InvalidDestination);
                }
                let seq = if auth {
                    r.u32()
                } else {
                    r.u16().map(u32::from)
                }
                .ok_or(bad)?;
                let tag = r.u8().ok_or(bad)?;
                let rest = r.rest();
                let mac_len = if auth { AUTH_TAG_LEN } else { 0 };
                if rest.len() < mac_len {
                    return Err(bad);
                }
                let (body, mac_bytes) = rest.split_at(rest.len() - mac_len);
                let payload = Payload::from_slice(body).map_err(|_| bad)?;
                r.pos = data.len();
                if auth {
                    let mut mac = [0u8; AUTH_TAG_LEN];
                    mac.copy_from_slice(mac_bytes);
                    Frame::AuthCommand {
                        dst,
                        counter: seq,
                        tag,
                        payload,
                        mac,
                    }
                } else {
                    let src = sender(src)?;
                    let seq = seq as u16;
                    if kind == Kind::Request {
                        Frame::Request {
                            src,
                            dst,
                            seq,
                            tag,
                            payload,
                        }
                    } else {
                        Frame::Reply {
                            src,
                            dst,
                            seq,
                            tag,
                            payload,
                        }
                    }
                }
            }
            Kind::Group => {
                let dst = Address::from_byte(r.u8().ok_or(bad)?)?;
                let group = r.u8().ok_or(bad)?;
                let gseq = r.u8().ok_or(bad)?;
                let msg = match r.u8().ok_or(bad)? {
                    1 => GroupMsg::Role {
                        role: Role::from_bits(r.u8().ok_or(bad)?)
                            .map_err(|field| FrameError::FieldOutOfRange { field })?,
                    },
                    2 => GroupMsg::Slot {
                        slot: r.u8().ok_or(bad)?,
                        count: r.u8().ok_or(bad)?,
                    },
                    3 => {
                        let x = r.u16().ok_or(bad)?;
                        let y = r.u16().ok_or(bad)?;
                        let h = r.u16().ok_or(bad)?;
                        check_pose(x, y, h)?;
                        GroupMsg::Target {
                            x,
                            y,
                            heading_mrad: h,
                        }
                    }
                    4 => GroupMsg::Start {
                        delay_ms: r.u16().ok_or(bad)?,
                    },
                    5 => GroupMsg::Stop,
                    value => return Err(FrameError::UnknownGroupMsg { value }),
                };
                Frame::Group {
                    src: sender(src)?,
                    dst,
                    group,
                    gseq,
                    msg,
                }
            }
            Kind::GroundBeat | Kind::Hello => {
                // The same layout: eight bytes (epoch and beat, or the nonce), then the tag.
                let hello = match src {
                    Address::Car(id) if kind == Kind::Hello => Some(id),
                    Address::Ground if kind == Kind::GroundBeat => None,
                    _ => return Err(FrameError::InvalidSource),
                };
                let word = r.u64().ok_or(bad)?;
                let mac = r.mac().ok_or(bad)?;
                match hello {
                    Some(src) => Frame::Hello {
                        src,
                        nonce: word,
                        mac,
                    },
                    None => Frame::GroundBeat {
                        epoch: word as u32,
                        beat: (word >> 32) as u32,
                        mac,
                    },
                }
            }
            Kind::SessionOpen => {
                if src != Address::Ground {
                    return Err(FrameError::InvalidSource);
                }
                let Address::Car(dst) = Address::from_byte(r.u8().ok_or(bad)?)? else {
                    return Err(FrameError::InvalidDestination);
                };
                Frame::SessionOpen {
                    dst,
                    nonce: r.u64().ok_or(bad)?,
                    epoch: r.u32().ok_or(bad)?,
                    command_min: r.u32().ok_or(bad)?,
                    beat_min: r.u32().ok_or(bad)?,
                    mac: r.mac().ok_or(bad)?,
                }
            }
        };
        if r.pos != data.len() {
            return Err(bad);
        }
        Ok(frame)
    }

    /// Length of the raw frame (before COBS).
    pub fn raw_len(&self) -> usize {
        2 + CRC_LEN
            + match self {
                Frame::State { .. } => 10,
                Frame::Heartbeat { .. } => 4,
                Frame::Request { payload, .. } | Frame::Reply { payload, .. } => 4 + payload.len(),
                Frame::Group { msg, .. } => {
                    4 + match msg {
                        GroupMsg::Role { .. } => 1,
                        GroupMsg::Slot { .. } => 2,
                        GroupMsg::Target { .. } => 6,
                        GroupMsg::Start { .. } => 2,
                        GroupMsg::Stop => 0,
                    }
                }
                Frame::AuthCommand { payload, .. } => 6 + payload.len() + AUTH_TAG_LEN,
                Frame::GroundBeat { .. } | Frame::Hello { .. } => 8 + AUTH_TAG_LEN,
                Frame::SessionOpen { .. } => 21 + AUTH_TAG_LEN,
            }
    }

    /// Length on air: COBS adds one byte (raw frames are far below 254 bytes), plus the delimiter.
    pub fn encoded_len(&self) -> usize {
        self.raw_len() + 2
    }

    /// Write the raw frame (with CRC) into `buf`; returns its length.
    pub fn emit_raw(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new();
        let done = self.emit_into(&mut w);
        // A field is checked before it is written: its error counts only if everything
        // written before it fits in `buf`.
        let out = buf.get_mut(..w.pos).ok_or(EncodeError::BufferTooSmall)?;
        done?;
        out.copy_from_slice(w.written());
        Ok(w.pos)
    }

    /// Write the raw frame (with CRC) into `w` from its start; on an error `w.pos` is where
    /// the field in error would have gone.
    pub(crate) fn emit_into(&self, w: &mut Writer) -> Result<(), EncodeError> {
        w.pos = 0;
        let src = self.src();
        if src == Address::Broadcast {
            return Err(EncodeError::InvalidSource);
        }
        w.u8((VERSION << 5) | self.kind() as u8)?;
        w.u8(src.to_byte())?;
        // The tag of the authenticated kinds goes last.
        let mac = match self {
            Frame::State { seq, state, .. } => {
                w.u8(*seq)?;
                w.u16(check_coord(state.x, Field::X)?)?;
                w.u16(check_coord(state.y, Field::Y)?)?;
                w.u16(check_heading(state.heading_mrad)?)?;
                w.u16(state.velocity_mm_s as u16)?;
                w.u8(state.mode.to_byte()?)?;
                None
            }
            Frame::Heartbeat { beat, .. } => {
                if src == Address::Ground {
                    return Err(EncodeError::InvalidSource);
                }
                w.u8(beat.mode.to_byte()?)?;
                w.u8(beat.neighbours)?;
                w.u16(beat.uptime_s)?;
                None
            }
            Frame::Request {
                dst,
                seq,
                tag,
                payload,
                ..
            }
            | Frame::Reply {
                dst,
                seq,
                tag,
                payload,
                ..
            } => {
                if *dst == Address::Broadcast {
                    return Err(EncodeError::InvalidDestination);
                }
                w.u8(dst.to_byte())?;
                w.u16(*seq)?;
                w.u8(*tag)?;
                w.bytes(payload)?;
                None
            }
            Frame::Group {
                dst,
                group,
                gseq,
                msg,
                ..
            } => {
                w.u8(dst.to_byte())?;
                w.u8(*group)?;
                w.u8(*gseq)?;
                w.u8(msg.type_byte())?;
                match *msg {
                    GroupMsg::Role { role } => w.u8(role as u8)?,
                    GroupMsg::Slot { slot, count } => w.bytes(&[slot, count])?,
                    GroupMsg::Target { x, y, heading_mrad } => {
                        w.u16(check_coord(x, Field::X)?)?;
                        w.u16(check_coord(y, Field::Y)?)?;
                        w.u16(check_heading(heading_mrad)?)?;
                    }
                    GroupMsg::Start { delay_ms } => w.u16(delay_ms)?,
                    GroupMsg::Stop => {}
                }
                None
            }
            Frame::AuthCommand {
                dst,
                counter,
                tag,
                payload,
                mac,
            } => {
                if *dst == Address::Ground {
                    return Err(EncodeError::InvalidDestination);
                }
                w.u8(dst.to_byte())?;
                w.bytes(&counter.to_le_bytes())?;
                w.u8(*tag)?;
                w.bytes(payload)?;
                Some(mac)
            }
            Frame::GroundBeat { epoch, beat, mac } => {
                w.bytes(&epoch.to_le_bytes())?;
                w.bytes(&beat.to_le_bytes())?;
                Some(mac)
            }
            Frame::Hello { nonce, mac, .. } => {
                w.bytes(&nonce.to_le_bytes())?;
                Some(mac)
            }
            Frame::SessionOpen {
                dst,
                nonce,
                epoch,
                command_min,
                beat_min,
                mac,
            } => {
                w.u8(dst.get())?;
                w.bytes(&nonce.to_le_bytes())?;
                w.bytes(&epoch.to_le_bytes())?;
                w.bytes(&command_min.to_le_bytes())?;
                w.bytes(&beat_min.to_le_bytes())?;
                Some(mac)
            }
        };
        if let Some(mac) = mac {
            w.bytes(mac)?;
        }
        w.u16(crc16(w.written()))
    }

    /// Write the frame as it goes on air (COBS + `0x00` delimiter); returns its length.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let mut w = Writer::new();
        self.emit_into(&mut w)?;
        let enc = cobs::try_encode(w.written(), buf).map_err(|_| EncodeError::BufferTooSmall)?;
        *buf.get_mut(enc).ok_or(EncodeError::BufferTooSmall)? = 0;
        Ok(enc + 1)
    }
}

/// Encoded frame ready for the radio UART.
pub type Encoded = Vec<u8, MAX_ENCODED>;

/// Encode a frame into an owned buffer.
pub fn encode_frame(frame: &Frame) -> Result<Encoded, EncodeError> {
    let mut buf = [0u8; MAX_ENCODED];
    let n = frame.encode(&mut buf)?;
    let bytes = buf.get(..n).ok_or(EncodeError::BufferTooSmall)?;
    Encoded::from_slice(bytes).map_err(|_| EncodeError::BufferTooSmall)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(id: u8) -> CarId {
        CarId::new(id).unwrap()
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(CRC16.checksum(b"123456789"), 0x29B1);
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(crc16(b""), 0xFFFF);
    }

    proptest::proptest! {
        #[test]
        fn nibble_crc_is_the_crates(data in proptest::collection::vec(proptest::num::u8::ANY, 0..300)) {
            proptest::prop_assert_eq!(crc16(&data), CRC16.checksum(&data));
        }
    }

    /// Hand-computed state frame: car 5, seq 7, x=320 (0x0140), y=480 (0x01E0),
    /// heading=1571 (0x0623), v=-200 (0xFF38), leader in phase 2 (0x12).
    #[test]
    fn state_frame_bytes() {
        let f = Frame::State {
            src: car(5),
            seq: 7,
            state: CarState {
                x: 320,
                y: 480,
                heading_mrad: 1571,
                velocity_mm_s: -200,
                mode: Mode {
                    role: Role::Leader,
                    phase: 2,
                },
            },
        };
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        let body = [
            0x41, 0x05, 0x07, 0x40, 0x01, 0xE0, 0x01, 0x23, 0x06, 0x38, 0xFF, 0x12,
        ];
        assert_eq!(&raw[..12], &body);
        // CRC-16/IBM-3740 of the 12 bytes above is 0x1606 (computed independently).
        assert_eq!(&raw[12..n], &[0x06, 0x16]);
        assert_eq!(n, 14);
        let mut enc = [0u8; MAX_ENCODED];
        let m = f.encode(&mut enc).unwrap();
        assert_eq!(m, STATE_FRAME_LEN);
        // No zero in the raw frame: COBS prepends one code byte = 15 (14 data + 1).
        assert_eq!(enc[0], 15);
        assert_eq!(&enc[1..15], &raw[..n]);
        assert_eq!(enc[m - 1], 0);
        assert_eq!(Frame::parse(&raw[..n]), Ok(f));
    }

    /// COBS with zeros inside: the ground station's heartbeat (src 0x00), epoch 0, beat 0x0102.
    #[test]
    fn ground_beat_cobs_bytes() {
        let f = Frame::GroundBeat {
            epoch: 0,
            beat: 0x0102,
            mac: [0x11; AUTH_TAG_LEN],
        };
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        assert_eq!(&raw[..10], &[0x47, 0x00, 0, 0, 0, 0, 0x02, 0x01, 0, 0]);
        // CRC-16/IBM-3740 of the 18 bytes before it is 0xBF02 (computed independently).
        assert_eq!(&raw[18..n], &[0x02, 0xBF]);
        let mut enc = [0u8; MAX_ENCODED];
        let m = f.encode(&mut enc).unwrap();
        assert_eq!(
            &enc[..m],
            &[
                0x02, 0x47, 0x01, 0x01, 0x01, 0x01, 0x03, 0x02, 0x01, 0x01, 0x0B, 0x11, 0x11, 0x11,
                0x11, 0x11, 0x11, 0x11, 0x11, 0x02, 0xBF, 0x00
            ]
        );
        assert_eq!(Frame::parse(&raw[..n]), Ok(f));
        // A plain heartbeat from the ground station's address is refused both ways.
        let plain = Frame::Heartbeat {
            src: Address::Ground,
            beat: Heartbeat::default(),
        };
        assert_eq!(plain.emit_raw(&mut raw), Err(EncodeError::InvalidSource));
        assert_eq!(
            Frame::parse(&with_crc(&[0x42, 0x00, 0x00, 0x03, 0x02, 0x01])),
            Err(FrameError::InvalidSource)
        );
    }

    #[test]
    fn request_bytes() {
        let f = Frame::Request {
            src: Address::Car(car(2)),
            dst: Address::Car(car(9)),
            seq: 0x1234,
            tag: 0x41,
            payload: Payload::from_slice(&[0xE8]).unwrap(),
        };
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        assert_eq!(&raw[..7], &[0x43, 0x02, 0x09, 0x34, 0x12, 0x41, 0xE8]);
        assert_eq!(n, 9);
        assert_eq!(Frame::parse(&raw[..n]), Ok(f));
    }

    #[test]
    fn auth_command_bytes() {
        let f = Frame::AuthCommand {
            dst: Address::Broadcast,
            counter: 0x0A0B0C0D,
            tag: 7,
            payload: Payload::from_slice(&[1, 2]).unwrap(),
            mac: [0x11; AUTH_TAG_LEN],
        };
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        assert_eq!(
            &raw[..10],
            &[0x46, 0x00, 0x7F, 0x0D, 0x0C, 0x0B, 0x0A, 0x07, 0x01, 0x02]
        );
        assert_eq!(&raw[10..18], &[0x11; 8]);
        assert_eq!(n, 20);
        assert_eq!(Frame::parse(&raw[..n]), Ok(f));
    }

    /// `body` and its CRC, up to a frame longer than any valid one.
    fn with_crc(body: &[u8]) -> Vec<u8, 64> {
        let mut v = Vec::<u8, 64>::from_slice(body).unwrap();
        v.extend_from_slice(&CRC16.checksum(body).to_le_bytes())
            .unwrap();
        v
    }

    #[test]
    fn typed_errors() {
        assert_eq!(
            Frame::parse(&[1, 2, 3]),
            Err(FrameError::TooShort { len: 3 })
        );
        let mut good = with_crc(&[0x42, 0x01, 0x00, 0x00, 0x00, 0x00]);
        assert!(Frame::parse(&good).is_ok());
        good[3] ^= 1;
        assert!(matches!(
            Frame::parse(&good),
            Err(FrameError::ChecksumMismatch { .. })
        ));
        assert_eq!(
            Frame::parse(&with_crc(&[0x22, 0x01, 0x00, 0x00, 0x00, 0x00])),
            Err(FrameError::UnsupportedVersion { got: 1 })
        );
        assert_eq!(
            Frame::parse(&with_crc(&[0x5F, 0x00])),
            Err(FrameError::UnknownKind { kind: 0x1F })
        );
        assert_eq!(
            Frame::parse(&with_crc(&[0x42, 0x01, 0x00])),
            Err(FrameError::BadLength {
                kind: Kind::Heartbeat,
                len: 5
            })
        );
        assert_eq!(
            Frame::parse(&with_crc(&[0x42, 0x80, 0, 0, 0, 0])),
            Err(FrameError::InvalidAddress { value: 0x80 })
        );
        // State from the ground station.
        assert_eq!(
            Frame::parse(&with_crc(&[0x41, 0x00, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])),
            Err(FrameError::InvalidSource)
        );
        // X above 14 bits.
        assert_eq!(
            Frame::parse(&with_crc(&[0x41, 0x01, 0, 0, 0x40, 0, 0, 0, 0, 0, 0, 0])),
            Err(FrameError::FieldOutOfRange { field: Field::X })
        );
        // Request to broadcast.
        assert_eq!(
            Frame::parse(&with_crc(&[0x43, 0x01, 0x7F, 0, 0, 0])),
            Err(FrameError::InvalidDestination)
        );
        // Authenticated command from a car.
        assert_eq!(
            Frame::parse(&with_crc(&[
                0x46, 0x01, 0x7F, 0, 0, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8
            ])),
            Err(FrameError::InvalidSource)
        );
        // Authenticated command to the ground station, cut into its tag, or with a payload
        // too long; requests from broadcast, to no address, or too long.
        let mut cmd = [0u8; 16];
        cmd[0] = 0x46;
        cmd[2] = 0x01;
        assert!(Frame::parse(&with_crc(&cmd)).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&cmd[..15])),
            Err(FrameError::BadLength {
                kind: Kind::AuthCommand,
                len: 17
            })
        );
        cmd[2] = 0x7F;
        assert!(Frame::parse(&with_crc(&cmd)).is_ok());
        cmd[2] = 0x80;
        assert_eq!(
            Frame::parse(&with_crc(&cmd)),
            Err(FrameError::InvalidAddress { value: 0x80 })
        );
        cmd[2] = 0x00;
        assert_eq!(
            Frame::parse(&with_crc(&cmd)),
            Err(FrameError::InvalidDestination)
        );
        assert_eq!(
            Frame::parse(&with_crc(&cmd[..4])),
            Err(FrameError::InvalidDestination)
        );
        cmd[2] = 0x01;
        for n in 2..8 {
            assert_eq!(
                Frame::parse(&with_crc(&cmd[..n])),
                Err(FrameError::BadLength {
                    kind: Kind::AuthCommand,
                    len: n + 2
                })
            );
        }
        let mut long = [0u8; 49];
        long[0] = 0x46;
        long[2] = 0x01;
        assert!(Frame::parse(&with_crc(&long[..48])).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&long)),
            Err(FrameError::BadLength {
                kind: Kind::AuthCommand,
                len: 51
            })
        );
        let mut req = [0u8; 39];
        req[0] = 0x43;
        req[1] = 0x01;
        req[2] = 0x02;
        assert!(Frame::parse(&with_crc(&req[..38])).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&req)),
            Err(FrameError::BadLength {
                kind: Kind::Request,
                len: 41
            })
        );
        for n in 3..6 {
            assert_eq!(
                Frame::parse(&with_crc(&req[..n])),
                Err(FrameError::BadLength {
                    kind: Kind::Request,
                    len: n + 2
                })
            );
        }
        req[1] = 0x7F;
        assert_eq!(
            Frame::parse(&with_crc(&req[..6])),
            Err(FrameError::InvalidSource)
        );
        assert_eq!(
            Frame::parse(&with_crc(&req[..5])),
            Err(FrameError::BadLength {
                kind: Kind::Request,
                len: 7
            })
        );
        req[0] = 0x44;
        req[2] = 0x90;
        assert_eq!(
            Frame::parse(&with_crc(&req[..6])),
            Err(FrameError::InvalidAddress { value: 0x90 })
        );
        req[2] = 0x00;
        req[1] = 0x00;
        assert!(Frame::parse(&with_crc(&req[..6])).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&[0x45, 0x01, 0x7F, 0, 0, 9])),
            Err(FrameError::UnknownGroupMsg { value: 9 })
        );
        // Session frames: a Hello from the ground station, a session opening from a car or
        // for the ground station.
        let mut hello = [0u8; 18];
        hello[0] = 0x48;
        assert_eq!(
            Frame::parse(&with_crc(&hello)),
            Err(FrameError::InvalidSource)
        );
        hello[1] = 0x7F;
        assert_eq!(
            Frame::parse(&with_crc(&hello)),
            Err(FrameError::InvalidSource)
        );
        hello[1] = 0x03;
        assert!(Frame::parse(&with_crc(&hello)).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&hello[..17])),
            Err(FrameError::BadLength {
                kind: Kind::Hello,
                len: 19
            })
        );
        // The ground station's heartbeat from a car or broadcast, or cut short.
        let mut beat = [0u8; 18];
        beat[0] = 0x47;
        beat[1] = 0x03;
        assert_eq!(
            Frame::parse(&with_crc(&beat)),
            Err(FrameError::InvalidSource)
        );
        beat[1] = 0x7F;
        assert_eq!(
            Frame::parse(&with_crc(&beat)),
            Err(FrameError::InvalidSource)
        );
        beat[1] = 0x00;
        assert!(Frame::parse(&with_crc(&beat)).is_ok());
        for n in 2..18 {
            assert_eq!(
                Frame::parse(&with_crc(&beat[..n])),
                Err(FrameError::BadLength {
                    kind: Kind::GroundBeat,
                    len: n + 2
                })
            );
        }
        let mut open = [0u8; 31];
        open[0] = 0x49;
        open[1] = 0x02;
        assert_eq!(
            Frame::parse(&with_crc(&open)),
            Err(FrameError::InvalidSource)
        );
        open[1] = 0x00;
        assert_eq!(
            Frame::parse(&with_crc(&open)),
            Err(FrameError::InvalidDestination)
        );
        open[2] = 0x03;
        assert!(Frame::parse(&with_crc(&open)).is_ok());
        assert_eq!(
            Frame::parse(&with_crc(&open[..30])),
            Err(FrameError::BadLength {
                kind: Kind::SessionOpen,
                len: 32
            })
        );
    }

    #[test]
    fn encode_rejects_out_of_range() {
        let f = Frame::State {
            src: car(1),
            seq: 0,
            state: CarState {
                heading_mrad: 6284,
                ..CarState::default()
            },
        };
        assert_eq!(
            f.encode(&mut [0u8; MAX_ENCODED]),
            Err(EncodeError::FieldOutOfRange {
                field: Field::Heading
            })
        );
        assert_eq!(
            f.encode(&mut [0u8; 4]),
            Err(EncodeError::FieldOutOfRange {
                field: Field::Heading
            })
        );
        let ok = Frame::State {
            src: car(1),
            seq: 0,
            state: CarState::default(),
        };
        assert_eq!(ok.encode(&mut [0u8; 10]), Err(EncodeError::BufferTooSmall));
        // Into a small buffer, a field error counts once every field before it was written:
        // the heading goes at offset 7, after header, source, sequence number, X and Y.
        let heading = Err(EncodeError::FieldOutOfRange {
            field: Field::Heading,
        });
        for len in 0..7 {
            assert_eq!(
                f.emit_raw(&mut [0u8; 16][..len]),
                Err(EncodeError::BufferTooSmall),
                "{len}"
            );
        }
        for len in 7..16 {
            assert_eq!(f.emit_raw(&mut [0u8; 16][..len]), heading, "{len}");
        }
        // A heartbeat from the ground station is refused after the header is written.
        let plain = Frame::Heartbeat {
            src: Address::Ground,
            beat: Heartbeat::default(),
        };
        assert_eq!(
            plain.emit_raw(&mut [0u8; 1]),
            Err(EncodeError::BufferTooSmall)
        );
        assert_eq!(
            plain.emit_raw(&mut [0u8; 2]),
            Err(EncodeError::InvalidSource)
        );
        assert_eq!(
            ok.emit_raw(&mut [0u8; 13]),
            Err(EncodeError::BufferTooSmall)
        );
        assert_eq!(ok.emit_raw(&mut [0u8; 14]), Ok(14));
    }
}
