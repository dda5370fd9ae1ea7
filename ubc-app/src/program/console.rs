//! The user's console over the radio: typed request and reply payloads.
//!
//! A console request travels as a radio-mac command (authenticated by the ground station's
//! key); the radio-mac tag says which request it is ([`Tag`]) and the payload starts with the
//! version of that request's layout: [`GROUP_VERSION`] for `GroupStart`, [`VERSION`] for every
//! other request. The car answers with a radio-mac reply carrying the same tag and a payload
//! `[VERSION, result, body...]`. LBC commands and replies are carried as
//! complete LBC messages (header, packed data, checksum, terminator; seed 3.2) so that any
//! tool speaking the LBC protocol can build and read them. Multi-byte integers are
//! little-endian. The field tables are in `docs/ubc-app.md`.

use heapless::Vec;
use lbc_link::wire::{Frame, FrameError};
use lbc_link::{Command, CommandKind, LbcMessage, Reply as LbcReply};

pub use super::camera::{BlobReport, CameraReport};

/// The group maneuver parameters a [`Request::GroupStart`] carries.
pub use maneuvers::ManeuverParams;

/// Version byte opening every request (but `GroupStart`) and every reply payload.
pub const VERSION: u8 = 1;
/// Version byte of a `GroupStart` request: 2 since it carries a law ID of the registration
/// list and that law's parameters (version 1 carried a 3-bit law selector and is refused).
pub const GROUP_VERSION: u8 = 2;
/// Largest console payload (radio-mac's `MAX_PAYLOAD`).
pub const MAX_PAYLOAD: usize = radio_mac::MAX_PAYLOAD;
/// Largest number of points in one go-to maneuver.
pub const MAX_POINTS: usize = 7;
/// Counters in one statistics page.
pub const STATS_PER_PAGE: usize = 7;
/// Statistics pages (see [`StatsPage`]).
pub const STATS_PAGES: u8 = 4;

/// Radio-mac tags of console requests (and of their replies).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Tag {
    /// Forward one LBC command and return its outcome.
    Lbc = 0x01,
    /// Vehicle and program status.
    Status = 0x02,
    /// Set the stream format the program asks of the LBC.
    StreamFormat = 0x03,
    /// Start a go-to-points maneuver.
    ManeuverStart = 0x04,
    /// Stop the maneuver (and the car).
    ManeuverStop = 0x05,
    /// One page of counters.
    Stats = 0x06,
    /// Start a group maneuver: any law of the registration list.
    GroupStart = 0x07,
    /// Next waypoint of the running group maneuver's law.
    GroupWaypoint = 0x08,
    /// The latest camera detections and the camera-follow state.
    Camera = 0x09,
    /// Start the firmware's own program loop (a program built from the template).
    ProgramStart = 0x0A,
    /// Stop it (and the car).
    ProgramStop = 0x0B,
    /// Car to ground station: something the user should know (sent as a radio-mac request).
    Notice = 0x10,
}

impl Tag {
    /// The tag with this value.
    #[must_use]
    pub fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0x01 => Tag::Lbc,
            0x02 => Tag::Status,
            0x03 => Tag::StreamFormat,
            0x04 => Tag::ManeuverStart,
            0x05 => Tag::ManeuverStop,
            0x06 => Tag::Stats,
            0x07 => Tag::GroupStart,
            0x08 => Tag::GroupWaypoint,
            0x09 => Tag::Camera,
            0x0A => Tag::ProgramStart,
            0x0B => Tag::ProgramStop,
            0x10 => Tag::Notice,
            _ => return None,
        })
    }
}

/// Why a console payload could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// The payload is empty (no version byte).
    Empty,
    /// A version this program does not speak.
    UnsupportedVersion { got: u8 },
    /// A tag this program does not know.
    UnknownTag { tag: u8 },
    /// The body has the wrong length.
    Length {
        tag: u8,
        expected: usize,
        got: usize,
    },
    /// A field is out of range.
    Field { tag: u8, offset: usize },
    /// An unknown result code.
    UnknownResult { code: u8 },
    /// The carried LBC message is not a well-formed frame.
    LbcFrame(FrameError),
    /// The carried LBC message is framed but not a valid message of the expected kind.
    LbcMessage(lbc_link::DecodeError),
    /// The group maneuver parameters do not decode.
    Params {
        tag: u8,
        error: maneuvers::DecodeError,
    },
}

