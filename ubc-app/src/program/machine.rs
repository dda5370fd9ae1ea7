//! The program's state machine: LBC bring-up and recovery, vehicle state, console, safety.
//!
//! One [`Program::poll`] reads what both UARTs have (bounded, so neither starves the other),
//! runs the LBC client and the radio MAC, acts on their events and on its own timers, and
//! writes what fits back to the UARTs, keeping the rest for the next call.

use heapless::Vec;
use lbc_link::client::{Client, Event as LinkEvent, Failure, Instant, Token};
use lbc_link::{Command, LedPattern, Reply as LbcReply, StreamFormat, StreamSample};
use radio_mac::{Address, CarConfig, CarId, CarMac, CarState, Event as RadioEvent, IncomingId};
use radio_mac::{Mode, Role};

use super::camera::Camera;
use super::config::Config;
use super::console::{
    self, flags, LbcOutcome, Notice, Refusal, Reply, Request, Status, Tag, MAX_PAYLOAD,
};
use super::group::{lbc_command, Group};
use super::leds::LedState;
use super::maneuver::Maneuver;
use super::user::{NoProgram, UserProgram};
use super::{sat_sub, BytePort, Clock, LogSink};
use user_loop::UserState;

/// Stream variables the program always asks for: position (1), steering and velocity (2),
/// heading (4), chip status (15), target position (16), target steering and velocity (17).
pub const REQUIRED_STREAM: u32 = (1 << 1) | (1 << 2) | (1 << 4) | (1 << 15) | (1 << 16) | (1 << 17);

/// Bytes read from one UART in one poll before the other gets its turn.
const RX_BUDGET: usize = 512;
/// Requests the program can have with the LBC client at once (queue plus the one in flight).
const MAX_OWNED: usize = lbc_link::client::QUEUE_LEN + 1;
/// Staging buffer towards the radio UART.
const RADIO_TX: usize = 64;
/// Milliseconds between retries of a write that did not fit in a UART.
const TX_RETRY_US: u64 = 1_000;

mod user_loop;

/// Bring-up state (the `phase` of [`Status`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Phase {
    /// Sending the bring-up sequence.
    BringingUp = 1,
    /// Brought up; the stream keeps the vehicle state current.
    Running = 2,
    /// Bring-up failed; waiting before the next attempt.
    Backoff = 3,
}

/// Bring-up sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Step {
    Init,
    ReadId,
    /// READ_EP of the radio key registers 0x38..=0x3F, before the radio starts.
    ReadKey,
    /// READ_EP of the boot counter (register 0x37).
    ReadBoot,
    /// WRIT_EP of the incremented boot counter; once acked the radio takes the key.
    WriteBoot,
    Rsep,
    UpdSf,
    Sten,
    Dren,
}

const STEPS: [Step; 9] = [
    Step::Init,
    Step::ReadId,
    Step::ReadKey,
    Step::ReadBoot,
    Step::WriteBoot,
    Step::Rsep,
    Step::UpdSf,
    Step::Sten,
    Step::Dren,
];

/// First EEPROM register of the radio key (radio-protocol.md, key provisioning).
const KEY_REGISTER: u8 = 0x38;
/// EEPROM register of the boot counter: incremented at every start before the radio takes
/// its key (the high half of the radio's Hello nonces, `radio_mac::CarConfig::boot`).
pub const BOOT_REGISTER: u8 = 0x37;

/// Whether an LBC command reads or writes the registers the program keeps to itself: the
/// boot counter and the radio key (0x37..=0x3F). The console refuses them (`Protected`).
#[must_use]
pub fn touches_secrets(cmd: &Command) -> bool {
    let reg = match cmd {
        Command::ReadEp(a) => a.get(),
        Command::WritEp { address, .. } => address.get(),
        _ => return false,
    };
    reg >= BOOT_REGISTER
}

/// Who asked for an LBC request, so its outcome reaches the right place.
#[derive(Debug, Clone, Copy)]
enum Owner {
    BringUp,
    Console(IncomingId),
    StreamFormat(IncomingId),
    Maneuver,
    Group,
    Led(LedPattern, LedPattern),
    Stop,
    Ping,
}

/// What the program reports to its log sink.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LogEvent {
    /// Bring-up sequence started (attempt number since the last success).
    BringUpStarted { attempt: u32 },
    /// Bring-up complete.
    BringUpDone { car_id: u8 },
    /// A bring-up step failed; the next attempt follows after `retry_in_ms`.
    BringUpFailed { step: u8, retry_in_ms: u32 },
    /// No STREAM frame (or ping answer) in time while running: the car is stopped and
    /// brought up again.
    LbcLost,
    /// The LBC refused a motion command while the drive should have been enabled (it reset).
    LbcStateLost,
    /// The radio started with this car ID; `keyed`: with the key, after the LBC answered (a
    /// radio without it refuses every command).
    RadioStarted { car_id: u8, keyed: bool },
    /// The ground station was not heard in time: the car is stopped.
    UserLinkLost,
    /// The ground station is heard again.
    UserLinkRestored,
    /// Battery or temperature warnings changed.
    Warnings {
        battery_low: bool,
        over_temperature: bool,
    },
    /// A console request arrived; `refused` is the refusal code, if any.
    Console { tag: u8, refused: Option<u8> },
    /// A maneuver started.
    ManeuverStarted { points: u8 },
    /// The maneuver reached its last point.
    ManeuverDone,
    /// The maneuver was aborted.
    ManeuverAborted,
    /// A group maneuver started (the law's ID in the registration list).
    GroupStarted { kind: u8 },
    /// The group maneuver was stopped (request, link loss or a manual LBC command).
    GroupStopped,
    /// The program loop started.
    ProgramStarted,
    /// The program loop finished (it returned `Done`).
    ProgramDone,
    /// The program loop was stopped before it finished.
    ProgramStopped,
}

/// Program-level counters (statistics page 3).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Completed bring-ups.
    pub bringups: u32,
    /// Failed bring-up attempts.
    pub bringup_failures: u32,
    /// Streams lost while running.
    pub streams_lost: u32,
    /// User-link losses.
    pub user_links_lost: u32,
    /// STREAM frames that did not decode with the expected format.
    pub stream_errors: u32,
    /// Console requests received.
    pub console_requests: u32,
    /// Console requests refused.
    pub console_refusals: u32,
    /// Radio bytes dropped because the radio had not started.
    pub radio_rx_dropped: u32,
}

