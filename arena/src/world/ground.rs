//! The ground station inside the world: a `radio_mac::GroundStation` on its own node of the
//! radio medium, stepped at every quantum boundary. It carries the runner's console requests
//! (one authenticated command at a time), acknowledges the cars' notices, and records the
//! state broadcasts it hears.

use super::{GroundCounters, WorldError, WorldEvent};
use crate::engine::Nanos;
use radio_mac::{Address, CarId, CarState, Event, GroundConfig, GroundStation, Key, RequestHandle};
use std::collections::HashMap;
use std::time::Duration;
use ubc_app::program::console::{self, Reply, Request};

/// How a request ended, before decoding.
#[derive(Debug, Clone)]
enum Outcome {
    Reply(u8, Vec<u8>),
    Failed,
}

/// A console request on its way (see [`crate::world::World::try_request`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PendingReply {
    id: u8,
    handle: RequestHandle,
}

impl PendingReply {
    /// The car asked.
    pub fn car(&self) -> u8 {
        self.id
    }
}

/// The world's ground station.
#[derive(Debug)]
pub struct Ground {
    station: GroundStation,
    waiting: Vec<RequestHandle>,
    outcomes: HashMap<RequestHandle, Outcome>,
    /// Counters for the summary.
    pub counters: GroundCounters,
    /// Latest state and number of states heard per car index.
    pub states: Vec<(Option<CarState>, u64)>,
    index: HashMap<u8, usize>,
    buf: Vec<u8>,
}

impl Ground {
    /// A ground station for cars `ids` with the command `key`.
    pub fn new(ids: &[u8], key: [u8; 16], seed: u64) -> Self {
        let mut gcfg = GroundConfig::new(Key::new(key), 1);
        gcfg.retry.max_us = 1_000_000;
        gcfg.retry.max_attempts = 10;
        gcfg.seed = (seed as u32) ^ 0x5A5A;
        Ground {
            station: GroundStation::new(gcfg),
            waiting: Vec::new(),
            outcomes: HashMap::new(),
            counters: GroundCounters::default(),
            states: vec![(None, 0); ids.len()],
            index: ids.iter().enumerate().map(|(k, &id)| (id, k)).collect(),
            buf: vec![0; 1024],
        }
    }

    /// Protocol counters of the station.
    pub fn stats(&self) -> radio_mac::Stats {
        *self.station.stats()
    }

    /// Sends `req` to car `id` at `now`; `Ok(None)` while another command is on its way.
    pub fn try_request(
        &mut self,
        now: Nanos,
        id: u8,
        req: &Request,
    ) -> Result<Option<PendingReply>, WorldError> {
        let car = CarId::new(id).ok_or(WorldError::BadCar { id })?;
        let mut buf = [0u8; console::MAX_PAYLOAD];
        let n = req.encode(&mut buf).map_err(WorldError::Encode)?;
        match self
            .station
            .command(now / 1000, Address::Car(car), req.tag() as u8, &buf[..n])
        {
            Ok(handle) => {
                self.waiting.push(handle);
                self.counters.requests += 1;
                Ok(Some(PendingReply { id, handle }))
            }
            Err(radio_mac::SendError::Busy) | Err(radio_mac::SendError::TxQueueFull) => Ok(None),
            Err(err) => Err(WorldError::Send(err)),
        }
    }

    /// The outcome of `p` once known (taken: a second call gives `None`).
    pub fn poll(&mut self, p: &PendingReply) -> Option<Result<Reply, WorldError>> {
        match self.outcomes.remove(&p.handle)? {
            Outcome::Reply(tag, payload) => {
                Some(Reply::decode(tag, &payload).map_err(WorldError::BadReply))
            }
            Outcome::Failed => Some(Err(WorldError::NoReply { id: p.id })),
        }
    }

    /// Feeds what the ground node received, runs the station to `now`, records what it
    /// heard, and returns the bytes it sends.
    pub fn step(&mut self, now: Nanos, rx: &[u8], events: &mut Vec<WorldEvent>) -> &[u8] {
        let now_us = now / 1000;
        let at = Duration::from_nanos(now);
        if !rx.is_empty() {
            self.station.push_rx(now_us, rx);
        }
        self.station.poll(now_us);
        while let Some(ev) = self.station.next_event() {
            match ev {
                // Cars report with requests (notices); an empty reply acknowledges them.
                Event::Request(inc)
                    if !inc.id.broadcast && self.station.reply(inc.id, inc.tag, &[]).is_ok() =>
                {
                    self.counters.notices += 1;
                    if let Address::Car(id) = inc.id.from {
                        let what = match console::Notice::decode(&inc.payload) {
                            Ok(n) => format!("notice {n:?}"),
                            Err(_) => format!("notice tag {}", inc.tag),
                        };
                        events.push(WorldEvent {
                            at,
                            car: id.get(),
                            what,
                        });
                    }
                }
                Event::State { from, state, .. } => {
                    self.counters.states_heard += 1;
                    if let Some(&k) = self.index.get(&from.get()) {
                        self.states[k].0 = Some(state);
                        self.states[k].1 += 1;
                    }
                }
                Event::Reply {
                    handle,
                    tag,
                    payload,
                    ..
                } => {
                    self.counters.replies += 1;
                    self.resolve(handle, Outcome::Reply(tag, payload.to_vec()));
                }
                Event::Failed { handle, .. } => {
                    self.counters.failed += 1;
                    self.resolve(handle, Outcome::Failed);
                }
                Event::RepeatsDone { handle } => self.resolve(handle, Outcome::Failed),
                _ => {}
            }
        }
        let n = self.station.transmit(&mut self.buf);
        &self.buf[..n]
    }

    fn resolve(&mut self, h: RequestHandle, o: Outcome) {
        if let Some(i) = self.waiting.iter().position(|w| *w == h) {
            self.waiting.swap_remove(i);
            self.outcomes.insert(h, o);
        }
    }
}