/// Why a payload could not be written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The output buffer is too small.
    BufferTooSmall { needed: usize },
    /// The carried LBC message could not be written.
    Lbc(lbc_link::EncodeError),
    /// A field is out of range (e.g. more than [`MAX_POINTS`] points).
    Field,
}

/// A point of a go-to maneuver, in tracking units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Point {
    /// X, 0..=640.
    pub x: u16,
    /// Y, 0..=960.
    pub y: u16,
}

/// Points of a go-to maneuver.
pub type Points = Vec<Point, MAX_POINTS>;

/// A console request (ground station to car).
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Issue this LBC command.
    Lbc(Command),
    /// Report [`Status`].
    Status,
    /// Stream these variables (28-bit format word) in addition to the ones the program needs.
    StreamFormat(u32),
    /// Drive through these points in order, then stop.
    ManeuverStart(Points),
    /// Abort the maneuver and stop.
    ManeuverStop,
    /// Report one [`StatsPage`].
    Stats(u8),
    /// Run this group maneuver (replacing any running maneuver); the body is the
    /// [`ManeuverParams::encode`] form (law ID, options, parameters).
    GroupStart(ManeuverParams),
    /// Next waypoint of the running law, tracking units (X 0..=640, Y 0..=960).
    GroupWaypoint {
        /// X.
        x: u16,
        /// Y.
        y: u16,
    },
    /// Report the latest camera detections with blob `blob` (0: the largest), see
    /// [`CameraReport`].
    Camera {
        /// Index of the blob to include.
        blob: u8,
    },
    /// Start the program loop with these arguments (their meaning is the program's).
    ProgramStart(super::user::Args),
    /// Stop the program loop and the car.
    ProgramStop,
}

fn put(out: &mut [u8], at: usize, bytes: &[u8]) -> Result<(), EncodeError> {
    let end = at + bytes.len();
    out.get_mut(at..end)
        .ok_or(EncodeError::BufferTooSmall { needed: end })?
        .copy_from_slice(bytes);
    Ok(())
}

/// Little-endian `u16` at `at`; callers check the length first, so the `0` fallback is unused.
fn u16_at(b: &[u8], at: usize) -> u16 {
    b.get(at..)
        .and_then(<[u8]>::first_chunk)
        .map_or(0, |&w| u16::from_le_bytes(w))
}

/// Little-endian `u32` at `at`; callers check the length first, so the `0` fallback is unused.
fn u32_at(b: &[u8], at: usize) -> u32 {
    b.get(at..)
        .and_then(<[u8]>::first_chunk)
        .map_or(0, |&w| u32::from_le_bytes(w))
}

fn body(payload: &[u8], version: u8) -> Result<&[u8], DecodeError> {
    match payload.split_first() {
        None => Err(DecodeError::Empty),
        Some((&v, rest)) if v == version => Ok(rest),
        Some((&got, _)) => Err(DecodeError::UnsupportedVersion { got }),
    }
}

fn expect_len(tag: Tag, body: &[u8], expected: usize) -> Result<(), DecodeError> {
    if body.len() == expected {
        Ok(())
    } else {
        Err(DecodeError::Length {
            tag: tag as u8,
            expected,
            got: body.len(),
        })
    }
}

fn lbc_frame(bytes: &[u8]) -> Result<(u8, &[u8]), DecodeError> {
    Frame::new_checked(bytes).map_err(DecodeError::LbcFrame)?;
    // A checked frame is header, data, checksum, terminator.
    match bytes {
        [header, data @ .., _, _] => Ok((*header, data)),
        _ => Err(DecodeError::LbcFrame(FrameError::TooShort {
            len: bytes.len(),
        })),
    }
}

/// The version byte of requests with tag `t`.
fn version_of(t: Tag) -> u8 {
    if t == Tag::GroupStart {
        GROUP_VERSION
    } else {
        VERSION
    }
}

