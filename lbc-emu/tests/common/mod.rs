//! A lockstep test bench: lbc-link's UBC client talking to the emulated LBC in simulated time.
#![allow(dead_code)]

use lbc_emu::{Lbc, LbcConfig};
use lbc_link::client::{Client, Event, Failure, Instant};
use lbc_link::{Command, Deframer, LbcMessage, Reply, StreamSample};

/// Simulation step, us.
pub const STEP_US: u64 = 1000;

pub struct Bench {
    pub lbc: Lbc,
    pub client: Client,
    pub now: u64,
    /// Events other than the completion of a request (streams, link noise), in order.
    pub events: Vec<(u64, Event)>,
    done: Vec<Event>,
    raw_mode: bool,
    raw_rx: Vec<(u64, u8)>,
}

impl Bench {
    pub fn new(cfg: LbcConfig) -> Self {
        Self::with_lbc(Lbc::with_memory_eeprom(cfg, 7))
    }

    pub fn with_lbc(lbc: Lbc) -> Self {
        Self {
            lbc,
            client: Client::default(),
            now: 0,
            events: Vec::new(),
            done: Vec::new(),
            raw_mode: false,
            raw_rx: Vec::new(),
        }
    }

    /// Advances by `us`, moving bytes both ways every millisecond.
    pub fn run_for(&mut self, us: u64) {
        let end = self.now + us;
        while self.now < end {
            self.now = (self.now + STEP_US).min(end);
            let mut tx = [0u8; 64];
            let n = self.client.transmit(&mut tx);
            self.lbc.push_rx(self.now, &tx[..n]);
            self.lbc.step_until(self.now);
            let mut rx = Vec::new();
            while let Some((t, b)) = self.lbc.pop_tx(self.now) {
                rx.push(b);
                if self.raw_mode {
                    self.raw_rx.push((t, b));
                }
            }
            if self.raw_mode {
                continue;
            }
            let now = self.now;
            let (events, done) = (&mut self.events, &mut self.done);
            self.client
                .poll(Instant::from_micros(now), &rx, |e| match e {
                    Event::Done { .. } | Event::Failed { .. } => done.push(e),
                    other => events.push((now, other)),
                });
        }
    }

    /// Sends `cmd` through the client and runs until it completes (at most 5 s).
    pub fn request(&mut self, cmd: Command) -> Result<Reply, Failure> {
        let token = self
            .client
            .send(Instant::from_micros(self.now), cmd)
            .expect("client queue has room");
        for _ in 0..5000 {
            self.run_for(STEP_US);
            if let Some(i) = self.done.iter().position(|e| match e {
                Event::Done { token: t, .. } | Event::Failed { token: t, .. } => *t == token,
                _ => false,
            }) {
                return match self.done.remove(i) {
                    Event::Done { reply, .. } => Ok(reply),
                    Event::Failed { failure, .. } => Err(failure),
                    _ => unreachable!(),
                };
            }
        }
        panic!("request {cmd:?} never completed");
    }

    /// Sends `cmd` and expects the LBC to repeat it.
    pub fn echo(&mut self, cmd: Command) {
        assert_eq!(self.request(cmd), Ok(Reply::Echo(cmd)), "{cmd:?}");
    }

    /// Sends raw bytes (bypassing the client) and returns every byte the LBC sent in the next
    /// `wait_us`, with times.
    pub fn raw_exchange(&mut self, bytes: &[u8], wait_us: u64) -> Vec<(u64, u8)> {
        self.raw_mode = true;
        self.raw_rx.clear();
        self.lbc.push_rx(self.now, bytes);
        self.run_for(wait_us);
        self.raw_mode = false;
        std::mem::take(&mut self.raw_rx)
    }

    /// Like [`Bench::raw_exchange`], returning only the bytes.
    pub fn raw(&mut self, bytes: &[u8]) -> Vec<u8> {
        self.raw_exchange(bytes, 20_000)
            .into_iter()
            .map(|(_, b)| b)
            .collect()
    }

    pub fn streams(&self) -> Vec<(u64, StreamSample)> {
        self.events
            .iter()
            .filter_map(|(t, e)| match e {
                Event::Stream(Ok(s)) => Some((*t, *s)),
                _ => None,
            })
            .collect()
    }

    /// DREN after INIT.
    pub fn enable(&mut self) {
        self.echo(Command::Init);
        self.echo(Command::Dren);
    }
}

/// Splits raw LBC output into decoded messages.
pub fn decode_all(bytes: &[u8]) -> Vec<LbcMessage> {
    let mut d = Deframer::new();
    let mut out = Vec::new();
    for &b in bytes {
        if let Some(r) = d.push(b) {
            out.push(LbcMessage::parse(&r.expect("well-framed")).expect("decodes"));
        }
    }
    out
}

/// A raw message with a correct checksum.
pub fn frame(header: u8, fields: &[(u32, u8)]) -> Vec<u8> {
    let mut data = [0u8; 64];
    let n = lbc_link::pack::pack(fields, &mut data).expect("fits");
    let mut out = vec![header];
    out.extend_from_slice(&data[..n]);
    out.push(lbc_link::checksum(header, &data[..n]));
    out.push(0xFF);
    out
}

/// Distance from the car's true position to (x, y) in tracking units.
pub fn distance_units(lbc: &Lbc, x: f64, y: f64) -> f64 {
    let p = lbc.vehicle().pose();
    (p.x_mm / 2.5 - x).hypot(p.y_mm / 2.5 - y)
}
