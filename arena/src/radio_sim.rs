//! Cars and a ground station running `radio-mac` over the [`RadioMedium`], each with its own
//! drifting local clock, plus ready-made experiments (state delivery, commands under loss).
//!
//! The driver jumps from one interesting instant to the next (a packet finishing at some
//! host, a MAC deadline, a medium event), so a simulated minute of 16 cars takes well under
//! a second in release builds.

use crate::radio_medium::{MediumParams, MediumStats, Nanos, NodeId, RadioMedium};
use radio_mac::schedule::{StateTiming, TimeBase, FRAME_US};
use radio_mac::{
    Address, CarConfig, CarId, CarMac, CarState, Event, GroundConfig, GroundStation, Key, Mode,
    Role,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A local clock: `offset + t * (1 + ppm / 1e6)`, in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Clock {
    /// Local time at simulation start, microseconds.
    pub offset_us: u64,
    /// Rate error in parts per million.
    pub ppm: i32,
}

impl Clock {
    /// The simulation's own clock.
    pub const IDEAL: Clock = Clock {
        offset_us: 0,
        ppm: 0,
    };

    fn rate(&self) -> u128 {
        (1_000_000i64 + i64::from(self.ppm)) as u128
    }

    /// Local microseconds at simulation time `t`.
    pub fn local(&self, t: Nanos) -> u64 {
        self.offset_us + (u128::from(t) * self.rate() / 1_000_000_000) as u64
    }

    /// Earliest simulation time at which the local clock reads at least `local_us`.
    pub fn sim_time(&self, local_us: u64) -> Nanos {
        let d = u128::from(local_us.saturating_sub(self.offset_us));
        (d * 1_000_000_000).div_ceil(self.rate()) as Nanos
    }
}

/// A simulated car's radio side.
#[derive(Debug)]
pub struct SimCar {
    /// Its protocol engine.
    pub mac: CarMac,
    /// Its node in the medium.
    pub node: NodeId,
    /// Its local clock.
    pub clock: Clock,
}

/// The simulated ground station.
#[derive(Debug)]
pub struct SimGround {
    /// Its protocol engine.
    pub station: GroundStation,
    /// Its node in the medium.
    pub node: NodeId,
}

/// Who an event belongs to, with mutable access for the reaction.
#[derive(Debug)]
pub enum Actor<'a> {
    /// Car `index` (into [`Sim::cars`]).
    Car {
        /// Index into [`Sim::cars`].
        index: usize,
        /// Its engine.
        mac: &'a mut CarMac,
    },
    /// The ground station.
    Ground(&'a mut GroundStation),
}

/// The world of radios.
#[derive(Debug)]
pub struct Sim {
    /// The channel.
    pub medium: RadioMedium,
    /// Cars.
    pub cars: Vec<SimCar>,
    /// Ground station, if any.
    pub ground: Option<SimGround>,
    /// Simulation time.
    pub now: Nanos,
    /// Period of the overhead tracking broadcast; when set, every car gets
    /// [`CarMac::sync_tick`] at each multiple of it (all cars hear tracking at once).
    pub tracking_period: Option<Nanos>,
}

impl Sim {
    /// An empty world over `medium`.
    pub fn new(medium: RadioMedium) -> Self {
        Self {
            medium,
            cars: Vec::new(),
            ground: None,
            now: 0,
            tracking_period: None,
        }
    }

    /// Add a car at `pos` (metres).
    pub fn add_car(&mut self, config: CarConfig, pos: (f64, f64), clock: Clock) -> usize {
        let node = self.medium.add_node(pos);
        self.cars.push(SimCar {
            mac: CarMac::new(config),
            node,
            clock,
        });
        self.cars.len() - 1
    }

    /// Add the ground station at `pos`.
    pub fn add_ground(&mut self, config: GroundConfig, pos: (f64, f64)) {
        let node = self.medium.add_node(pos);
        self.ground = Some(SimGround {
            station: GroundStation::new(config),
            node,
        });
    }

    /// Run until `end`, handing every event to `on_event(actor, local_now_us, event)`.
    pub fn run_until(&mut self, end: Nanos, mut on_event: impl FnMut(Actor<'_>, u64, Event)) {
        let mut buf = [0u8; 1024];
        while self.now < end {
            let mut t = end;
            if let Some(m) = self.medium.next_packet_time() {
                t = t.min(m);
            }
            for c in &mut self.cars {
                let local = c.clock.local(self.now);
                t = t.min(c.clock.sim_time(c.mac.poll_at(local)));
            }
            if let Some(g) = &mut self.ground {
                t = t.min(Clock::IDEAL.sim_time(g.station.poll_at(self.now / 1000)));
            }
            let tick = self
                .tracking_period
                .filter(|p| *p > 0)
                .map(|p| (self.now / p + 1) * p);
            if let Some(k) = tick {
                t = t.min(k);
            }
            self.now = t.max(self.now + 1).min(end);
            let now = self.now;
            self.medium.step(now);
            let ticked = tick == Some(now);
            for (index, c) in self.cars.iter_mut().enumerate() {
                let local = c.clock.local(now);
                if ticked {
                    c.mac.sync_tick(local);
                }
                let rx = self.medium.read(c.node, now);
                if !rx.is_empty() {
                    c.mac.push_rx(local, &rx);
                }
                c.mac.poll(local);
                while let Some(ev) = c.mac.next_event() {
                    on_event(
                        Actor::Car {
                            index,
                            mac: &mut c.mac,
                        },
                        local,
                        ev,
                    );
                }
                let n = c.mac.transmit(&mut buf);
                if n > 0 {
                    self.medium.write(c.node, now, &buf[..n]);
                }
            }
            if let Some(g) = &mut self.ground {
                let local = now / 1000;
                let rx = self.medium.read(g.node, now);
                if !rx.is_empty() {
                    g.station.push_rx(local, &rx);
                }
                g.station.poll(local);
                while let Some(ev) = g.station.next_event() {
                    on_event(Actor::Ground(&mut g.station), local, ev);
                }
                let n = g.station.transmit(&mut buf);
                if n > 0 {
                    self.medium.write(g.node, now, &buf[..n]);
                }
            }
        }
    }
}

/// The testbed key used by the simulations.
pub const SIM_KEY: [u8; 16] = *b"ALMC-sim-key-016";

/// State broadcast experiment parameters.
#[derive(Debug, Clone)]
pub struct StateExperiment {
    /// Number of cars (IDs 1..=cars).
    pub cars: usize,
    /// Slotted schedule (true) or plain periodic 30 Hz with random phase over CSMA (false).
    pub scheduled: bool,
    /// Simulated duration.
    pub duration: Nanos,
    /// Deliveries before this time are not counted (sync acquisition).
    pub warmup: Nanos,
    /// Seed of the medium, the clocks and the start times.
    pub seed: u64,
    /// Channel parameters.
    pub medium: MediumParams,
    /// Heartbeat period of the ground station (its only traffic here).
    pub ground_heartbeat_us: u32,
    /// Slotted cars take their frame time from the tracking broadcast
    /// ([`TimeBase::External`]) instead of following the lowest ID heard.
    pub tracking_time_base: bool,
}

impl StateExperiment {
    /// `cars` cars for `duration`, default channel.
    pub fn new(cars: usize, scheduled: bool, duration: Nanos, seed: u64) -> Self {
        Self {
            cars,
            scheduled,
            duration,
            warmup: 1_000_000_000,
            seed,
            medium: MediumParams::default(),
            ground_heartbeat_us: radio_mac::endpoint::HEARTBEAT_US,
            tracking_time_base: false,
        }
    }
}

/// State broadcast experiment result.
#[derive(Debug, Clone, PartialEq)]
pub struct StateReport {
    /// State frames sent after the warm-up.
    pub sent: u64,
    /// Receptions expected (each sent frame at every other node, ground station included).
    pub expected: u64,
    /// State events delivered after the warm-up.
    pub received: u64,
    /// Channel counters for the whole run.
    pub medium: MediumStats,
    /// Per car (by index): state frames the ground station heard and missed, whole run.
    pub per_car_at_ground: Vec<(u32, u32)>,
    /// Per car (by index): the ground station's heartbeats it heard, whole run (the cars
    /// hold no key, so they count them without verifying).
    pub beats_per_car: Vec<u32>,
}

impl StateReport {
    /// Delivered / expected.
    pub fn delivery_ratio(&self) -> f64 {
        if self.expected == 0 {
            1.0
        } else {
            self.received as f64 / self.expected as f64
        }
    }
}

/// Cars on a grid inside the 1.5 m x 2 m arena.
fn arena_position(i: usize) -> (f64, f64) {
    let col = (i % 4) as f64;
    let row = (i / 4) as f64;
    (0.2 + col * 0.35, 0.2 + row * 0.4)
}

fn states_sent(sim: &Sim) -> u64 {
    sim.cars
        .iter()
        .map(|c| u64::from(c.mac.stats().states_sent))
        .sum()
}

/// N cars broadcasting state at 30 Hz, counted at every other car and at the ground station.
pub fn run_state_experiment(e: &StateExperiment) -> StateReport {
    let mut rng = ChaCha8Rng::seed_from_u64(e.seed ^ 0x5EED);
    let latency_ns = e
        .medium
        .pipeline_latency_ns(radio_mac::wire::STATE_FRAME_LEN);
    let mut sim = Sim::new(RadioMedium::new(e.medium.clone(), e.seed));
    if e.scheduled && e.tracking_time_base {
        sim.tracking_period = Some(Nanos::from(FRAME_US) * 1000);
    }
    let mut starts = Vec::new();
    for i in 0..e.cars {
        let Some(id) = CarId::new((i + 1) as u8) else {
            break;
        };
        let mut cfg = CarConfig::new(id);
        cfg.seed = rng.random();
        cfg.timing = if e.scheduled {
            let time_base = if e.tracking_time_base {
                TimeBase::External { offset_us: 0 }
            } else {
                TimeBase::FollowLowest {
                    latency_us: (latency_ns / 1000) as u32,
                }
            };
            StateTiming::Slotted {
                slot: radio_mac::schedule::default_slot(id),
                time_base,
            }
        } else {
            StateTiming::Periodic {
                period_us: FRAME_US,
            }
        };
        let clock = Clock {
            offset_us: rng.random_range(0..1_000_000_000),
            ppm: rng.random_range(-50..=50),
        };
        sim.add_car(cfg, arena_position(i), clock);
        // Each car starts within the first frame, at an independent instant.
        starts.push(rng.random_range(0..u64::from(FRAME_US) * 1000));
    }
    let mut ground = GroundConfig::new(Key::new(SIM_KEY), 1);
    ground.heartbeat_us = e.ground_heartbeat_us;
    sim.add_ground(ground, (0.75, -0.3));

    // Start the cars one by one.
    let mut order: Vec<usize> = (0..sim.cars.len()).collect();
    order.sort_by_key(|&i| starts[i]);
    for i in order {
        sim.run_until(starts[i], |_, _, _| {});
        let st = CarState {
            x: 100 + i as u16 * 20,
            y: 200,
            heading_mrad: 0,
            velocity_mm_s: 0,
            mode: Mode {
                role: Role::Idle,
                phase: 0,
            },
        };
        sim.cars[i].mac.set_state(st);
    }
    // A state frame is counted as sent when queued and as received one pipeline latency
    // later: shift the reception window by that latency.
    let lag = latency_ns + 300_000;
    sim.run_until(e.warmup, |_, _, _| {});
    let sent_before = states_sent(&sim);
    sim.run_until(e.warmup + lag, |_, _, _| {});
    let mut received = 0u64;
    sim.run_until(e.warmup + e.duration, |_, _, ev| {
        if matches!(ev, Event::State { .. }) {
            received += 1;
        }
    });
    let sent_after = states_sent(&sim);
    sim.run_until(e.warmup + e.duration + lag, |_, _, ev| {
        if matches!(ev, Event::State { .. }) {
            received += 1;
        }
    });
    let sent = sent_after - sent_before;
    // Every other car plus the ground station.
    let receivers = sim.cars.len() as u64;
    let per_car_at_ground = sim
        .cars
        .iter()
        .map(|c| {
            sim.ground
                .as_ref()
                .and_then(|g| g.station.neighbours().get(Address::Car(c.mac.id())))
                .map(|n| (n.states_heard, n.states_missed))
                .unwrap_or((0, 0))
        })
        .collect();
    let beats_per_car = sim.cars.iter().map(|c| c.mac.stats().auth_no_key).collect();
    StateReport {
        sent,
        expected: sent * receivers,
        received,
        medium: *sim.medium.stats(),
        per_car_at_ground,
        beats_per_car,
    }
}

/// Result of the command experiment.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CommandReport {
    /// Commands the ground station issued.
    pub issued: u32,
    /// Replies it received.
    pub replied: u32,
    /// Commands that failed after all retries.
    pub failed: u32,
    /// Executions per (car index, counter), to check exactly-once.
    pub executions: std::collections::BTreeMap<(usize, u32), u32>,
    /// Car-to-car requests issued, replied and executed (by (car, seq)).
    pub peer_issued: u32,
    /// Car-to-car replies received.
    pub peer_replied: u32,
    /// Car-to-car executions per (receiver index, sender, seq).
    pub peer_executions: std::collections::BTreeMap<(usize, u8, u16), u32>,
}

/// Authenticated ground commands to `cars` cars (round robin) and car-to-car requests, over
/// a channel losing `loss` of packets at each receiver, with cars also broadcasting state.
pub fn run_command_experiment(cars: usize, commands: u32, loss: f64, seed: u64) -> CommandReport {
    let params = MediumParams {
        loss_probability: loss,
        ..MediumParams::default()
    };
    let mut sim = Sim::new(RadioMedium::new(params, seed));
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for i in 0..cars {
        let Some(id) = CarId::new((i + 1) as u8) else {
            break;
        };
        let mut cfg = CarConfig::new(id);
        cfg.key = Some(Key::new(SIM_KEY));
        cfg.seed = rng.random();
        let clock = Clock {
            offset_us: rng.random_range(0..1_000_000),
            ppm: rng.random_range(-50..=50),
        };
        let idx = sim.add_car(cfg, arena_position(i), clock);
        sim.cars[idx].mac.set_state(CarState::default());
    }
    sim.add_ground(GroundConfig::new(Key::new(SIM_KEY), 1000), (0.75, -0.3));
    let mut report = CommandReport::default();
    let mut outstanding = false;
    let mut next_peer = 0u32;
    let step: Nanos = 20_000_000;
    let mut t: Nanos = 200_000_000;
    while report.issued < commands || outstanding {
        if !outstanding && report.issued < commands {
            let dst_i = (report.issued as usize) % cars;
            if let (Some(g), Some(id)) = (sim.ground.as_mut(), CarId::new((dst_i + 1) as u8)) {
                let now = sim.now / 1000;
                let payload = report.issued.to_le_bytes();
                if g.station
                    .command(now, Address::Car(id), 1, &payload)
                    .is_ok()
                {
                    report.issued += 1;
                    outstanding = true;
                }
            }
            // A car-to-car request alongside.
            if cars >= 2 {
                let from = (next_peer as usize) % cars;
                let to = (from + 1) % cars;
                if let Some(id) = CarId::new((to + 1) as u8) {
                    let c = &mut sim.cars[from];
                    let local = c.clock.local(sim.now);
                    if c.mac
                        .request(local, Address::Car(id), 2, &next_peer.to_le_bytes())
                        .is_ok()
                    {
                        report.peer_issued += 1;
                        next_peer += 1;
                    }
                }
            }
        }
        t += step;
        sim.run_until(t, |actor, _now, ev| match (actor, ev) {
            (Actor::Car { index, mac }, Event::Request(inc)) => {
                match inc.id.counter {
                    Some(c) => *report.executions.entry((index, c)).or_insert(0) += 1,
                    None => {
                        let from = inc.id.from.to_byte();
                        *report
                            .peer_executions
                            .entry((index, from, inc.id.seq))
                            .or_insert(0) += 1;
                    }
                }
                let _ = mac.reply(inc.id, 0x80, &inc.payload);
            }
            (Actor::Car { .. }, Event::Reply { .. }) => report.peer_replied += 1,
            (Actor::Ground(_), Event::Reply { .. }) => {
                report.replied += 1;
                outstanding = false;
            }
            (Actor::Ground(_), Event::Failed { .. }) => {
                report.failed += 1;
                outstanding = false;
            }
            _ => {}
        });
        if t > 600_000_000_000 {
            break;
        }
    }
    // Let outstanding car-to-car requests finish.
    sim.run_until(t + 3_000_000_000, |actor, _now, ev| match (actor, ev) {
        (Actor::Car { index, mac }, Event::Request(inc)) => {
            if inc.id.counter.is_none() {
                let from = inc.id.from.to_byte();
                *report
                    .peer_executions
                    .entry((index, from, inc.id.seq))
                    .or_insert(0) += 1;
            }
            let _ = mac.reply(inc.id, 0x80, &inc.payload);
        }
        (Actor::Car { .. }, Event::Reply { .. }) => report.peer_replied += 1,
        _ => {}
    });
    report
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_inverse() {
        let c = Clock {
            offset_us: 12_345,
            ppm: -37,
        };
        for local in [12_345u64, 12_346, 99_999, 5_000_000] {
            let t = c.sim_time(local);
            assert!(c.local(t) >= local);
            if t > 0 {
                assert!(c.local(t - 1) < local);
            }
        }
    }
}