impl Request {
    /// The radio-mac tag.
    #[must_use]
    pub fn tag(&self) -> Tag {
        match self {
            Request::Lbc(_) => Tag::Lbc,
            Request::Status => Tag::Status,
            Request::StreamFormat(_) => Tag::StreamFormat,
            Request::ManeuverStart(_) => Tag::ManeuverStart,
            Request::ManeuverStop => Tag::ManeuverStop,
            Request::Stats(_) => Tag::Stats,
            Request::GroupStart(_) => Tag::GroupStart,
            Request::GroupWaypoint { .. } => Tag::GroupWaypoint,
            Request::Camera { .. } => Tag::Camera,
            Request::ProgramStart(_) => Tag::ProgramStart,
            Request::ProgramStop => Tag::ProgramStop,
        }
    }

    /// The version byte of this request's layout.
    #[must_use]
    pub fn version(&self) -> u8 {
        version_of(self.tag())
    }

    /// Writes the payload; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        put(out, 0, &[self.version()])?;
        let len = match self {
            Request::Lbc(cmd) => {
                let dst = out
                    .get_mut(1..)
                    .ok_or(EncodeError::BufferTooSmall { needed: 2 })?;
                1 + cmd.emit(dst).map_err(EncodeError::Lbc)?
            }
            Request::Status | Request::ManeuverStop | Request::ProgramStop => 1,
            Request::ProgramStart(args) => {
                put(out, 1, &[args.len() as u8])?;
                for (i, a) in args.iter().enumerate() {
                    put(out, 2 + 2 * i, &a.to_le_bytes())?;
                }
                2 + 2 * args.len()
            }
            Request::StreamFormat(bits) => {
                put(out, 1, &bits.to_le_bytes())?;
                5
            }
            Request::ManeuverStart(points) => {
                put(out, 1, &[points.len() as u8])?;
                for (i, p) in points.iter().enumerate() {
                    put(out, 2 + 4 * i, &p.x.to_le_bytes())?;
                    put(out, 4 + 4 * i, &p.y.to_le_bytes())?;
                }
                2 + 4 * points.len()
            }
            Request::Stats(page) | Request::Camera { blob: page } => {
                put(out, 1, &[*page])?;
                2
            }
            Request::GroupStart(params) => {
                let dst = out
                    .get_mut(1..)
                    .ok_or(EncodeError::BufferTooSmall { needed: 2 })?;
                1 + params.encode(dst).map_err(|e| match e {
                    maneuvers::EncodeError::BufferTooSmall { needed } => {
                        EncodeError::BufferTooSmall { needed: 1 + needed }
                    }
                    _ => EncodeError::Field,
                })?
            }
            Request::GroupWaypoint { x, y } => {
                if *x > 640 || *y > 960 {
                    return Err(EncodeError::Field);
                }
                put(out, 1, &x.to_le_bytes())?;
                put(out, 3, &y.to_le_bytes())?;
                5
            }
        };
        if len > MAX_PAYLOAD {
            return Err(EncodeError::Field);
        }
        Ok(len)
    }

    /// Reads a request from its radio-mac tag and payload.
    pub fn decode(tag: u8, payload: &[u8]) -> Result<Self, DecodeError> {
        let t = Tag::from_u8(tag).ok_or(DecodeError::UnknownTag { tag })?;
        let b = body(payload, version_of(t))?;
        Ok(match t {
            Tag::Lbc => {
                let (header, data) = lbc_frame(b)?;
                Request::Lbc(Command::decode(header, data).map_err(DecodeError::LbcMessage)?)
            }
            Tag::Status => {
                expect_len(t, b, 0)?;
                Request::Status
            }
            Tag::ManeuverStop => {
                expect_len(t, b, 0)?;
                Request::ManeuverStop
            }
            Tag::ProgramStop => {
                expect_len(t, b, 0)?;
                Request::ProgramStop
            }
            Tag::ProgramStart => {
                let n = usize::from(*b.first().ok_or(DecodeError::Length {
                    tag,
                    expected: 1,
                    got: 0,
                })?);
                if n > super::user::MAX_ARGS {
                    return Err(DecodeError::Field { tag, offset: 0 });
                }
                expect_len(t, b, 1 + 2 * n)?;
                let mut args = super::user::Args::new();
                for i in 0..n {
                    // Cannot fail: n <= MAX_ARGS.
                    let _ = args.push(u16_at(b, 1 + 2 * i) as i16);
                }
                Request::ProgramStart(args)
            }
            Tag::StreamFormat => {
                expect_len(t, b, 4)?;
                Request::StreamFormat(u32_at(b, 0))
            }
            Tag::ManeuverStart => {
                let n = usize::from(*b.first().ok_or(DecodeError::Length {
                    tag,
                    expected: 1,
                    got: 0,
                })?);
                if n == 0 || n > MAX_POINTS {
                    return Err(DecodeError::Field { tag, offset: 0 });
                }
                expect_len(t, b, 1 + 4 * n)?;
                let mut points = Points::new();
                for i in 0..n {
                    let p = Point {
                        x: u16_at(b, 1 + 4 * i),
                        y: u16_at(b, 3 + 4 * i),
                    };
                    if p.x > 640 || p.y > 960 {
                        return Err(DecodeError::Field {
                            tag,
                            offset: 1 + 4 * i,
                        });
                    }
                    // Cannot fail: n <= MAX_POINTS.
                    let _ = points.push(p);
                }
                Request::ManeuverStart(points)
            }
            Tag::Stats => {
                expect_len(t, b, 1)?;
                Request::Stats(b[0])
            }
            Tag::Camera => {
                expect_len(t, b, 1)?;
                Request::Camera { blob: b[0] }
            }
            Tag::GroupStart => Request::GroupStart(
                ManeuverParams::decode(b).map_err(|e| DecodeError::Params { tag, error: e })?,
            ),
            Tag::GroupWaypoint => {
                expect_len(t, b, 4)?;
                let (x, y) = (u16_at(b, 0), u16_at(b, 2));
                if x > 640 {
                    return Err(DecodeError::Field { tag, offset: 0 });
                }
                if y > 960 {
                    return Err(DecodeError::Field { tag, offset: 2 });
                }
                Request::GroupWaypoint { x, y }
            }
            Tag::Notice => return Err(DecodeError::UnknownTag { tag }),
        })
    }
}