#[derive(Debug, Clone, Copy, Default)]
struct Vehicle {
    x: u16,
    y: u16,
    heading: u16,
    steering: i16,
    velocity: i16,
    temperature: Option<u8>,
    battery_low: bool,
    over_temperature: bool,
    have_pose: bool,
}

/// The UBC program.
// `repr(C)`: the fields lie in the order written, the small ones first, within the 2 KiB an
// instruction's offset reaches from the program's address; the radio's state (4.4 KB) last.
// In Rust's order it came second and pushed the others out of reach: three instructions for
// each access instead of one.
#[derive(Debug)]
#[repr(C)]
pub struct Program {
    started_us: Option<u64>,
    lbc_error_at_us: Option<u64>,
    last_stream_us: Option<u64>,
    last_ground_us: Option<u64>,
    retry_at_us: u64,
    next_ping_us: u64,
    step: usize,
    attempts: u32,
    lbc_failures: u32,
    lbc_tx_len: usize,
    lbc_tx_pos: usize,
    radio_tx_len: usize,
    radio_tx_pos: usize,
    boot: u16,
    car_id: Option<u8>,
    phase: Phase,
    had_failure: bool,
    drive_enabled: bool,
    streaming_wanted: bool,
    user_lost: bool,
    /// The radio runs with the key (and the boot counter was incremented).
    keyed: bool,
    leds_sent: Option<(LedPattern, LedPattern)>,
    vehicle: Vehicle,
    counters: Counters,
    cfg: Config,
    key_words: Vec<u16, 8>,
    maneuver: Maneuver,
    user: UserState,
    group: Group,
    owned: Vec<(Token, Owner), MAX_OWNED>,
    client: Client,
    lbc_tx: [u8; lbc_link::MAX_FRAME_LEN],
    radio_tx: [u8; RADIO_TX],
    mac: Option<CarMac>,
    camera: Camera,
}

/// Moves `t` back to `x` when `x` is earlier.
// Out of line: the 64-bit comparison inlined at each of the poll's deadlines made the image
// larger.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn earliest(t: &mut u64, x: u64) {
    *t = (*t).min(x);
}

/// `v` milliseconds in microseconds.
fn ms(v: u32) -> u64 {
    u64::from(v) * 1_000
}

fn is_motion(cmd: &Command) -> bool {
    matches!(
        cmd,
        Command::MoveXy(_) | Command::MoveSv(_) | Command::CalbSt | Command::CalbDm
    )
}

fn outcome(failure: &Failure, command: &Command) -> LbcOutcome {
    match failure {
        Failure::Rejected => LbcOutcome::Rejected(command.kind()),
        Failure::UnknownCommand(_) => LbcOutcome::UnknownCommand,
        Failure::TimedOut => LbcOutcome::TimedOut,
        Failure::ChecksumErrors => LbcOutcome::ChecksumErrors,
    }
}

/// How close to a poll's start its state broadcast must be due for the poll to look at the
/// clock between its inputs and send the broadcast when it comes, in microseconds: a poll
/// with many inputs (a batch of radio frames, an authenticated ground frame, the control law)
/// can take this long, and on a full channel a broadcast written more than about 0.35 ms late
/// pushes every later one back (`docs/radio-protocol.md`, "Keeping the slot").
pub const STATE_WATCH_US: u64 = 2_000;

/// When a radio frame read in a poll that began at `now` counts as heard: when its delimiter
/// arrived, if the port knows (`end_us`), else `now`. A frame that ended after the poll began
/// (while it ran) keeps its own time, bounded by the clock (`clock_now`, read only then):
/// taking it as heard at `now` would date it early, and the slot schedule follows those times
/// (a follower whose reference's frames are dated early writes its own early, into the slot
/// before).
fn heard_at(end_us: Option<u64>, now: u64, clock_now: impl FnOnce() -> u64) -> u64 {
    match end_us {
        Some(t) if t > now => t.min(clock_now()),
        Some(t) => t,
        None => now,
    }
}

impl Program {
    /// A program that starts bringing the LBC up at its first poll.
    #[must_use]
    pub fn new(cfg: Config) -> Self {
        Self {
            cfg,
            client: Client::default(),
            mac: None,
            started_us: None,
            phase: Phase::Backoff,
            step: 0,
            retry_at_us: 0,
            attempts: 0,
            had_failure: false,
            lbc_error_at_us: None,
            lbc_failures: 0,
            car_id: None,
            drive_enabled: false,
            streaming_wanted: false,
            last_stream_us: None,
            next_ping_us: 0,
            vehicle: Vehicle::default(),
            maneuver: Maneuver::default(),
            group: Group::default(),
            camera: Camera::default(),
            user: UserState::default(),
            last_ground_us: None,
            user_lost: false,
            leds_sent: None,
            key_words: Vec::new(),
            keyed: false,
            boot: 0,
            owned: Vec::new(),
            counters: Counters::default(),
            lbc_tx: [0; lbc_link::MAX_FRAME_LEN],
            lbc_tx_len: 0,
            lbc_tx_pos: 0,
            radio_tx: [0; RADIO_TX],
            radio_tx_len: 0,
            radio_tx_pos: 0,
        }
    }

    /// The detections of camera frame `sequence`, processed at `now_us` by the board layer
    /// (which owns the frame grabber); they feed the console's camera report and the
    /// camera-follow maneuver.
    pub fn on_camera_frame(
        &mut self,
        now_us: u64,
        sequence: u32,
        detections: &vision::blobs::Detections,
    ) {
        self.camera.on_frame(now_us, sequence, detections);
    }

    /// The camera state.
    #[must_use]
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Bring-up state.
    #[must_use]
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Whether the program believes the LBC's drive is enabled.
    #[must_use]
    pub fn drive_enabled(&self) -> bool {
        self.drive_enabled
    }

    /// The go-to maneuver.
    #[must_use]
    pub fn maneuver(&self) -> &Maneuver {
        &self.maneuver
    }

    /// The group maneuver.
    #[must_use]
    pub fn group(&self) -> &Group {
        &self.group
    }

    /// Program counters.
    #[must_use]
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// LBC link counters.
    #[must_use]
    pub fn lbc_stats(&self) -> lbc_link::client::LinkStats {
        self.client.stats()
    }

    /// Radio counters, once the radio runs.
    #[must_use]
    pub fn radio_stats(&self) -> Option<radio_mac::Stats> {
        self.mac.as_ref().map(|m| *m.stats())
    }

    /// The stream format asked of the LBC.
    #[must_use]
    pub fn stream_format(&self) -> StreamFormat {
        StreamFormat::new(REQUIRED_STREAM | self.cfg.extra_stream)
            .unwrap_or(StreamFormat::new(REQUIRED_STREAM).unwrap_or(StreamFormat::EMPTY))
    }

