//! The overhead tracker: samples every car's true pose at its rate, adds noise, drops fixes
//! with a probability, and delivers each fix to the car's LBC after its latency. Times are
//! world nanoseconds; randomness comes from the world's seed, drawn in car order.

use super::{TrackingParams, MM_PER_UNIT};
use crate::engine::Nanos;
use lbc_emu::{Lbc, Pose};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

/// One fix on its way: delivery time, X and Y in tracking units, heading in mrad.
type Fix = (Nanos, u16, u16, u16);

/// Tracker state and counters.
#[derive(Debug)]
pub struct Tracker {
    params: TrackingParams,
    period: Nanos,
    latency: Nanos,
    next_tick: Nanos,
    rng: ChaCha8Rng,
    queues: Vec<VecDeque<Fix>>,
    /// Fixes delivered, per car.
    pub delivered: Vec<u64>,
    /// Fixes dropped, per car.
    pub dropped: Vec<u64>,
}

impl Tracker {
    /// A tracker of `cars` cars.
    pub fn new(params: TrackingParams, cars: usize, seed: u64) -> Self {
        let period = (1e9 / params.rate_hz.clamp(0.1, 1000.0)).round() as Nanos;
        Tracker {
            params,
            period,
            latency: u64::try_from(params.latency.as_nanos()).unwrap_or(u64::MAX),
            next_tick: 0,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7472_6163),
            queues: vec![VecDeque::new(); cars],
            delivered: vec![0; cars],
            dropped: vec![0; cars],
        }
    }

    /// Takes every fix due before `until` (sampling the poses of `lbcs` at each tick that
    /// falls before `until`) and hands the due ones to the LBCs. Returns whether a tick fell
    /// in the interval.
    pub fn step(&mut self, until: Nanos, lbcs: &mut [Lbc]) -> bool {
        let mut ticked = false;
        while self.next_tick < until {
            let t = self.next_tick;
            self.next_tick += self.period;
            ticked = true;
            for (k, lbc) in lbcs.iter().enumerate() {
                if self.rng.random::<f64>() < self.params.drop {
                    self.dropped[k] += 1;
                    continue;
                }
                let fix = self.measure(&lbc.vehicle().pose());
                self.queues[k].push_back((t + self.latency, fix.0, fix.1, fix.2));
            }
        }
        for (k, lbc) in lbcs.iter_mut().enumerate() {
            while let Some(&(t, x, y, h)) = self.queues[k].front() {
                if t >= until {
                    break;
                }
                self.queues[k].pop_front();
                lbc.set_tracked_pose(t / 1000, x, y, h);
                self.delivered[k] += 1;
            }
        }
        ticked
    }

    fn measure(&mut self, p: &Pose) -> (u16, u16, u16) {
        let g = &mut self.rng;
        let x = p.x_mm + lbc_emu::vehicle::gaussian(g) * self.params.noise_mm;
        let y = p.y_mm + lbc_emu::vehicle::gaussian(g) * self.params.noise_mm;
        let h =
            p.heading_rad * 1000.0 + lbc_emu::vehicle::gaussian(g) * self.params.heading_noise_mrad;
        let units = |mm: f64, max: f64| (mm / MM_PER_UNIT).round().clamp(0.0, max) as u16;
        let h = h
            .rem_euclid(std::f64::consts::TAU * 1000.0)
            .round()
            .min(6283.0) as u16;
        (units(x, 640.0), units(y, 960.0), h)
    }
}