/// Why the program did not carry out a request (result codes 0x01..=0x0F).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Refusal {
    /// The request could not be decoded.
    Malformed = 0x01,
    /// The request's version byte is not [`VERSION`].
    UnsupportedVersion = 0x02,
    /// The tag is not a console request.
    UnknownRequest = 0x03,
    /// Too many requests in progress; try again.
    Busy = 0x04,
    /// A motion command while the drive is disabled (send DREN first).
    DriveDisabled = 0x05,
    /// The LBC is not brought up yet.
    NotReady = 0x06,
    /// Only the authenticated ground station may do this.
    NotAuthorized = 0x07,
    /// An argument is out of range (e.g. a stream format with NOT-IN-USE bits).
    BadArgument = 0x08,
    /// A group waypoint while no group maneuver runs.
    NoGroup = 0x09,
    /// An LBC command that reads or writes the registers the car keeps to itself (the boot
    /// counter and the radio key, EEPROM 0x37..=0x3F).
    Protected = 0x0A,
    /// A group maneuver whose law ID is not in this firmware's registration list.
    UnknownLaw = 0x0B,
    /// A program start to a firmware without a program loop (the stock firmware).
    NoProgram = 0x0C,
}

impl Refusal {
    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0x01 => Refusal::Malformed,
            0x02 => Refusal::UnsupportedVersion,
            0x03 => Refusal::UnknownRequest,
            0x04 => Refusal::Busy,
            0x05 => Refusal::DriveDisabled,
            0x06 => Refusal::NotReady,
            0x07 => Refusal::NotAuthorized,
            0x08 => Refusal::BadArgument,
            0x09 => Refusal::NoGroup,
            0x0A => Refusal::Protected,
            0x0B => Refusal::UnknownLaw,
            0x0C => Refusal::NoProgram,
            _ => return None,
        })
    }
}

/// What became of an LBC command.
#[derive(Debug, Clone, PartialEq)]
pub enum LbcOutcome {
    /// The LBC's positive answer (an echo or data), result code 0x00.
    Answer(LbcReply),
    /// The LBC answered with the command's specific error, result code 0x10.
    Rejected(CommandKind),
    /// The LBC answered UNKCMD, result code 0x11.
    UnknownCommand,
    /// No answer after all retries, result code 0x12.
    TimedOut,
    /// The LBC kept reporting checksum errors, result code 0x13.
    ChecksumErrors,
}

