//! Sans-IO UBC client: one request in flight, a small queue, timeouts and retries.
//!
//! The firmware calls [`Client::send`] to queue commands, [`Client::poll`] with the
//! current time and any bytes read from the LBC UART (events arrive through a
//! callback), and [`Client::transmit`] to fetch bytes to write to the UART.
//! Replies are matched to the request in flight by header: the same header is the
//! ack, the header with bit 6 cleared is its specific error. READ_EP's two-message
//! exchange, CSER (resend), UNKCMD and STREAM frames in between replies are
//! handled here; STREAM data is decoded with the format last set by UPD_SF or
//! reported by READ_SF.

use core::time::Duration;

use heapless::Deque;

use crate::deframe::{DeframeError, Deframer, DeframerStats};
use crate::header::CommandKind;
use crate::message::{Command, DecodeError, Echo, LbcMessage, Reply};
use crate::stream::{StreamError, StreamFormat, StreamSample};
use crate::wire::MAX_FRAME_LEN;

/// Commands that can wait behind the one in flight.
pub const QUEUE_LEN: usize = 8;

/// A point in time, in microseconds since any fixed origin.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Instant(pub u64);

impl Instant {
    /// From microseconds.
    #[must_use]
    pub const fn from_micros(us: u64) -> Self {
        Instant(us)
    }

    /// From milliseconds.
    #[must_use]
    pub const fn from_millis(ms: u64) -> Self {
        Instant(ms.saturating_mul(1000))
    }

    /// Microseconds.
    #[must_use]
    pub const fn micros(self) -> u64 {
        self.0
    }

    // Out of line: a smaller image than its 64-bit arithmetic at each deadline.
    #[inline(never)]
    fn after(self, d: Duration) -> Self {
        // `d.as_micros()` saturated to u64, without 128-bit arithmetic.
        let us = d
            .as_secs()
            .saturating_mul(1_000_000)
            .saturating_add(u64::from(d.subsec_micros()));
        Instant(self.0.saturating_add(us))
    }
}

/// Timeouts and retries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub struct Config {
    /// Wait for replies that the LBC's command parser sends itself.
    pub reply_timeout: Duration,
    /// Wait for replies that go through the EEPROM task or calibration.
    pub slow_reply_timeout: Duration,
    /// Resends after a timeout or CSER before giving up.
    pub max_retries: u8,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            reply_timeout: Duration::from_millis(50),
            slow_reply_timeout: Duration::from_millis(2000),
            max_retries: 2,
        }
    }
}

impl Config {
    /// How long to wait for the reply to `kind`.
    #[must_use]
    pub fn timeout_for(&self, kind: CommandKind) -> Duration {
        use CommandKind as K;
        match kind {
            K::CalbSt | K::CalbDm | K::CalbGs | K::Cmep | K::Rsep | K::WritEp | K::ReadEp => {
                self.slow_reply_timeout
            }
            _ => self.reply_timeout,
        }
    }
}

/// Identifies a request given to [`Client::send`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Token(pub u32);

/// Why a request did not complete.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Failure {
    /// The LBC answered with the command's specific error.
    Rejected,
    /// The LBC answered UNKCMD.
    UnknownCommand(Option<Echo>),
    /// No reply after all retries.
    TimedOut,
    /// The LBC kept reporting checksum errors (CSER) after all retries.
    ChecksumErrors,
}

/// Something the client has to tell the application.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// A request succeeded. For READ_EP the reply is [`Reply::ReadEpData`].
    Done {
        token: Token,
        command: Command,
        reply: Reply,
    },
    /// A request failed.
    Failed {
        token: Token,
        command: Command,
        failure: Failure,
    },
    /// A STREAM message, decoded with the streaming format the client knows.
    Stream(Result<StreamSample, StreamError>),
    /// An UNKCMD with no request in flight.
    UnknownCommand(Option<Echo>),
    /// A well-formed message that matches no request in flight.
    Unexpected { header: u8 },
    /// A well-framed message that could not be decoded.
    Malformed(DecodeError),
    /// Framing noise or a corrupted message on the line.
    Link(DeframeError),
}

/// Error from [`Client::send`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SendError {
    /// The queue already holds [`QUEUE_LEN`] commands.
    QueueFull,
}