    /// Status as the console reports it, at `now_us`.
    #[must_use]
    pub fn status(&self, now_us: u64) -> Status {
        let v = &self.vehicle;
        let mut f = 0;
        let stream_age = self.last_stream_us.map(|t| sat_sub(now_us, t));
        let fresh = stream_age.is_some_and(|a| a <= ms(self.cfg.stream_timeout_ms));
        let mut set = |on: bool, bit: u8| {
            if on {
                f |= bit;
            }
        };
        set(self.drive_enabled, flags::DRIVE_ENABLED);
        set(self.phase == Phase::Running && fresh, flags::STREAMING);
        set(self.user_link(now_us), flags::USER_LINK);
        set(v.battery_low, flags::BATTERY_LOW);
        set(v.over_temperature, flags::OVER_TEMPERATURE);
        set(
            self.maneuver.active() || self.group.active() || self.user.running,
            flags::MANEUVER,
        );
        set(self.lbc_error(now_us), flags::LBC_ERROR);
        set(v.have_pose && fresh, flags::POSE_VALID);
        let (index, len) = match self.maneuver.state() {
            super::ManeuverState::Driving { index } => (index, self.maneuver.points().len() as u8),
            _ if self.user.running => self.user.progress,
            _ => (0, 0),
        };
        let sat16 = |x: u64| u16::try_from(x).unwrap_or(u16::MAX);
        let g = self.group.status();
        Status {
            phase: self.phase as u8,
            flags: f,
            car_id: self.car_id.unwrap_or(0),
            x: v.x,
            y: v.y,
            heading_mrad: v.heading,
            steering_mrad: v.steering,
            velocity_mm_s: v.velocity,
            temperature_c: v.temperature.unwrap_or(0xFF),
            maneuver_index: index,
            maneuver_len: len,
            stream_age_ms: stream_age.map_or(u16::MAX, |a| sat16(a / 1_000)),
            bringups: self.counters.bringups.min(0xFFFF) as u16,
            lbc_failures: self.lbc_failures.min(0xFFFF) as u16,
            uptime_s: (sat_sub(now_us, self.started_us.unwrap_or(now_us)) / 1_000_000) as u16,
            group_kind: self.group.law_id(),
            group_phase: g.phase.bits(),
            group_converged: g.converged,
            group_error_units: g.error_units,
        }
    }

    fn user_link(&self, now: u64) -> bool {
        self.last_ground_us
            .is_some_and(|t| sat_sub(now, t) <= ms(self.cfg.user_link_timeout_ms))
    }

    fn lbc_error(&self, now: u64) -> bool {
        self.lbc_error_at_us
            .is_some_and(|t| sat_sub(now, t) < ms(self.cfg.error_led_ms))
    }

    /// Runs everything due at the clock's time: reads both UARTs, handles events and timers,
    /// writes what fits.
    pub fn poll<C, L, R, S>(&mut self, clock: &C, lbc: &mut L, radio: &mut R, log: &mut S)
    where
        C: Clock + ?Sized,
        L: BytePort + ?Sized,
        R: BytePort + ?Sized,
        S: LogSink + ?Sized,
    {
        self.poll_with(clock, lbc, radio, log, &mut NoProgram);
    }