/// Program and vehicle status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Bring-up state (see `Phase` codes in `docs/ubc-app.md`).
    pub phase: u8,
    /// [`flags`] bits.
    pub flags: u8,
    /// Car ID from READ_ID (0 until known).
    pub car_id: u8,
    /// Position, tracking units.
    pub x: u16,
    /// Position, tracking units.
    pub y: u16,
    /// Heading, mrad.
    pub heading_mrad: u16,
    /// Steering, signed mrad.
    pub steering_mrad: i16,
    /// Velocity, signed mm/s.
    pub velocity_mm_s: i16,
    /// Chip temperature, degrees Celsius (0xFF unknown).
    pub temperature_c: u8,
    /// Index of the point being driven to.
    pub maneuver_index: u8,
    /// Points in the maneuver (0: none).
    pub maneuver_len: u8,
    /// Milliseconds since the last STREAM frame (0xFFFF: none or longer).
    pub stream_age_ms: u16,
    /// Completed bring-ups.
    pub bringups: u16,
    /// LBC link failures (bring-up failures and lost streams).
    pub lbc_failures: u16,
    /// Seconds since the program started (wraps).
    pub uptime_s: u16,
    /// Group maneuver law: the [`ManeuverParams::kind`] selector (0: none).
    pub group_kind: u8,
    /// Group maneuver phase ([`maneuvers::Phase`] value, as broadcast in the mode byte).
    pub group_phase: u8,
    /// The group maneuver's convergence test holds.
    pub group_converged: bool,
    /// Distance to the group maneuver's goal, tracking units (saturated).
    pub group_error_units: u16,
}

/// Bits of [`Status::flags`].
pub mod flags {
    /// The drive is enabled (DREN acknowledged, no reset seen since).
    pub const DRIVE_ENABLED: u8 = 1 << 0;
    /// STREAM frames are arriving.
    pub const STREAMING: u8 = 1 << 1;
    /// The ground station was heard within the user-link timeout.
    pub const USER_LINK: u8 = 1 << 2;
    /// Battery low.
    pub const BATTERY_LOW: u8 = 1 << 3;
    /// Chip over temperature.
    pub const OVER_TEMPERATURE: u8 = 1 << 4;
    /// A maneuver is running.
    pub const MANEUVER: u8 = 1 << 5;
    /// The LBC link failed recently (the red LED shows it).
    pub const LBC_ERROR: u8 = 1 << 6;
    /// The pose comes from a fresh STREAM frame.
    pub const POSE_VALID: u8 = 1 << 7;
}

const STATUS_LEN: usize = 29;

impl Status {
    fn write(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let mut b = [0u8; STATUS_LEN];
        b[0] = self.phase;
        b[1] = self.flags;
        b[2] = self.car_id;
        b[3..5].copy_from_slice(&self.x.to_le_bytes());
        b[5..7].copy_from_slice(&self.y.to_le_bytes());
        b[7..9].copy_from_slice(&self.heading_mrad.to_le_bytes());
        b[9..11].copy_from_slice(&self.steering_mrad.to_le_bytes());
        b[11..13].copy_from_slice(&self.velocity_mm_s.to_le_bytes());
        b[13] = self.temperature_c;
        b[14] = self.maneuver_index;
        b[15] = self.maneuver_len;
        b[16..18].copy_from_slice(&self.stream_age_ms.to_le_bytes());
        b[18..20].copy_from_slice(&self.bringups.to_le_bytes());
        b[20..22].copy_from_slice(&self.lbc_failures.to_le_bytes());
        b[22..24].copy_from_slice(&self.uptime_s.to_le_bytes());
        b[24] = self.group_kind;
        b[25] = self.group_phase;
        b[26] = u8::from(self.group_converged);
        b[27..29].copy_from_slice(&self.group_error_units.to_le_bytes());
        put(out, 0, &b)?;
        Ok(STATUS_LEN)
    }