/// Link counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct LinkStats {
    /// Command messages put on the wire, retries included.
    pub sent: u32,
    /// Requests that completed with a positive reply.
    pub acked: u32,
    /// Specific errors received for requests.
    pub errors: u32,
    /// Reply timeouts (each one, retried or not).
    pub timeouts: u32,
    /// Resends after a timeout or CSER.
    pub retries: u32,
    /// CSER messages received.
    pub cser: u32,
    /// UNKCMD messages received.
    pub unkcmd: u32,
    /// STREAM messages received.
    pub stream_frames: u32,
    /// Messages matching no request in flight.
    pub unexpected: u32,
    /// Well-framed messages that failed to decode.
    pub decode_errors: u32,
    /// Framing counters.
    pub deframer: DeframerStats,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    AwaitReply,
    /// READ_EP: the echo arrived, the data message is pending.
    AwaitData,
}

#[derive(Debug, Clone, Copy)]
struct InFlight {
    token: Token,
    command: Command,
    phase: Phase,
    deadline: Instant,
    retries: u8,
}

/// Counts one more event; the counters wrap like the deframer's, since the LBC (or line noise)
/// decides how often they move.
fn bump(counter: &mut u32) {
    *counter = counter.wrapping_add(1);
}

/// The UBC's side of the link.
#[derive(Debug)]
pub struct Client {
    config: Config,
    deframer: Deframer,
    queue: Deque<(Token, Command), QUEUE_LEN>,
    in_flight: Option<InFlight>,
    tx: [u8; MAX_FRAME_LEN],
    tx_len: usize,
    tx_pos: usize,
    next_token: u32,
    stream_format: Option<StreamFormat>,
    stats: LinkStats,
}

impl Default for Client {
    fn default() -> Self {
        Self::new(Config::default())
    }
}

