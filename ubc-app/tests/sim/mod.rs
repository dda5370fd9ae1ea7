//! The simulated car for the program's integration tests: the program, the emulated LBC in
//! lockstep (simulated time) and a radio-mac ground station on a direct radio pipe, with an
//! optional program loop.
#![allow(dead_code)]

use std::cell::Cell;
use std::collections::VecDeque;

use lbc_emu::{Lbc, LbcConfig};
use lbc_link::Command;
use radio_mac::{Address, CarId, CarMac, Event, GroundConfig, GroundStation, Key, RequestHandle};
use ubc_app::program::console::{LbcOutcome, Notice, Reply, Request, Tag};
use ubc_app::program::user::{ProgramInput, Step, UserProgram};
use ubc_app::program::{BytePort, Clock, Config, LogEvent, LogSink, Phase, Program, DEFAULT_KEY};

pub const CAR: u8 = 7;

pub struct SimClock(pub Cell<u64>);

impl Clock for SimClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

#[derive(Default)]
pub struct Pipe {
    pub rx: VecDeque<u8>,
    pub tx: Vec<u8>,
}

impl BytePort for Pipe {
    fn read(&mut self, buf: &mut [u8]) -> usize {
        let n = buf.len().min(self.rx.len());
        for b in buf.iter_mut().take(n) {
            *b = self.rx.pop_front().unwrap_or(0);
        }
        n
    }

    fn write(&mut self, bytes: &[u8]) -> usize {
        self.tx.extend_from_slice(bytes);
        bytes.len()
    }
}

#[derive(Default)]
pub struct Log(pub Vec<(u64, LogEvent)>);

impl LogSink for Log {
    fn log(&mut self, now_us: u64, event: LogEvent) {
        self.0.push((now_us, event));
    }
}

pub struct Sim {
    pub now: u64,
    pub prog: Program,
    pub lbc: Lbc,
    pub ground: GroundStation,
    pub lbc_port: Pipe,
    pub radio_port: Pipe,
    pub log: Log,
    pub lbc_connected: bool,
    pub ground_on: bool,
    pub notices: Vec<Notice>,
    pub replies: Vec<(RequestHandle, u8, Vec<u8>)>,
    pub failed: Vec<RequestHandle>,
    /// One byte in `n` on every link direction is corrupted (0: none).
    pub noise_every: u32,
    pub seed: u32,
    /// Another car on the radio, broadcasting a fixed state (heard by the program only).
    pub other: Option<CarMac>,
    /// Every byte the ground station sent (what a listener on the channel records).
    pub tape: Vec<u8>,
    /// The firmware's program loop (`None`: the stock firmware's).
    pub user: Option<DriveTo>,
}

/// A program loop for the tests: drives to the point given by its two arguments with MOVE_XY
/// and is done within 12 units of it; counts what the program calls.
#[derive(Debug, Default)]
pub struct DriveTo {
    pub target: (u16, u16),
    pub starts: u32,
    pub stops: u32,
    pub steps: u32,
}

impl UserProgram for DriveTo {
    fn start(&mut self, _now_us: u64, args: &[i16]) {
        self.starts += 1;
        let arg = |i: usize| args.get(i).map_or(300, |&a| a as u16);
        self.target = (arg(0), arg(1));
    }

    fn step(&mut self, input: &ProgramInput<'_>) -> Step {
        self.steps += 1;
        let (x, y) = self.target;
        let dx = f64::from(x) - f64::from(input.own.x);
        let dy = f64::from(y) - f64::from(input.own.y);
        if dx.hypot(dy) <= 12.0 {
            Step::Done
        } else {
            Step::Drive(maneuvers::Command::MoveXy { x, y })
        }
    }

    fn stop(&mut self) {
        self.stops += 1;
    }

    fn progress(&self) -> (u8, u8) {
        (1, 2)
    }
}

impl Sim {
    pub fn new() -> Self {
        Self::with(Config::default())
    }

    pub fn with(cfg: Config) -> Self {
        Self::with_lbc(
            cfg,
            Lbc::with_memory_eeprom(LbcConfig::default(), CAR),
            DEFAULT_KEY,
        )
    }

    pub fn with_lbc(cfg: Config, lbc: Lbc, ground_key: [u8; 16]) -> Self {
        Sim {
            now: 0,
            prog: Program::new(cfg),
            lbc,
            ground: GroundStation::new(GroundConfig::new(Key::new(ground_key), 1)),
            lbc_port: Pipe::default(),
            radio_port: Pipe::default(),
            log: Log::default(),
            lbc_connected: true,
            ground_on: true,
            notices: Vec::new(),
            replies: Vec::new(),
            failed: Vec::new(),
            noise_every: 0,
            seed: 0x1234_5678,
            other: None,
            tape: Vec::new(),
            user: None,
        }
    }

    pub fn corrupt(&mut self, bytes: &mut [u8]) {
        if self.noise_every == 0 {
            return;
        }
        for b in bytes {
            if u32::from(self.rand()) * 256 + u32::from(self.rand()) < 65_536 / self.noise_every {
                *b ^= self.rand() | 1;
            }
        }
    }