    /// `b` is [`STATUS_LEN`] bytes long (checked by the caller).
    fn read(b: &[u8]) -> Result<Self, DecodeError> {
        let group_converged = match b[26] {
            0 => false,
            1 => true,
            _ => {
                return Err(DecodeError::Field {
                    tag: Tag::Status as u8,
                    offset: 26,
                })
            }
        };
        Ok(Status {
            phase: b[0],
            flags: b[1],
            car_id: b[2],
            x: u16_at(b, 3),
            y: u16_at(b, 5),
            heading_mrad: u16_at(b, 7),
            steering_mrad: u16_at(b, 9) as i16,
            velocity_mm_s: u16_at(b, 11) as i16,
            temperature_c: b[13],
            maneuver_index: b[14],
            maneuver_len: b[15],
            stream_age_ms: u16_at(b, 16),
            bringups: u16_at(b, 18),
            lbc_failures: u16_at(b, 20),
            uptime_s: u16_at(b, 22),
            group_kind: b[24],
            group_phase: b[25],
            group_converged,
            group_error_units: u16_at(b, 27),
        })
    }
}

/// Statistics pages: which counters each page carries, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum StatsPage {
    /// LBC requests: sent, acked, errors, timeouts, retries, cser, unkcmd.
    LbcRequests = 0,
    /// LBC line: stream frames, unexpected, decode errors, garbage bytes, truncated,
    /// missing checksum, checksum errors.
    LbcLine = 1,
    /// Radio: rx frames, rx checksum, rx cobs, rx malformed, auth bad mac, auth replay,
    /// states sent.
    Radio = 2,
    /// Program: bring-ups, bring-up failures, streams lost, user links lost, stream decode
    /// errors, console requests, console refusals.
    Program = 3,
}

impl StatsPage {
    /// Every page, in page order.
    pub const ALL: [StatsPage; STATS_PAGES as usize] = [
        StatsPage::LbcRequests,
        StatsPage::LbcLine,
        StatsPage::Radio,
        StatsPage::Program,
    ];

    /// The page's name in reports.
    pub const fn name(self) -> &'static str {
        match self {
            StatsPage::LbcRequests => "lbc_requests",
            StatsPage::LbcLine => "lbc_line",
            StatsPage::Radio => "radio",
            StatsPage::Program => "program",
        }
    }

    /// The names of the page's counters, in the order of [`Reply::Stats`] values.
    pub const fn counters(self) -> [&'static str; STATS_PER_PAGE] {
        match self {
            StatsPage::LbcRequests => [
                "sent", "acked", "errors", "timeouts", "retries", "cser", "unkcmd",
            ],
            StatsPage::LbcLine => [
                "stream_frames",
                "unexpected",
                "decode_errors",
                "garbage_bytes",
                "truncated",
                "missing_checksum",
                "checksum_errors",
            ],
            StatsPage::Radio => [
                "rx_frames",
                "rx_checksum",
                "rx_cobs",
                "rx_malformed",
                "auth_bad_mac",
                "auth_replay",
                "states_sent",
            ],
            StatsPage::Program => [
                "bringups",
                "bringup_failures",
                "streams_lost",
                "user_links_lost",
                "stream_errors",
                "console_requests",
                "console_refusals",
            ],
        }
    }

    /// The page with number `n`.
    pub fn from_number(n: u8) -> Option<Self> {
        Self::ALL.get(usize::from(n)).copied()
    }
}

/// A console reply (car to ground station).
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// The program did not carry out the request.
    Refused(Refusal),
    /// Outcome of [`Request::Lbc`].
    Lbc(LbcOutcome),
    /// Answer to [`Request::Status`].
    Status(Status),
    /// The stream format now asked of the LBC (the requested variables plus the program's).
    StreamFormat(u32),
    /// The maneuver started with this many points.
    ManeuverStarted(u8),
    /// The maneuver was stopped.
    ManeuverStopped,
    /// The group maneuver started.
    GroupStarted,
    /// The formation leader took the waypoint.
    GroupWaypointSet,
    /// One statistics page.
    Stats {
        page: u8,
        values: Vec<u32, STATS_PER_PAGE>,
    },
    /// The camera report.
    Camera(CameraReport),
    /// The program loop started.
    ProgramStarted,
    /// The program loop stopped.
    ProgramStopped,
}

const OK: u8 = 0x00;
const LBC_REJECTED: u8 = 0x10;
const LBC_UNKNOWN: u8 = 0x11;
const LBC_TIMEOUT: u8 = 0x12;
const LBC_CSER: u8 = 0x13;

