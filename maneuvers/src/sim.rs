//! Host simulation for the tests: kinematic bicycle cars (wheelbase 80 mm, +/-30 degrees,
//! speed limit, first-order speed response), each running its own [`Controller`] at 30 Hz,
//! exchanging quantised state broadcasts over a lossy, delayed radio.

use crate::geom::{rad_to_mrad, wrap, Vec2};
use crate::{
    CarPose, Command, Controller, ControllerConfig, Inputs, ManeuverParams, Neighbour, Output,
    ARENA_X_MAX, ARENA_Y_MAX, MM_PER_UNIT, WHEELBASE_MM,
};

pub const CONTROL_HZ: f32 = 30.0;
const SUBSTEPS: u32 = 6;
/// Speed response time constant of the LBC's velocity loop, s.
const SPEED_TAU_S: f32 = 0.05;
/// Top speed of the car, mm/s.
const TOP_SPEED_MM_S: f32 = 1500.0;

/// Radio model between every pair of cars.
#[derive(Debug, Clone, Copy)]
pub struct Radio {
    /// Probability that one broadcast is lost at one receiver.
    pub loss: f32,
    /// Delivery delay in control periods.
    pub delay_periods: u32,
}

impl Radio {
    pub const PERFECT: Radio = Radio {
        loss: 0.0,
        delay_periods: 0,
    };
}

#[derive(Debug)]
pub struct Car {
    pub id: u8,
    pub pos: Vec2,
    pub heading: f32,
    pub speed: f32,
    pub command: Command,
    pub last: Option<Output>,
    pub ctrl: Controller,
    /// Latest state heard from each other car: (sender index, pose, arrival time in s).
    heard: Vec<(usize, CarPose, f32)>,
}

impl Car {
    pub fn pose(&self) -> CarPose {
        CarPose {
            x: libm::roundf(self.pos.x.max(0.0)) as u16,
            y: libm::roundf(self.pos.y.max(0.0)) as u16,
            heading_mrad: rad_to_mrad(self.heading),
            velocity_mm_s: libm::roundf(self.speed) as i16,
        }
    }

    pub fn body(&self) -> Vec2 {
        self.pos + Vec2::from_angle(self.heading) * 16.0
    }
}

pub struct World {
    pub cars: Vec<Car>,
    pub t: f32,
    radio: Radio,
    rng: u64,
    in_flight: Vec<(u32, usize, usize, CarPose)>,
    period: u32,
    silenced: Vec<usize>,
    config: ControllerConfig,
    /// Smallest body-centre distance seen between any two cars, tracking units.
    pub min_distance: f32,
    /// Largest excursion of a body circle (radius 24) beyond a wall, tracking units (0 = none).
    pub wall_excursion: f32,
}

impl World {
    pub fn new(radio: Radio, seed: u64) -> Self {
        Self {
            cars: Vec::new(),
            t: 0.0,
            radio,
            rng: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1,
            in_flight: Vec::new(),
            period: 0,
            silenced: Vec::new(),
            config: ControllerConfig::default(),
            min_distance: f32::MAX,
            wall_excursion: 0.0,
        }
    }

    /// Controller configuration of the cars added from now on.
    pub fn set_config(&mut self, config: ControllerConfig) {
        self.config = config;
    }

    /// Adds a car at `(x, y)` tracking units, heading in degrees, running `params`.
    pub fn add(&mut self, id: u8, x: f32, y: f32, heading_deg: f32, params: ManeuverParams) {
        let mut ctrl = Controller::new(self.config);
        ctrl.start(params);
        self.cars.push(Car {
            id,
            pos: Vec2::new(x, y),
            heading: wrap(heading_deg.to_radians()),
            speed: 0.0,
            command: Command::Stop,
            last: None,
            ctrl,
            heard: Vec::new(),
        });
    }