    pub fn rand(&mut self) -> u8 {
        self.seed ^= self.seed << 13;
        self.seed ^= self.seed >> 17;
        self.seed ^= self.seed << 5;
        (self.seed >> 8) as u8
    }

    /// One simulated millisecond.
    pub fn step(&mut self) {
        self.now += 1_000;
        let now = self.now;
        let mut to_lbc: Vec<u8> = self.lbc_port.tx.drain(..).collect();
        self.corrupt(&mut to_lbc);
        if self.lbc_connected {
            self.lbc.push_rx(now, &to_lbc);
        }
        self.lbc.step_until(now);
        let mut from_lbc = Vec::new();
        self.lbc.drain_tx(now, &mut from_lbc);
        self.corrupt(&mut from_lbc);
        if self.lbc_connected {
            self.lbc_port.rx.extend(from_lbc);
        }
        let mut to_ground: Vec<u8> = self.radio_port.tx.drain(..).collect();
        self.corrupt(&mut to_ground);
        if self.ground_on {
            self.ground.push_rx(now, &to_ground);
            self.ground.poll(now);
            while let Some(ev) = self.ground.next_event() {
                match ev {
                    Event::Request(inc) if inc.tag == Tag::Notice as u8 => {
                        if let Ok(n) = Notice::decode(&inc.payload) {
                            self.notices.push(n);
                        }
                        let _ = self.ground.reply(inc.id, inc.tag, &[]);
                    }
                    Event::Reply {
                        handle,
                        tag,
                        payload,
                        ..
                    } => self.replies.push((handle, tag, payload.to_vec())),
                    Event::Failed { handle, .. } => self.failed.push(handle),
                    _ => {}
                }
            }
            let mut buf = [0u8; 256];
            loop {
                let n = self.ground.transmit(&mut buf);
                if n == 0 {
                    break;
                }
                let mut bytes = buf[..n].to_vec();
                self.tape.extend_from_slice(&bytes);
                self.corrupt(&mut bytes);
                self.radio_port.rx.extend(bytes);
            }
        }
        if let Some(o) = self.other.as_mut() {
            o.poll(now);
            let mut buf = [0u8; 256];
            loop {
                let n = o.transmit(&mut buf);
                if n == 0 {
                    break;
                }
                self.radio_port.rx.extend(&buf[..n]);
            }
        }
        let clock = SimClock(Cell::new(now));
        match self.user.as_mut() {
            Some(user) => self.prog.poll_with(
                &clock,
                &mut self.lbc_port,
                &mut self.radio_port,
                &mut self.log,
                user,
            ),
            None => self.prog.poll(
                &clock,
                &mut self.lbc_port,
                &mut self.radio_port,
                &mut self.log,
            ),
        }
    }

    pub fn run_ms(&mut self, ms: u64) {
        for _ in 0..ms {
            self.step();
        }
    }

    pub fn run_until(&mut self, max_ms: u64, done: impl Fn(&Sim) -> bool) -> bool {
        for _ in 0..max_ms {
            if done(self) {
                return true;
            }
            self.step();
        }
        done(self)
    }

    pub fn bring_up(&mut self) {
        assert!(
            self.run_until(2_000, |s| s.prog.phase() == Phase::Running),
            "no bring-up: {:?}",
            self.log.0
        );
    }

    /// Sends a console request from the ground station and waits for the car's reply.
    pub fn request(&mut self, req: &Request) -> Reply {
        let mut buf = [0u8; 32];
        let n = req.encode(&mut buf).expect("encode");
        let tag = req.tag() as u8;
        self.request_raw(tag, &buf[..n])
    }

    pub fn request_raw(&mut self, tag: u8, payload: &[u8]) -> Reply {
        let dst = Address::Car(CarId::new(CAR).unwrap());
        let h = self
            .ground
            .command(self.now, dst, tag, payload)
            .expect("ground command");
        let ok = self.run_until(5_000, |s| {
            s.replies.iter().any(|r| r.0 == h) || s.failed.contains(&h)
        });
        assert!(ok, "no answer to tag {tag:#x}");
        assert!(
            !self.failed.contains(&h),
            "request {tag:#x} failed on the radio: car {:?}, ground {:?}, log {:?}",
            self.prog.radio_stats(),
            self.ground.stats(),
            &self.log.0[self.log.0.len().saturating_sub(10)..]
        );
        let (_, rtag, payload) = self.replies.iter().find(|r| r.0 == h).unwrap().clone();
        assert_eq!(rtag, tag);
        Reply::decode(rtag, &payload).expect("reply decodes")
    }

    pub fn lbc(&mut self, cmd: Command) -> LbcOutcome {
        match self.request(&Request::Lbc(cmd)) {
            Reply::Lbc(o) => o,
            other => panic!("{cmd:?}: {other:?}"),
        }
    }

    pub fn status(&mut self) -> ubc_app::program::console::Status {
        match self.request(&Request::Status) {
            Reply::Status(s) => s,
            other => panic!("{other:?}"),
        }
    }

    pub fn logged(&self, f: impl Fn(&LogEvent) -> bool) -> usize {
        self.log.0.iter().filter(|(_, e)| f(e)).count()
    }
}