impl Reply {
    /// Writes the payload of the reply to a request with tag `tag`; returns its length.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        put(out, 0, &[VERSION])?;
        let (code, body_len) = match self {
            Reply::Refused(r) => (*r as u8, 0),
            Reply::Lbc(LbcOutcome::Answer(reply)) => {
                let dst = out
                    .get_mut(2..)
                    .ok_or(EncodeError::BufferTooSmall { needed: 3 })?;
                (OK, reply.emit(dst).map_err(EncodeError::Lbc)?)
            }
            Reply::Lbc(LbcOutcome::Rejected(kind)) => {
                put(out, 2, &[kind.error_header()])?;
                (LBC_REJECTED, 1)
            }
            Reply::Lbc(LbcOutcome::UnknownCommand) => (LBC_UNKNOWN, 0),
            Reply::Lbc(LbcOutcome::TimedOut) => (LBC_TIMEOUT, 0),
            Reply::Lbc(LbcOutcome::ChecksumErrors) => (LBC_CSER, 0),
            Reply::Status(s) => {
                let dst = out
                    .get_mut(2..)
                    .ok_or(EncodeError::BufferTooSmall { needed: 3 })?;
                (OK, s.write(dst)?)
            }
            Reply::StreamFormat(bits) => {
                put(out, 2, &bits.to_le_bytes())?;
                (OK, 4)
            }
            Reply::ManeuverStarted(n) => {
                put(out, 2, &[*n])?;
                (OK, 1)
            }
            Reply::ManeuverStopped
            | Reply::GroupStarted
            | Reply::GroupWaypointSet
            | Reply::ProgramStarted
            | Reply::ProgramStopped => (OK, 0),
            Reply::Camera(report) => {
                let dst = out
                    .get_mut(2..)
                    .ok_or(EncodeError::BufferTooSmall { needed: 3 })?;
                let n = report.write(dst).map_err(|_| EncodeError::BufferTooSmall {
                    needed: 2 + super::camera::REPORT_LEN + super::camera::BLOB_LEN,
                })?;
                (OK, n)
            }
            Reply::Stats { page, values } => {
                put(out, 2, &[*page])?;
                for (i, v) in values.iter().enumerate() {
                    put(out, 3 + 4 * i, &v.to_le_bytes())?;
                }
                (OK, 1 + 4 * values.len())
            }
        };
        put(out, 1, &[code])?;
        let len = 2 + body_len;
        if len > MAX_PAYLOAD {
            return Err(EncodeError::Field);
        }
        Ok(len)
    }

    /// Reads the reply to a request with tag `tag`.
    pub fn decode(tag: u8, payload: &[u8]) -> Result<Self, DecodeError> {
        let b = body(payload, VERSION)?;
        let (&code, b) = b.split_first().ok_or(DecodeError::Length {
            tag,
            expected: 1,
            got: 0,
        })?;
        if let Some(r) = Refusal::from_u8(code) {
            // Any request, even one with an unknown tag, can be refused.
            if !b.is_empty() {
                return Err(DecodeError::Length {
                    tag,
                    expected: 0,
                    got: b.len(),
                });
            }
            return Ok(Reply::Refused(r));
        }
        let t = Tag::from_u8(tag).ok_or(DecodeError::UnknownTag { tag })?;
        Ok(match (t, code) {
            (Tag::Lbc, OK) => {
                let (header, data) = lbc_frame(b)?;
                match LbcMessage::decode(header, data).map_err(DecodeError::LbcMessage)? {
                    LbcMessage::Reply(r) => Reply::Lbc(LbcOutcome::Answer(r)),
                    _ => return Err(DecodeError::Field { tag, offset: 0 }),
                }
            }
            (Tag::Lbc, LBC_REJECTED) => {
                expect_len(t, b, 1)?;
                match LbcMessage::decode(b[0], &[]).map_err(DecodeError::LbcMessage)? {
                    LbcMessage::Error(kind) => Reply::Lbc(LbcOutcome::Rejected(kind)),
                    _ => return Err(DecodeError::Field { tag, offset: 0 }),
                }
            }
            (Tag::Lbc, LBC_UNKNOWN | LBC_TIMEOUT | LBC_CSER) => {
                expect_len(t, b, 0)?;
                Reply::Lbc(match code {
                    LBC_UNKNOWN => LbcOutcome::UnknownCommand,
                    LBC_TIMEOUT => LbcOutcome::TimedOut,
                    _ => LbcOutcome::ChecksumErrors,
                })
            }
            (Tag::Status, OK) => {
                expect_len(t, b, STATUS_LEN)?;
                Reply::Status(Status::read(b)?)
            }
            (Tag::StreamFormat, OK) => {
                expect_len(t, b, 4)?;
                Reply::StreamFormat(u32_at(b, 0))
            }
            (Tag::ManeuverStart, OK) => {
                expect_len(t, b, 1)?;
                Reply::ManeuverStarted(b[0])
            }
            (
                Tag::ManeuverStop
                | Tag::GroupStart
                | Tag::GroupWaypoint
                | Tag::ProgramStart
                | Tag::ProgramStop,
                OK,
            ) => {
                expect_len(t, b, 0)?;
                match t {
                    Tag::GroupStart => Reply::GroupStarted,
                    Tag::GroupWaypoint => Reply::GroupWaypointSet,
                    Tag::ProgramStart => Reply::ProgramStarted,
                    Tag::ProgramStop => Reply::ProgramStopped,
                    _ => Reply::ManeuverStopped,
                }
            }
            (Tag::Stats, OK) => {
                let (&page, rest) = b.split_first().ok_or(DecodeError::Length {
                    tag,
                    expected: 1,
                    got: 0,
                })?;
                if rest.len() % 4 != 0 || rest.len() > 4 * STATS_PER_PAGE {
                    return Err(DecodeError::Length {
                        tag,
                        expected: 4 * STATS_PER_PAGE,
                        got: rest.len(),
                    });
                }
                let mut values = Vec::new();
                for c in rest.chunks_exact(4) {
                    // Cannot fail: at most STATS_PER_PAGE chunks.
                    let _ = values.push(u32_at(c, 0));
                }
                Reply::Stats { page, values }
            }
            (Tag::Camera, OK) => {
                Reply::Camera(CameraReport::read(b).map_err(|_| DecodeError::Length {
                    tag,
                    expected: super::camera::REPORT_LEN,
                    got: b.len(),
                })?)
            }
            (Tag::Notice, _) => return Err(DecodeError::UnknownTag { tag }),
            (_, code) => return Err(DecodeError::UnknownResult { code }),
        })
    }
}