impl Client {
    /// An idle client.
    #[must_use]
    pub fn new(config: Config) -> Self {
        Self {
            config,
            deframer: Deframer::new(),
            queue: Deque::new(),
            in_flight: None,
            tx: [0; MAX_FRAME_LEN],
            tx_len: 0,
            tx_pos: 0,
            next_token: 0,
            stream_format: None,
            stats: LinkStats::default(),
        }
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Counters, framing included.
    #[must_use]
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            deframer: *self.deframer.stats(),
            ..self.stats
        }
    }

    /// The streaming format used to decode STREAM messages.
    #[must_use]
    pub fn stream_format(&self) -> Option<StreamFormat> {
        self.stream_format
    }

    /// Sets the streaming format (e.g. when the LBC is known to use a default).
    pub fn set_stream_format(&mut self, format: Option<StreamFormat>) {
        self.stream_format = format;
    }

    /// True when no request is in flight or queued.
    #[must_use]
    pub fn is_idle(&self) -> bool {
        self.in_flight.is_none() && self.queue.is_empty()
    }

    /// Requests waiting behind the one in flight.
    #[must_use]
    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// When [`Client::poll`] next has work to do without new bytes (a timeout).
    #[must_use]
    pub fn poll_at(&self) -> Option<Instant> {
        self.in_flight.map(|f| f.deadline)
    }

    /// Queues a command; it goes on the wire when the ones before it are done.
    pub fn send(&mut self, now: Instant, command: Command) -> Result<Token, SendError> {
        let token = Token(self.next_token);
        self.queue
            .push_back((token, command))
            .map_err(|_| SendError::QueueFull)?;
        self.next_token = self.next_token.wrapping_add(1);
        self.start_next(now);
        Ok(token)
    }

    /// Bytes waiting to go to the LBC.
    #[must_use]
    pub fn tx_pending(&self) -> usize {
        self.tx_len - self.tx_pos
    }

    /// Copies bytes to transmit into `buf`; returns how many.
    pub fn transmit(&mut self, buf: &mut [u8]) -> usize {
        let pending = self.tx.get(self.tx_pos..self.tx_len).unwrap_or_default();
        let mut n = 0;
        for (dst, &src) in buf.iter_mut().zip(pending) {
            *dst = src;
            n += 1;
        }
        self.tx_pos += n;
        n
    }

    /// Processes received bytes and timeouts at `now`; reports events to `on_event`.
    pub fn poll<F: FnMut(Event)>(&mut self, now: Instant, rx: &[u8], mut on_event: F) {
        let mut input = rx;
        while !input.is_empty() {
            let parsed = match self.deframer.push_slice(&mut input) {
                None => break,
                Some(Ok(msg)) => Ok(LbcMessage::parse(&msg)),
                Some(Err(e)) => Err(e),
            };
            match parsed {
                Ok(Ok(msg)) => self.handle(now, msg, &mut on_event),
                Ok(Err(e)) => {
                    bump(&mut self.stats.decode_errors);
                    on_event(Event::Malformed(e));
                }
                Err(e) => on_event(Event::Link(e)),
            }
        }
        if let Some(f) = self.in_flight {
            if now >= f.deadline {
                bump(&mut self.stats.timeouts);
                self.retry_or_fail(now, Failure::TimedOut, &mut on_event);
            }
        }
        self.start_next(now);
    }

    fn start_next(&mut self, now: Instant) {
        if self.in_flight.is_some() {
            return;
        }
        if let Some((token, command)) = self.queue.pop_front() {
            self.in_flight = Some(InFlight {
                token,
                command,
                phase: Phase::AwaitReply,
                deadline: now,
                retries: 0,
            });
            self.transmit_in_flight(now);
        }
    }

    fn transmit_in_flight(&mut self, now: Instant) {
        let Some(f) = self.in_flight.as_mut() else {
            return;
        };
        f.phase = Phase::AwaitReply;
        f.deadline = now.after(self.config.timeout_for(f.command.kind()));
        // A command always fits: the longest is 7 bytes.
        self.tx_len = f.command.emit(&mut self.tx).unwrap_or(0);
        self.tx_pos = 0;
        bump(&mut self.stats.sent);
    }

    fn retry_or_fail<F: FnMut(Event)>(&mut self, now: Instant, failure: Failure, on_event: &mut F) {
        let Some(f) = self.in_flight.as_mut() else {
            return;
        };
        if f.retries < self.config.max_retries {
            f.retries += 1;
            bump(&mut self.stats.retries);
            self.transmit_in_flight(now);
        } else {
            let failure = match failure {
                Failure::TimedOut => Failure::TimedOut,
                _ => Failure::ChecksumErrors,
            };
            self.finish(Err(failure), on_event);
        }
    }

    fn finish<F: FnMut(Event)>(&mut self, result: Result<Reply, Failure>, on_event: &mut F) {
        let Some(f) = self.in_flight.take() else {
            return;
        };
        // Drop any unsent bytes of the finished request.
        self.tx_pos = self.tx_len;
        let event = match result {
            Ok(reply) => {
                bump(&mut self.stats.acked);
                Event::Done {
                    token: f.token,
                    command: f.command,
                    reply,
                }
            }
            Err(failure) => Event::Failed {
                token: f.token,
                command: f.command,
                failure,
            },
        };
        on_event(event);
    }

    fn unexpected<F: FnMut(Event)>(&mut self, header: u8, on_event: &mut F) {
        bump(&mut self.stats.unexpected);
        on_event(Event::Unexpected { header });
    }

    fn handle<F: FnMut(Event)>(&mut self, now: Instant, msg: LbcMessage, on_event: &mut F) {
        let in_flight = self.in_flight;
        match msg {
            LbcMessage::Stream(data) => {
                bump(&mut self.stats.stream_frames);
                let sample = match self.stream_format {
                    Some(format) => data.decode(format),
                    None => Err(StreamError::UnknownFormat),
                };
                on_event(Event::Stream(sample));
            }
            LbcMessage::ChecksumError => {
                bump(&mut self.stats.cser);
                if in_flight.is_some() {
                    self.retry_or_fail(now, Failure::ChecksumErrors, on_event);
                } else {
                    self.unexpected(crate::header::CSER, on_event);
                }
            }
            LbcMessage::UnknownCommand(echo) => {
                bump(&mut self.stats.unkcmd);
                if in_flight.is_some() {
                    self.finish(Err(Failure::UnknownCommand(echo)), on_event);
                } else {
                    on_event(Event::UnknownCommand(echo));
                }
            }
            LbcMessage::Error(kind) => match in_flight {
                Some(f) if f.command.kind() == kind => {
                    bump(&mut self.stats.errors);
                    self.finish(Err(Failure::Rejected), on_event);
                }
                _ => self.unexpected(kind.error_header(), on_event),
            },
            LbcMessage::Reply(reply) => {
                let header = reply.kind().header();
                let Some(f) = in_flight.filter(|f| f.command.kind() == reply.kind()) else {
                    return self.unexpected(header, on_event);
                };
                match (f.command, f.phase, reply) {
                    // READ_EP: the echo first, then the data.
                    (Command::ReadEp(a), Phase::AwaitReply, Reply::Echo(Command::ReadEp(b)))
                        if a == b =>
                    {
                        if let Some(f) = self.in_flight.as_mut() {
                            f.phase = Phase::AwaitData;
                            f.deadline = now.after(self.config.slow_reply_timeout);
                        }
                    }
                    (Command::ReadEp(a), _, Reply::ReadEpData { address, .. }) if a == address => {
                        self.finish(Ok(reply), on_event);
                    }
                    (Command::ReadEp(_), _, _) => self.unexpected(header, on_event),
                    // An echo must repeat the command exactly.
                    (cmd, _, Reply::Echo(echo)) if echo != cmd => self.unexpected(header, on_event),
                    (_, _, reply) => {
                        match reply {
                            Reply::ReadSf(format) | Reply::Echo(Command::UpdSf(format)) => {
                                self.stream_format = Some(format);
                            }
                            _ => {}
                        }
                        self.finish(Ok(reply), on_event);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fields::{EepromAddress, Position};
    use crate::stream::SystemVariable;
    use std::vec::Vec;

    fn wire<T: Fn(&mut [u8]) -> usize>(f: T) -> Vec<u8> {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = f(&mut buf);
        buf[..n].to_vec()
    }

    fn reply(r: Reply) -> Vec<u8> {
        wire(|b| r.emit(b).unwrap())
    }

    fn lbc(m: LbcMessage) -> Vec<u8> {
        wire(|b| m.emit(b).unwrap())
    }

    fn drain(c: &mut Client) -> Vec<u8> {
        let mut buf = [0u8; 64];
        let n = c.transmit(&mut buf);
        buf[..n].to_vec()
    }

    fn poll(c: &mut Client, t: u64, rx: &[u8]) -> Vec<Event> {
        let mut ev = Vec::new();
        c.poll(Instant::from_millis(t), rx, |e| ev.push(e));
        ev
    }

    #[test]
    fn read_id_round_trip() {
        let mut c = Client::default();
        let t = c.send(Instant::from_millis(0), Command::ReadId).unwrap();
        assert_eq!(drain(&mut c), [0xE8, 0x68, 0xFF]);
        let id = crate::VehicleId::new(5).unwrap();
        let ev = poll(&mut c, 1, &reply(Reply::ReadId(id)));
        assert_eq!(
            ev,
            [Event::Done {
                token: t,
                command: Command::ReadId,
                reply: Reply::ReadId(id)
            }]
        );
        assert!(c.is_idle());
        assert_eq!(c.stats().acked, 1);
    }

    #[test]
    fn queued_commands_go_one_at_a_time() {
        let mut c = Client::default();
        c.send(Instant::from_millis(0), Command::Stop).unwrap();
        c.send(Instant::from_millis(0), Command::Init).unwrap();
        assert_eq!(drain(&mut c), [0xC0, 0x40, 0xFF]);
        assert!(drain(&mut c).is_empty());
        let ev = poll(&mut c, 1, &[0xC0, 0x40, 0xFF]);
        assert_eq!(ev.len(), 1);
        assert_eq!(drain(&mut c), [0xE0, 0x60, 0xFF]);
    }

    #[test]
    fn queue_is_bounded() {
        let mut c = Client::default();
        for _ in 0..=QUEUE_LEN {
            c.send(Instant::from_millis(0), Command::Stop).unwrap();
        }
        assert_eq!(
            c.send(Instant::from_millis(0), Command::Stop),
            Err(SendError::QueueFull)
        );
    }

    #[test]
    fn timeout_retries_then_fails() {
        let mut c = Client::default();
        c.send(Instant::from_millis(0), Command::ReadXy).unwrap();
        drain(&mut c);
        assert!(poll(&mut c, 49, &[]).is_empty());
        assert!(poll(&mut c, 50, &[]).is_empty());
        assert_eq!(drain(&mut c), [0xE9, 0x69, 0xFF]);
        assert!(poll(&mut c, 100, &[]).is_empty());
        assert_eq!(drain(&mut c), [0xE9, 0x69, 0xFF]);
        let ev = poll(&mut c, 150, &[]);
        assert!(matches!(
            ev[..],
            [Event::Failed {
                failure: Failure::TimedOut,
                ..
            }]
        ));
        let s = c.stats();
        assert_eq!((s.sent, s.timeouts, s.retries), (3, 3, 2));
    }

    #[test]
    fn cser_resends_at_once() {
        let mut c = Client::default();
        c.send(Instant::from_millis(0), Command::Sten).unwrap();
        drain(&mut c);
        assert!(poll(&mut c, 1, &lbc(LbcMessage::ChecksumError)).is_empty());
        assert_eq!(drain(&mut c), [0xE6, 0x66, 0xFF]);
        assert_eq!(c.stats().cser, 1);
        assert_eq!(c.stats().retries, 1);
    }

    #[test]
    fn specific_error_fails_the_request() {
        let mut c = Client::default();
        c.send(Instant::from_millis(0), Command::ReadAy).unwrap();
        let ev = poll(&mut c, 1, &[0xAB, 0x2B, 0xFF]);
        assert!(matches!(
            ev[..],
            [Event::Failed {
                failure: Failure::Rejected,
                command: Command::ReadAy,
                ..
            }]
        ));
    }

    #[test]
    fn unkcmd_fails_the_request() {
        let mut c = Client::default();
        c.send(Instant::from_millis(0), Command::ReadBt).unwrap();
        let ev = poll(&mut c, 1, &[0xBC, 0x6D, (0xBC ^ 0x6D) & 0x7F, 0xFF]);
        let [Event::Failed {
            failure: Failure::UnknownCommand(Some(echo)),
            ..
        }] = &ev[..]
        else {
            panic!("{ev:?}");
        };
        assert_eq!(echo.header, 0xED);
        assert_eq!(c.stats().unkcmd, 1);
    }

    #[test]
    fn read_ep_waits_for_the_data_message() {
        let mut c = Client::default();
        let addr = EepromAddress::new(0x21).unwrap();
        c.send(Instant::from_millis(0), Command::ReadEp(addr))
            .unwrap();
        let echo = reply(Reply::Echo(Command::ReadEp(addr)));
        assert_eq!(drain(&mut c), echo);
        assert!(poll(&mut c, 1, &echo).is_empty());
        let data = reply(Reply::ReadEpData {
            address: addr,
            value: 0xBEEF,
        });
        assert_eq!(
            data,
            [
                0xD1,
                0x21,
                0x5F,
                0x3B,
                0x03,
                (0xD1 ^ 0x21 ^ 0x5F ^ 0x3B ^ 0x03) & 0x7F,
                0xFF
            ]
        );
        let ev = poll(&mut c, 1500, &data);
        assert!(matches!(
            ev[..],
            [Event::Done {
                reply: Reply::ReadEpData { value: 0xBEEF, .. },
                ..
            }]
        ));
    }

    #[test]
    fn stream_between_request_and_reply_uses_the_new_format() {
        let mut c = Client::default();
        let format = crate::StreamFormat::EMPTY.with(SystemVariable::Position);
        c.send(Instant::from_millis(0), Command::UpdSf(format))
            .unwrap();
        let sample = StreamSample {
            position: Some(Position::new(1, 2).unwrap()),
            ..StreamSample::default()
        };
        let stream = wire(|b| sample.emit(format, b).unwrap());
        let mut rx = stream.clone();
        rx.extend(reply(Reply::Echo(Command::UpdSf(format))));
        rx.extend(&stream);
        let ev = poll(&mut c, 1, &rx);
        assert_eq!(ev[0], Event::Stream(Err(StreamError::UnknownFormat)));
        assert!(matches!(ev[1], Event::Done { .. }));
        assert_eq!(ev[2], Event::Stream(Ok(sample)));
        assert_eq!(c.stats().stream_frames, 2);
    }

    #[test]
    fn mismatched_echo_is_not_an_ack() {
        let mut c = Client::default();
        let a = Position::new(1, 2).unwrap();
        let b = Position::new(3, 4).unwrap();
        c.send(Instant::from_millis(0), Command::MoveXy(a)).unwrap();
        let ev = poll(&mut c, 1, &reply(Reply::Echo(Command::MoveXy(b))));
        assert_eq!(ev, [Event::Unexpected { header: 0xC1 }]);
        assert!(!c.is_idle());
    }

    #[test]
    fn line_noise_is_reported_and_counted() {
        let mut c = Client::default();
        let ev = poll(&mut c, 0, &[0x01, 0xE8, 0x05, 0x00, 0xFF]);
        assert_eq!(
            ev,
            [
                Event::Link(DeframeError::Garbage { byte: 1 }),
                Event::Link(DeframeError::ChecksumMismatch {
                    header: 0xE8,
                    expected: 0x6D,
                    got: 0
                })
            ]
        );
        assert_eq!(c.stats().deframer.errors(), 2);
    }
}