    fn random(&mut self) -> f32 {
        // xorshift64*: deterministic, good enough for loss decisions.
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        (self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }

    /// One control period: broadcast, deliver, control, move.
    pub fn step(&mut self) {
        let n = self.cars.len();
        for from in 0..n {
            let pose = self.cars[from].pose();
            let silent = self.silenced.contains(&from);
            for to in 0..n {
                if to != from && self.random() >= self.radio.loss && !silent {
                    self.in_flight
                        .push((self.period + self.radio.delay_periods, from, to, pose));
                }
            }
        }
        let period = self.period;
        let t = self.t;
        let mut i = 0;
        while i < self.in_flight.len() {
            let (at, from, to, pose) = self.in_flight[i];
            if at <= period {
                let heard = &mut self.cars[to].heard;
                match heard.iter_mut().find(|h| h.0 == from) {
                    Some(h) => *h = (from, pose, t),
                    None => heard.push((from, pose, t)),
                }
                self.in_flight.swap_remove(i);
            } else {
                i += 1;
            }
        }
        let ids: Vec<u8> = self.cars.iter().map(|c| c.id).collect();
        for car in &mut self.cars {
            let neighbours: Vec<Neighbour> = car
                .heard
                .iter()
                .map(|&(from, pose, at)| Neighbour {
                    id: ids[from],
                    pose,
                    age_us: ((t - at) * 1e6) as u32,
                })
                .collect();
            let out = car.ctrl.step(&Inputs {
                now_us: (t * 1e6) as u64,
                id: car.id,
                own: car.pose(),
                neighbours: &neighbours,
            });
            car.command = out.command;
            car.last = Some(out);
        }
        let dt = 1.0 / CONTROL_HZ / SUBSTEPS as f32;
        for _ in 0..SUBSTEPS {
            for car in &mut self.cars {
                let (steer, target) = match car.command {
                    Command::Stop => (0.0, 0.0),
                    Command::MoveSv {
                        steering_mrad,
                        velocity_mm_s,
                    } => (
                        f32::from(steering_mrad.clamp(-523, 523)) * 1e-3,
                        f32::from(velocity_mm_s).clamp(-TOP_SPEED_MM_S, TOP_SPEED_MM_S),
                    ),
                    Command::MoveXy { .. } => panic!("the simulated LBC does not run MOVE_XY"),
                };
                car.speed += (target - car.speed) * (dt / SPEED_TAU_S).min(1.0);
                let ds = car.speed * dt / MM_PER_UNIT;
                car.heading =
                    wrap(car.heading + ds * MM_PER_UNIT * libm::tanf(steer) / WHEELBASE_MM);
                car.pos = car.pos + Vec2::from_angle(car.heading) * ds;
            }
            self.measure();
        }
        self.period += 1;
        self.t = self.period as f32 / CONTROL_HZ;
    }

    fn measure(&mut self) {
        for (i, a) in self.cars.iter().enumerate() {
            let b = a.body();
            for c in &self.cars[i + 1..] {
                self.min_distance = self.min_distance.min((c.body() - b).norm());
            }
            let r = 24.0;
            let out = [
                r - b.x,
                r - b.y,
                b.x + r - f32::from(ARENA_X_MAX),
                b.y + r - f32::from(ARENA_Y_MAX),
            ];
            for o in out {
                self.wall_excursion = self.wall_excursion.max(o);
            }
        }
    }

    /// Runs until `done` holds or `limit_s` passes; returns the time it first held.
    pub fn run_until(&mut self, limit_s: f32, mut done: impl FnMut(&World) -> bool) -> Option<f32> {
        while self.t < limit_s {
            self.step();
            if done(self) {
                return Some(self.t);
            }
        }
        None
    }

    pub fn run_for(&mut self, seconds: f32, mut each: impl FnMut(&World)) {
        let end = self.t + seconds;
        while self.t < end {
            self.step();
            each(self);
        }
    }

    /// From now on nothing car `id` sends is delivered.
    pub fn silence(&mut self, id: u8) {
        if let Some(i) = self.cars.iter().position(|c| c.id == id) {
            self.silenced.push(i);
        }
    }

    pub fn all_converged(&self) -> bool {
        self.cars
            .iter()
            .all(|c| c.last.is_some_and(|o| o.status.converged))
    }

    pub fn car(&self, id: u8) -> &Car {
        self.cars
            .iter()
            .find(|c| c.id == id)
            .expect("car in the world")
    }

    pub fn car_mut(&mut self, id: u8) -> &mut Car {
        self.cars
            .iter_mut()
            .find(|c| c.id == id)
            .expect("car in the world")
    }
}