/// Something the car tells the ground station unasked (radio-mac request, tag [`Tag::Notice`]);
/// the ground station answers with an empty reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Notice {
    /// The LBC stopped answering (bring-up failed or its stream stopped); the car is stopped.
    LbcLost,
    /// The LBC is brought up again after a failure.
    LbcRecovered,
    /// Battery or temperature warnings changed: bit 0 over temperature, bit 1 battery low.
    Warnings(u8),
    /// The ground station was not heard for the user-link timeout; the car was stopped.
    UserLinkLost,
    /// The go-to maneuver reached its last point.
    ManeuverDone,
    /// The go-to maneuver was aborted (LBC refused a target or the link failed).
    ManeuverAborted,
}

impl Notice {
    /// Writes the payload `[VERSION, code, arg]`; returns its length (3).
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, EncodeError> {
        let (code, arg) = match *self {
            Notice::LbcLost => (1, 0),
            Notice::LbcRecovered => (2, 0),
            Notice::Warnings(w) => (3, w),
            Notice::UserLinkLost => (4, 0),
            Notice::ManeuverDone => (5, 0),
            Notice::ManeuverAborted => (6, 0),
        };
        put(out, 0, &[VERSION, code, arg])?;
        Ok(3)
    }

    /// Reads a notice payload.
    pub fn decode(payload: &[u8]) -> Result<Self, DecodeError> {
        let tag = Tag::Notice as u8;
        let b = body(payload, VERSION)?;
        expect_len(Tag::Notice, b, 2)?;
        let notice = match (b[0], b[1]) {
            (1, _) => Notice::LbcLost,
            (2, _) => Notice::LbcRecovered,
            (3, w) if w <= 3 => Notice::Warnings(w),
            (3, _) => return Err(DecodeError::Field { tag, offset: 2 }),
            (4, _) => Notice::UserLinkLost,
            (5, _) => Notice::ManeuverDone,
            (6, _) => Notice::ManeuverAborted,
            (code, _) => return Err(DecodeError::UnknownResult { code }),
        };
        Ok(notice)
    }
}

#[cfg(test)]
mod tests;