    /// [`Program::poll`] with a program loop ([`UserProgram`]), which runs once per new
    /// STREAM sample while the ground station has it started.
    // Out of line on the firmware: inlined into the main loop, whose stack frame holds the
    // whole program (6.6 KB), it reached its fields and temporaries beyond the 2 KiB of an
    // instruction's offset, three instructions each time: 1.5 KB more code.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    pub fn poll_with<C, L, R, S, U>(
        &mut self,
        clock: &C,
        lbc: &mut L,
        radio: &mut R,
        log: &mut S,
        program: &mut U,
    ) where
        C: Clock + ?Sized,
        L: BytePort + ?Sized,
        R: BytePort + ?Sized,
        S: LogSink + ?Sized,
        U: UserProgram + ?Sized,
    {
        self.user.present = U::PRESENT;
        let now = clock.now_us();
        if self.started_us.is_none() {
            self.started_us = Some(now);
            self.retry_at_us = now;
            if let Some(id) = self.cfg.car_id {
                self.start_radio(now, id, false, log);
            }
        }
        // The radio first: a state broadcast due now goes to the UART before any input is
        // looked at, and the schedule learns how long that took (its slot timing).
        self.send_state(now, clock, radio);
        // One due while this poll runs goes out between the inputs, on time (see
        // `STATE_WATCH_US`).
        let mut state_due = self
            .next_state_due(now)
            .filter(|&d| d > now && d - now <= STATE_WATCH_US);
        let mut now = now;
        let mut buf = [0u8; 64];
        let mut budget = RX_BUDGET;
        while budget > 0 {
            let len = budget.min(buf.len());
            let (n, _) = lbc.read_frame(buf.get_mut(..len).unwrap_or_default());
            if n == 0 {
                break;
            }
            budget -= n;
            self.state_if_due(&mut state_due, &mut now, clock, radio);
            // One message at most per call, so its events all fit (see `feed_lbc`).
            for part in buf
                .get(..n)
                .unwrap_or_default()
                .split_inclusive(|&b| b == lbc_link::header::TERMINATOR)
            {
                self.feed_lbc(now, part, log);
            }
        }
        self.feed_lbc(now, &[], log);

        let mut budget = RX_BUDGET;
        while budget > 0 {
            let len = budget.min(buf.len());
            let (n, end_us) = radio.read_frame(buf.get_mut(..len).unwrap_or_default());
            if n == 0 {
                break;
            }
            budget -= n;
            self.state_if_due(&mut state_due, &mut now, clock, radio);
            let at = heard_at(end_us, now, || clock.now_us());
            match self.mac.as_mut() {
                Some(m) => m.push_rx(at, buf.get(..n).unwrap_or(&buf)),
                None => self.counters.radio_rx_dropped += n as u32,
            }
        }
        if let Some(m) = self.mac.as_mut() {
            m.poll(now);
        }
        while let Some(ev) = self.mac.as_mut().and_then(CarMac::next_event) {
            self.on_radio(now, ev, log);
        }
        self.state_if_due(&mut state_due, &mut now, clock, radio);
        self.timers(now, log);
        if U::PRESENT {
            self.run_user(now, program, log);
        }
        // Commands queued by the handlers above go out in this same poll.
        self.feed_lbc(now, &[], log);
        self.flush(lbc, radio);
    }

    /// When the car's next state broadcast is due to be written (same clock), once its radio
    /// is up and it has a state to send.
    pub fn next_state_due(&mut self, now_us: u64) -> Option<u64> {
        self.mac.as_mut()?.next_state_due(now_us)
    }

    /// Polls the radio at `now` and, when that queued the state broadcast, writes it to the
    /// radio UART at once and tells the schedule when the write began.
    fn send_state<C, R>(&mut self, now: u64, clock: &C, radio: &mut R)
    where
        C: Clock + ?Sized,
        R: BytePort + ?Sized,
    {
        let Some(m) = self.mac.as_mut() else {
            return;
        };
        let sent = m.stats().states_sent;
        m.poll(now);
        if m.stats().states_sent != sent {
            self.flush_radio(radio);
            let at = clock.now_us();
            if let Some(m) = self.mac.as_mut() {
                m.state_written(at);
            }
        }
    }

    /// Between the inputs of a poll: when the state broadcast `due` (set while it is near) has
    /// come, sends it and moves the poll's time `now` on to the clock's.
    fn state_if_due<C, R>(&mut self, due: &mut Option<u64>, now: &mut u64, clock: &C, radio: &mut R)
    where
        C: Clock + ?Sized,
        R: BytePort + ?Sized,
    {
        let Some(d) = *due else {
            return;
        };
        let t = clock.now_us();
        if t >= d {
            *due = None;
            *now = t.max(*now);
            self.send_state(*now, clock, radio);
        }
    }

    /// The time (same clock) at which [`Program::poll`] next has work without new bytes.
    pub fn poll_at(&mut self, now_us: u64) -> u64 {
        let mut t = u64::MAX;
        let mut at = |x: u64| earliest(&mut t, x);
        if let Some(i) = self.client.poll_at() {
            at(i.micros());
        }
        if let Some(m) = self.mac.as_mut() {
            at(m.poll_at(now_us));
        } else if let Some(s) = self.started_us {
            at(s + ms(self.cfg.radio_fallback_ms));
        }
        match self.phase {
            Phase::Backoff => at(self.retry_at_us),
            Phase::Running if self.streaming_wanted => {
                if let Some(s) = self.last_stream_us {
                    at(s + ms(self.cfg.stream_timeout_ms) + 1);
                }
            }
            Phase::Running => at(self.next_ping_us),
            Phase::BringingUp => {}
        }
        if let (Some(g), false) = (self.last_ground_us, self.user_lost) {
            at(g + ms(self.cfg.user_link_timeout_ms) + 1);
        }
        if let Some(e) = self.lbc_error_at_us {
            if now_us < e + ms(self.cfg.error_led_ms) {
                at(e + ms(self.cfg.error_led_ms));
            }
        }
        if self.lbc_tx_pos < self.lbc_tx_len || self.radio_tx_pos < self.radio_tx_len {
            at(now_us + TX_RETRY_US);
        }
        if self.started_us.is_none() {
            at(now_us);
        }
        t.max(now_us)
    }

    // ----- LBC side ---------------------------------------------------------------------

    fn feed_lbc<S: LogSink + ?Sized>(&mut self, now: u64, bytes: &[u8], log: &mut S) {
        // The events the program acts on: a message's outcome and a timeout, so one call
        // with at most one message end yields at most two. Noise and stray messages are
        // counted by the client's statistics.
        let mut events: Vec<LinkEvent, 4> = Vec::new();
        self.client.poll(Instant(now), bytes, |e| {
            if matches!(
                e,
                LinkEvent::Done { .. } | LinkEvent::Failed { .. } | LinkEvent::Stream(_)
            ) {
                let _ = events.push(e);
            }
        });
        // Oldest first: reversed, then popped from the end.
        events.reverse();
        while let Some(e) = events.pop() {
            self.on_link(now, e, log);
        }
    }

    fn send(&mut self, now: u64, cmd: Command, owner: Owner) -> bool {
        if self.owned.is_full() {
            return false;
        }
        match self.client.send(Instant(now), cmd) {
            Ok(token) => {
                // Cannot fail: checked above.
                let _ = self.owned.push((token, owner));
                true
            }
            Err(_) => false,
        }
    }

    /// Sends `STOP` to the LBC, if the client takes it.
    // Out of line: one call instead of the command and its owner built at each use.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    fn send_stop(&mut self, now: u64) {
        let _ = self.send(now, Command::Stop, Owner::Stop);
    }

    fn take_owner(&mut self, token: Token) -> Option<Owner> {
        let i = self.owned.iter().position(|(t, _)| *t == token)?;
        // The last entry swapped into the hole: `swap_remove` moves it with `ptr::copy`,
        // which may overlap and would link `memmove` into the firmware.
        let mut item = self.owned.pop()?;
        if let Some(slot) = self.owned.get_mut(i) {
            core::mem::swap(slot, &mut item);
        }
        Some(item.1)
    }

    fn on_link<S: LogSink + ?Sized>(&mut self, now: u64, e: LinkEvent, log: &mut S) {
        match e {
            LinkEvent::Done {
                token,
                command,
                reply,
            } => {
                self.track_effect(&command, &reply);
                match self.take_owner(token) {
                    Some(Owner::BringUp) => self.bringup_step_done(now, &reply, log),
                    Some(Owner::Console(id)) => {
                        self.respond(id, Tag::Lbc as u8, &Reply::Lbc(LbcOutcome::Answer(reply)));
                    }
                    Some(Owner::StreamFormat(id)) => {
                        let bits = self.stream_format().bits();
                        self.respond(id, Tag::StreamFormat as u8, &Reply::StreamFormat(bits));
                    }
                    Some(Owner::Led(g, r)) => self.leds_sent = Some((g, r)),
                    Some(Owner::Maneuver | Owner::Group | Owner::Stop | Owner::Ping) | None => {}
                }
            }
            LinkEvent::Failed {
                token,
                command,
                failure,
            } => match self.take_owner(token) {
                Some(Owner::BringUp) => {
                    // A refused READ_EP of the key is a failure like any other: without the
                    // key the car cannot tell a provisioned EEPROM from a blank one.
                    if command == Command::Rsep && failure == Failure::Rejected {
                        // Invalid EEPROM parameters: keep running with the LBC's own.
                        self.bringup_step_done(now, &LbcReply::Echo(command), log);
                    } else {
                        self.bringup_failed(now, log);
                    }
                }
                Some(Owner::Console(id)) => {
                    self.respond(id, Tag::Lbc as u8, &Reply::Lbc(outcome(&failure, &command)));
                    self.check_refused_motion(now, &command, &failure, log);
                }
                Some(Owner::StreamFormat(id)) => {
                    self.respond(
                        id,
                        Tag::StreamFormat as u8,
                        &Reply::Lbc(outcome(&failure, &command)),
                    );
                }
                Some(Owner::Maneuver) => {
                    if self.maneuver.active() {
                        self.maneuver.abort();
                        log.log(now, LogEvent::ManeuverAborted);
                        self.notice(now, Notice::ManeuverAborted);
                    }
                    self.check_refused_motion(now, &command, &failure, log);
                }
                Some(Owner::Group) => {
                    // The next sample sends again; a refusal means the LBC reset.
                    self.group.unsent();
                    self.camera.unsent();
                    self.check_refused_motion(now, &command, &failure, log);
                }
                Some(Owner::Ping) if failure == Failure::TimedOut => {
                    if self.phase == Phase::Running {
                        self.lbc_lost(now, log);
                    }
                }
                Some(Owner::Led(..) | Owner::Stop | Owner::Ping) | None => {}
            },
            LinkEvent::Stream(Ok(sample)) => self.on_sample(now, &sample, log),
            LinkEvent::Stream(Err(_)) => self.counters.stream_errors += 1,
            _ => {}
        }
    }

    /// Keeps the program's picture of the LBC in step with commands that change it.
    fn track_effect(&mut self, command: &Command, reply: &LbcReply) {
        match command {
            Command::Dren => self.drive_enabled = true,
            Command::Drds | Command::Init => {
                self.drive_enabled = false;
                self.leds_sent = None;
                if *command == Command::Init {
                    self.streaming_wanted = false;
                }
            }
            Command::Sten => self.streaming_wanted = true,
            Command::Stds => self.streaming_wanted = false,
            Command::UpdSf(f) if f.bits() == 0 => self.streaming_wanted = false,
            _ => {}
        }
        if let LbcReply::ReadId(id) = reply {
            self.car_id = Some(id.get());
        }
        if self.streaming_wanted && self.last_stream_us.is_none() {
            self.last_stream_us = self.started_us;
        }
    }

    /// A motion command refused while the drive should be on means the LBC lost its state.
    fn check_refused_motion<S: LogSink + ?Sized>(
        &mut self,
        now: u64,
        command: &Command,
        failure: &Failure,
        log: &mut S,
    ) {
        if is_motion(command)
            && *failure == Failure::Rejected
            && self.drive_enabled
            && self.phase == Phase::Running
            && !matches!(command, Command::CalbSt | Command::CalbDm)
        {
            log.log(now, LogEvent::LbcStateLost);
            self.lbc_lost(now, log);
        }
    }

    fn start_bringup<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        self.phase = Phase::BringingUp;
        self.step = 0;
        self.key_words.clear();
        self.drive_enabled = false;
        self.attempts += 1;
        log.log(
            now,
            LogEvent::BringUpStarted {
                attempt: self.attempts,
            },
        );
        self.send_step(now, log);
    }

    fn send_step<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        while self.keyed
            && matches!(
                STEPS.get(self.step),
                Some(Step::ReadKey | Step::ReadBoot | Step::WriteBoot)
            )
        {
            self.step += 1;
        }
        let Some(&step) = STEPS.get(self.step) else {
            return self.bringup_failed(now, log);
        };
        let cmd = match step {
            Step::Init => Command::Init,
            Step::ReadId => Command::ReadId,
            Step::ReadKey => {
                let reg = KEY_REGISTER + self.key_words.len() as u8;
                match lbc_link::EepromAddress::new(reg) {
                    Ok(a) => Command::ReadEp(a),
                    Err(_) => return self.bringup_failed(now, log),
                }
            }
            Step::ReadBoot => match lbc_link::EepromAddress::new(BOOT_REGISTER) {
                Ok(a) => Command::ReadEp(a),
                Err(_) => return self.bringup_failed(now, log),
            },
            Step::WriteBoot => match lbc_link::UserRegister::new(BOOT_REGISTER) {
                Ok(address) => Command::WritEp {
                    address,
                    value: self.boot,
                },
                Err(_) => return self.bringup_failed(now, log),
            },
            Step::Rsep => Command::Rsep,
            Step::UpdSf => Command::UpdSf(self.stream_format()),
            Step::Sten => Command::Sten,
            Step::Dren => Command::Dren,
        };
        if !self.send(now, cmd, Owner::BringUp) {
            self.bringup_failed(now, log);
        }
    }

    fn bringup_step_done<S: LogSink + ?Sized>(&mut self, now: u64, reply: &LbcReply, log: &mut S) {
        if self.phase != Phase::BringingUp {
            return;
        }
        match (STEPS.get(self.step), reply) {
            (Some(Step::ReadKey), LbcReply::ReadEpData { value, .. }) => {
                // Cannot fail: the step ends once eight words are read.
                let _ = self.key_words.push(*value);
                if !self.key_words.is_full() {
                    self.send_step(now, log);
                    return;
                }
            }
            (Some(Step::ReadBoot), LbcReply::ReadEpData { value, .. }) => {
                // An erased register reads 0xFFFF and starts the count at 0; the count
                // stops below 0xFFFF, so no boot number ever comes back.
                self.boot = value.wrapping_add(1);
                if self.boot == u16::MAX {
                    return self.bringup_failed(now, log);
                }
            }
            (Some(Step::WriteBoot), _) => {
                // The new boot count is in the EEPROM: the radio may take the key.
                let id = self.car_id.unwrap_or(self.cfg.fallback_car_id);
                self.start_radio(now, id, true, log);
            }
            (Some(Step::ReadKey | Step::ReadBoot), _) => return self.bringup_failed(now, log),
            _ => {}
        }
        self.step += 1;
        if self.step < STEPS.len() {
            self.send_step(now, log);
            return;
        }
        self.phase = Phase::Running;
        self.attempts = 0;
        self.counters.bringups += 1;
        self.drive_enabled = true;
        self.streaming_wanted = true;
        self.last_stream_us = Some(now);
        self.leds_sent = None;
        log.log(
            now,
            LogEvent::BringUpDone {
                car_id: self.car_id.unwrap_or(0),
            },
        );
        if self.had_failure {
            self.had_failure = false;
            self.notice(now, Notice::LbcRecovered);
        }
    }

    fn bringup_failed<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        self.counters.bringup_failures += 1;
        self.lbc_failures += 1;
        self.lbc_error_at_us = Some(now);
        let shift = self.attempts.saturating_sub(1).min(5);
        let delay = (self.cfg.bringup_backoff_ms << shift).min(self.cfg.bringup_backoff_max_ms);
        self.phase = Phase::Backoff;
        self.retry_at_us = now + ms(delay);
        log.log(
            now,
            LogEvent::BringUpFailed {
                step: self.step as u8,
                retry_in_ms: delay,
            },
        );
        if !self.had_failure {
            self.had_failure = true;
            self.notice(now, Notice::LbcLost);
        }
    }

    fn lbc_lost<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        self.counters.streams_lost += 1;
        self.lbc_failures += 1;
        self.lbc_error_at_us = Some(now);
        log.log(now, LogEvent::LbcLost);
        self.send_stop(now);
        self.stop_maneuvers(now, log);
        if let Some(m) = self.mac.as_mut() {
            // Heartbeats take over from the state broadcast: they must not advertise the
            // maneuver that just stopped.
            m.clear_state();
            m.set_mode(Mode::default());
        }
        self.vehicle.have_pose = false;
        if !self.had_failure {
            self.had_failure = true;
            self.notice(now, Notice::LbcLost);
        }
        self.start_bringup(now, log);
    }

    fn on_sample<S: LogSink + ?Sized>(&mut self, now: u64, s: &StreamSample, log: &mut S) {
        self.last_stream_us = Some(now);
        let v = &mut self.vehicle;
        if let Some(p) = s.position {
            v.x = p.x.get();
            v.y = p.y.get();
            v.have_pose = true;
        }
        if let Some(h) = s.heading {
            v.heading = h.get();
        }
        if let Some(sv) = s.steer_velocity {
            v.steering = sv.steering.get();
            v.velocity = sv.velocity.get();
        }
        if let Some(c) = s.chip_status {
            v.temperature = Some(c.temperature.get());
            let w = c.warnings;
            if (w.battery_low, w.over_temperature) != (v.battery_low, v.over_temperature) {
                v.battery_low = w.battery_low;
                v.over_temperature = w.over_temperature;
                log.log(
                    now,
                    LogEvent::Warnings {
                        battery_low: w.battery_low,
                        over_temperature: w.over_temperature,
                    },
                );
                let bits = u8::from(w.over_temperature) | (u8::from(w.battery_low) << 1);
                self.notice(now, Notice::Warnings(bits));
            }
        }
        if s.position.is_some() {
            let (x, y) = (self.vehicle.x, self.vehicle.y);
            match self.maneuver.update(x, y, self.cfg.arrive_radius) {
                Some(Some(p)) => self.drive_to(now, p),
                Some(None) => {
                    self.send_stop(now);
                    log.log(now, LogEvent::ManeuverDone);
                    self.notice(now, Notice::ManeuverDone);
                }
                None => {}
            }
        }
        let id = self.mac.as_ref().map_or(0, |m| m.id().get());
        if s.position.is_some() && self.phase == Phase::Running && self.drive_enabled {
            self.step_group(now, id);
            self.user.sample = true;
        }
        if let Some(m) = self.mac.as_mut() {
            let v = &self.vehicle;
            let mode = if self.group.active() {
                self.group.mode(id)
            } else {
                Mode {
                    role: Role::Idle,
                    phase: u8::from(self.maneuver.active()),
                }
            };
            m.set_state(CarState {
                x: v.x,
                y: v.y,
                heading_mrad: v.heading,
                velocity_mm_s: v.velocity,
                mode,
            });
        }
    }

    /// One control period of the group maneuver; its command goes to the LBC when the
    /// group's gate lets it through and no earlier one is still queued.
    // Out of line on the firmware (one call per control sample): inlined into `feed_lbc`,
    // the controller's temporaries made it 640 bytes larger.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    fn step_group(&mut self, now: u64, id: u8) {
        let v = &self.vehicle;
        let own = maneuvers::CarPose {
            x: v.x,
            y: v.y,
            heading_mrad: v.heading,
            velocity_mm_s: v.velocity,
        };
        let may_send = !self.owned.iter().any(|(_, o)| matches!(o, Owner::Group));
        let table = self.mac.as_ref().map(CarMac::neighbours);
        if let Some(m) = self.group.step(now, id, own, table, may_send) {
            if !self.send(now, lbc_command(m), Owner::Group) {
                self.group.unsent();
            }
        }
        // Camera follow: the controller holds; the camera's law drives through the same gate
        // rules and the same LBC client slot.
        if self.camera.following() {
            if let Some(c) = self.camera.step(now, may_send) {
                let m = maneuvers::Command::MoveSv {
                    steering_mrad: c.steering_mrad,
                    velocity_mm_s: c.velocity_mm_s,
                };
                if !self.send(now, lbc_command(m), Owner::Group) {
                    self.camera.unsent();
                }
            }
        }
    }

    /// Aborts the go-to maneuver and stops the group maneuver, whichever runs (the caller
    /// stops the car).
    fn stop_maneuvers<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        if self.maneuver.active() {
            self.maneuver.abort();
            log.log(now, LogEvent::ManeuverAborted);
        }
        self.stop_group(now, log);
        if self.user.running {
            self.user.running = false;
            self.user.stop = true;
            log.log(now, LogEvent::ProgramStopped);
        }
    }

    /// Stops a running group maneuver (the caller stops the car).
    fn stop_group<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        self.camera.stop_follow();
        if self.group.active() {
            self.group.stop();
            log.log(now, LogEvent::GroupStopped);
        }
    }

    fn drive_to(&mut self, now: u64, p: console::Point) {
        match lbc_link::Position::new(p.x, p.y) {
            Ok(pos) => {
                let _ = self.send(now, Command::MoveXy(pos), Owner::Maneuver);
            }
            Err(_) => self.maneuver.abort(),
        }
    }

    // ----- timers -----------------------------------------------------------------------

    // Out of line on the firmware, like `on_radio`: 68 bytes less.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    fn timers<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        if self.mac.is_none() {
            if let Some(s) = self.started_us {
                if now >= s + ms(self.cfg.radio_fallback_ms) {
                    // Without the key: the car is heard (and reports the LBC failure) but
                    // takes no command until the LBC gave it its key.
                    self.start_radio(now, self.cfg.fallback_car_id, false, log);
                }
            }
        }
        match self.phase {
            Phase::Backoff if now >= self.retry_at_us => self.start_bringup(now, log),
            Phase::Running if self.streaming_wanted => {
                let last = self.last_stream_us.unwrap_or(now);
                if sat_sub(now, last) > ms(self.cfg.stream_timeout_ms) {
                    self.lbc_lost(now, log);
                }
            }
            Phase::Running => {
                let pinging = self.owned.iter().any(|(_, o)| matches!(o, Owner::Ping));
                if now >= self.next_ping_us && !pinging {
                    self.next_ping_us = now + ms(self.cfg.ping_interval_ms);
                    let _ = self.send(now, Command::ReadId, Owner::Ping);
                }
            }
            _ => {}
        }
        if let (Some(g), false) = (self.last_ground_us, self.user_lost) {
            if sat_sub(now, g) > ms(self.cfg.user_link_timeout_ms) {
                self.user_lost = true;
                self.counters.user_links_lost += 1;
                log.log(now, LogEvent::UserLinkLost);
                self.stop_maneuvers(now, log);
                self.send_stop(now);
                self.notice(now, Notice::UserLinkLost);
            }
        }
        if self.phase == Phase::Running
            && !self.owned.iter().any(|(_, o)| matches!(o, Owner::Led(..)))
        {
            let (g, r) = LedState {
                running: true,
                user_link: self.user_link(now),
                user_link_lost: self.user_lost,
                over_temperature: self.vehicle.over_temperature,
                battery_low: self.vehicle.battery_low,
                lbc_error: self.lbc_error(now),
            }
            .patterns();
            if self.leds_sent != Some((g, r)) {
                let _ = self.send(now, Command::WritLed { green: g, red: r }, Owner::Led(g, r));
            }
        }
    }

    // ----- radio side -------------------------------------------------------------------

    fn start_radio<S: LogSink + ?Sized>(&mut self, now: u64, id: u8, keyed: bool, log: &mut S) {
        let Some(car) = CarId::new(id).or(CarId::new(self.cfg.fallback_car_id)) else {
            return;
        };
        let mut c = CarConfig::new(car);
        c.key = keyed.then(|| self.radio_key());
        c.boot = u32::from(self.boot);
        c.seed = (now as u32) ^ u32::from(car.get());
        self.mac = Some(CarMac::new(c));
        self.keyed = keyed;
        log.log(
            now,
            LogEvent::RadioStarted {
                car_id: car.get(),
                keyed,
            },
        );
    }

    /// The key provisioned in EEPROM registers 0x38..=0x3F when all eight were read and they
    /// are not blank (all 0x0000 or all 0xFFFF), else the configured key.
    fn radio_key(&self) -> radio_mac::Key {
        let w = &self.key_words;
        let blank = w.iter().all(|&x| x == 0) || w.iter().all(|&x| x == 0xFFFF);
        match <[u16; 8]>::try_from(w.as_slice()) {
            Ok(words) if !blank => radio_mac::Key::from_eeprom_words(words),
            _ => self.cfg.key.clone(),
        }
    }

    fn ground_heard<S: LogSink + ?Sized>(&mut self, now: u64, log: &mut S) {
        self.last_ground_us = Some(now);
        if self.user_lost {
            self.user_lost = false;
            log.log(now, LogEvent::UserLinkRestored);
        }
    }

    // Out of line on the firmware (one call per radio event): inlined into the poll, the
    // console's request and reply temporaries made it 600 bytes larger.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    fn on_radio<S: LogSink + ?Sized>(&mut self, now: u64, ev: RadioEvent, log: &mut S) {
        match ev {
            RadioEvent::Heartbeat {
                from: Address::Ground,
                ..
            } => self.ground_heard(now, log),
            RadioEvent::Request(inc) => {
                let authorized = inc.id.counter.is_some() && inc.id.from == Address::Ground;
                if authorized {
                    self.ground_heard(now, log);
                }
                self.counters.console_requests += 1;
                let refused = self.console(now, inc.id, inc.tag, &inc.payload, authorized, log);
                if let Some(r) = refused {
                    self.counters.console_refusals += 1;
                    self.respond(inc.id, inc.tag, &Reply::Refused(r));
                }
                log.log(
                    now,
                    LogEvent::Console {
                        tag: inc.tag,
                        refused: refused.map(|r| r as u8),
                    },
                );
            }
            _ => {}
        }
    }

    /// Carries out one console request; returns a refusal to send instead of an answer.
    fn console<S: LogSink + ?Sized>(
        &mut self,
        now: u64,
        id: IncomingId,
        tag: u8,
        payload: &[u8],
        authorized: bool,
        log: &mut S,
    ) -> Option<Refusal> {
        let req = match Request::decode(tag, payload) {
            Ok(r) => r,
            Err(console::DecodeError::UnsupportedVersion { .. }) => {
                return Some(Refusal::UnsupportedVersion)
            }
            Err(console::DecodeError::UnknownTag { .. }) => return Some(Refusal::UnknownRequest),
            Err(console::DecodeError::Params {
                error: maneuvers::DecodeError::UnknownLaw { .. },
                ..
            }) => return Some(Refusal::UnknownLaw),
            Err(console::DecodeError::Params { .. }) => return Some(Refusal::BadArgument),
            Err(_) => return Some(Refusal::Malformed),
        };
        if !authorized && req != Request::Status {
            return Some(Refusal::NotAuthorized);
        }
        match req {
            Request::Status => {
                let s = self.status(now);
                self.respond(id, Tag::Status as u8, &Reply::Status(s));
            }
            Request::Stats(page) => {
                let Some(values) = self.stats_page(page) else {
                    return Some(Refusal::BadArgument);
                };
                self.respond(id, Tag::Stats as u8, &Reply::Stats { page, values });
            }
            Request::Camera { blob } => {
                let report = self.camera.report(blob);
                self.respond(id, Tag::Camera as u8, &Reply::Camera(report));
            }
            Request::Lbc(cmd) => {
                if touches_secrets(&cmd) {
                    return Some(Refusal::Protected);
                }
                if is_motion(&cmd) && !self.drive_enabled {
                    return Some(Refusal::DriveDisabled);
                }
                if is_motion(&cmd) || cmd == Command::Stop {
                    self.stop_maneuvers(now, log);
                }
                // The user takes the drive away from a group maneuver too.
                if matches!(cmd, Command::Drds | Command::Init) {
                    self.stop_group(now, log);
                }
                if !self.send(now, cmd, Owner::Console(id)) {
                    return Some(Refusal::Busy);
                }
            }
            Request::StreamFormat(bits) => {
                let Ok(fmt) = StreamFormat::new(bits | REQUIRED_STREAM) else {
                    return Some(Refusal::BadArgument);
                };
                // A refused request (Busy) leaves the configured format as it was.
                if self.phase == Phase::Running {
                    if !self.send(now, Command::UpdSf(fmt), Owner::StreamFormat(id)) {
                        return Some(Refusal::Busy);
                    }
                    self.last_stream_us = Some(now);
                } else {
                    self.respond(
                        id,
                        Tag::StreamFormat as u8,
                        &Reply::StreamFormat(fmt.bits()),
                    );
                }
                self.cfg.extra_stream = bits;
            }
            Request::ManeuverStart(points) => {
                if self.phase != Phase::Running {
                    return Some(Refusal::NotReady);
                }
                if !self.drive_enabled {
                    return Some(Refusal::DriveDisabled);
                }
                let n = points.len() as u8;
                self.stop_group(now, log);
                if let Some(p) = self.maneuver.start(points) {
                    self.drive_to(now, p);
                }
                log.log(now, LogEvent::ManeuverStarted { points: n });
                self.respond(id, Tag::ManeuverStart as u8, &Reply::ManeuverStarted(n));
            }
            Request::ManeuverStop => {
                self.stop_maneuvers(now, log);
                self.send_stop(now);
                self.respond(id, Tag::ManeuverStop as u8, &Reply::ManeuverStopped);
            }
            Request::GroupStart(params) => {
                if self.phase != Phase::Running {
                    return Some(Refusal::NotReady);
                }
                if !self.drive_enabled {
                    return Some(Refusal::DriveDisabled);
                }
                self.stop_maneuvers(now, log);
                if params.is_idle() {
                    self.send_stop(now);
                } else {
                    self.group.start(params);
                    if let Some(maneuvers::AnyLaw::CameraFollow(c)) = self.group.law() {
                        self.camera
                            .start_follow(c.marker, c.distance_units, c.speed_mm_s);
                    }
                    log.log(now, LogEvent::GroupStarted { kind: params.law() });
                }
                self.respond(id, Tag::GroupStart as u8, &Reply::GroupStarted);
            }
            Request::GroupWaypoint { x, y } => {
                if !self.group.set_waypoint(x, y) {
                    return Some(Refusal::NoGroup);
                }
                self.respond(id, Tag::GroupWaypoint as u8, &Reply::GroupWaypointSet);
            }
            Request::ProgramStart(args) => return self.program_start(now, id, args, log),
            Request::ProgramStop => {
                self.stop_maneuvers(now, log);
                self.send_stop(now);
                self.respond(id, Tag::ProgramStop as u8, &Reply::ProgramStopped);
            }
        }
        None
    }

    fn stats_page(&self, page: u8) -> Option<Vec<u32, { console::STATS_PER_PAGE }>> {
        let l = self.client.stats();
        let d = l.deframer;
        let r = self.radio_stats().unwrap_or_default();
        let c = self.counters;
        let values: [u32; 7] = match console::StatsPage::from_number(page)? {
            console::StatsPage::LbcRequests => [
                l.sent, l.acked, l.errors, l.timeouts, l.retries, l.cser, l.unkcmd,
            ],
            console::StatsPage::LbcLine => [
                l.stream_frames,
                l.unexpected,
                l.decode_errors,
                d.garbage_bytes,
                d.truncated,
                d.missing_checksum,
                d.checksum_errors,
            ],
            console::StatsPage::Radio => [
                r.rx_frames,
                r.rx_checksum,
                r.rx_cobs,
                r.rx_malformed,
                r.auth_bad_mac,
                r.auth_replay,
                r.states_sent,
            ],
            console::StatsPage::Program => [
                c.bringups,
                c.bringup_failures,
                c.streams_lost,
                c.user_links_lost,
                c.stream_errors,
                c.console_requests,
                c.console_refusals,
            ],
        };
        Some(values.iter().copied().collect())
    }

    fn respond(&mut self, id: IncomingId, tag: u8, reply: &Reply) {
        let mut buf = [0u8; MAX_PAYLOAD];
        let Ok(n) = reply.encode(&mut buf) else {
            return;
        };
        if let Some(m) = self.mac.as_mut() {
            // A broadcast command has no reply; a full queue loses this one (the ground
            // station retries and gets the cached answer).
            let _ = m.reply(id, tag, &buf[..n]);
        }
    }

    fn notice(&mut self, now: u64, n: Notice) {
        let mut buf = [0u8; 4];
        let Ok(len) = n.encode(&mut buf) else {
            return;
        };
        if let Some(m) = self.mac.as_mut() {
            let _ = m.request(now, Address::Ground, Tag::Notice as u8, &buf[..len]);
        }
    }

    // ----- output -----------------------------------------------------------------------

    fn flush<L: BytePort + ?Sized, R: BytePort + ?Sized>(&mut self, lbc: &mut L, radio: &mut R) {
        loop {
            if self.lbc_tx_pos == self.lbc_tx_len {
                self.lbc_tx_len = self.client.transmit(&mut self.lbc_tx);
                self.lbc_tx_pos = 0;
                if self.lbc_tx_len == 0 {
                    break;
                }
            }
            let pending = self
                .lbc_tx
                .get(self.lbc_tx_pos..self.lbc_tx_len)
                .unwrap_or_default();
            let n = lbc.write(pending);
            if n == 0 {
                break;
            }
            self.lbc_tx_pos += n;
        }
        self.flush_radio(radio);
    }

    fn flush_radio<R: BytePort + ?Sized>(&mut self, radio: &mut R) {
        loop {
            if self.radio_tx_pos == self.radio_tx_len {
                self.radio_tx_len = match self.mac.as_mut() {
                    Some(m) => m.transmit(&mut self.radio_tx),
                    None => 0,
                };
                self.radio_tx_pos = 0;
                if self.radio_tx_len == 0 {
                    break;
                }
            }
            let pending = self
                .radio_tx
                .get(self.radio_tx_pos..self.radio_tx_len)
                .unwrap_or_default();
            let n = radio.write(pending);
            if n == 0 {
                break;
            }
            self.radio_tx_pos += n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::heard_at;

    #[test]
    fn a_frame_is_heard_when_its_delimiter_arrived() {
        let never = || panic!("the clock is read only for a frame that ended after `now`");
        // Ended before the poll began: its own time.
        assert_eq!(heard_at(Some(900), 1_000, never), 900);
        assert_eq!(heard_at(Some(1_000), 1_000, never), 1_000);
        // No stamp: the poll's time.
        assert_eq!(heard_at(None, 1_000, never), 1_000);
        // Ended while the poll ran: its own time, not the poll's start.
        assert_eq!(heard_at(Some(1_250), 1_000, || 1_300), 1_250);
        // A stamp beyond the clock is bounded by it.
        assert_eq!(heard_at(Some(5_000), 1_000, || 1_300), 1_300);
    }
}
