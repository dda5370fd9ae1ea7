//! Group maneuvers on the car: the `maneuvers` controller fed from the STREAM pose and the
//! radio neighbour table, and a gate that decides which of its commands go to the LBC.
//!
//! The controller answers every 30 Hz sample, but the LBC's command UART (115200 bps, served
//! by a low-priority task, seed 2.1.8) also carries the console's commands and the LED updates
//! and every command waits for its answer, so a command is sent only when it differs
//! meaningfully from the last one sent (another kind, another `MOVE_XY` point, or a steering
//! or velocity change beyond [`STEER_STEP_MRAD`] / [`VELOCITY_STEP_MM_S`]), at most every
//! [`MIN_INTERVAL_US`], and repeated every [`REFRESH_US`] otherwise. A change to `STOP` goes
//! out at once. Any law of the registration list (`maneuvers::laws`) runs here; for a law that
//! does not drive (the camera follow, carried out by the program's camera part) the group
//! sends nothing and only reports.

use lbc_link::{Command, Position, SteerVelocity, SteeringAngle, Velocity};
use maneuvers::{
    AnyLaw, CarPose, Command as Motion, Controller, ControllerConfig, Inputs, ManeuverParams,
    Neighbour, Status, MAX_NEIGHBOURS,
};
use radio_mac::{Address, Mode, NeighbourTable, Role};

/// Smallest time between two group commands to the LBC, microseconds (10 Hz).
pub const MIN_INTERVAL_US: u64 = 100_000;
/// An unchanged command is sent again after this long, microseconds.
pub const REFRESH_US: u64 = 1_000_000;
/// Steering change that is worth a new `MOVE_SV`, mrad.
pub const STEER_STEP_MRAD: i16 = 20;
/// Velocity change that is worth a new `MOVE_SV`, mm/s.
pub const VELOCITY_STEP_MM_S: i16 = 10;

/// A maneuver command the [`SendGate`] thins out.
pub trait Gated: Copy {
    /// A stop: it goes out at once.
    fn is_stop(&self) -> bool;
    /// Whether `self` is worth sending after `last`.
    fn differs_from(&self, last: &Self) -> bool;
}

/// Decides which of a maneuver's per-sample commands go to the LBC (rules in the module docs).
#[derive(Debug, Clone)]
pub struct SendGate<C> {
    /// Last command handed to the LBC client and when.
    sent: Option<(C, u64)>,
}

impl<C> Default for SendGate<C> {
    fn default() -> Self {
        Self { sent: None }
    }
}

impl<C: Gated> SendGate<C> {
    /// `next` if it is due now and `may_send` (no earlier command still with the LBC client).
    pub fn offer(&mut self, now_us: u64, next: C, may_send: bool) -> Option<C> {
        let due = match self.sent {
            None => true,
            Some((last, at)) => due(
                super::sat_sub(now_us, at),
                next.is_stop() && !last.is_stop(),
                next.differs_from(&last),
            ),
        };
        if due && may_send {
            self.sent = Some((next, now_us));
            Some(next)
        } else {
            None
        }
    }

    /// Forgets the last command: the next one offered goes out (it did not reach the LBC, or
    /// a new maneuver starts).
    pub fn reset(&mut self) {
        self.sent = None;
    }
}

/// Whether a command goes out `since_us` after the last one: at once when it `stops` the car,
/// after [`MIN_INTERVAL_US`] when it `differs`, after [`REFRESH_US`] anyway.
// Out of line: one copy for every kind of command the gates thin out.
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn due(since_us: u64, stops: bool, differs: bool) -> bool {
    stops || (since_us >= MIN_INTERVAL_US && differs) || since_us >= REFRESH_US
}

impl Gated for Motion {
    fn is_stop(&self) -> bool {
        *self == Motion::Stop
    }

    fn differs_from(&self, last: &Self) -> bool {
        differs(*last, *self)
    }
}

/// The cars in the radio neighbour table with a state, their poses and ages at `now_us`
/// (at most [`MAX_NEIGHBOURS`]).
pub fn neighbours<const N: usize>(
    now_us: u64,
    table: Option<&NeighbourTable<N>>,
) -> heapless::Vec<Neighbour, MAX_NEIGHBOURS> {
    let mut out = heapless::Vec::new();
    for n in table.into_iter().flat_map(NeighbourTable::iter) {
        let (Address::Car(car), Some((s, at))) = (n.addr, n.state) else {
            continue;
        };
        let age = super::sat_sub(now_us, at);
        let _ = out.push(Neighbour {
            id: car.get(),
            pose: CarPose {
                x: s.x,
                y: s.y,
                heading_mrad: s.heading_mrad,
                velocity_mm_s: s.velocity_mm_s,
            },
            age_us: u32::try_from(age).unwrap_or(u32::MAX),
        });
    }
    out
}

/// The group maneuver of this car.
#[derive(Debug, Clone)]
pub struct Group {
    controller: Controller,
    status: Status,
    gate: SendGate<Motion>,
}

impl Default for Group {
    fn default() -> Self {
        Self {
            controller: Controller::new(ControllerConfig::default()),
            status: Status::default(),
            gate: SendGate::default(),
        }
    }
}

/// Whether `next` is worth sending after `last`.
fn differs(last: Motion, next: Motion) -> bool {
    match (last, next) {
        (
            Motion::MoveSv {
                steering_mrad: s0,
                velocity_mm_s: v0,
            },
            Motion::MoveSv {
                steering_mrad: s1,
                velocity_mm_s: v1,
            },
        ) => {
            (s1 - s0).abs() >= STEER_STEP_MRAD
                || (v1 - v0).abs() >= VELOCITY_STEP_MM_S
                // Starting, stopping or reversing always is.
                || v0.signum() != v1.signum()
        }
        (a, b) => a != b,
    }
}

/// The LBC command for a controller command (the controller keeps within the LBC's ranges;
/// a value outside them becomes `STOP`).
pub fn lbc_command(m: Motion) -> Command {
    match m {
        Motion::Stop => Command::Stop,
        Motion::MoveXy { x, y } => Position::new(x, y).map_or(Command::Stop, Command::MoveXy),
        Motion::MoveSv {
            steering_mrad,
            velocity_mm_s,
        } => match (
            SteeringAngle::new(steering_mrad),
            Velocity::new(velocity_mm_s),
        ) {
            (Ok(steering), Ok(velocity)) => Command::MoveSv(SteerVelocity { steering, velocity }),
            _ => Command::Stop,
        },
    }
}

impl Group {
    /// Starts `params` (replacing the running maneuver); [`ManeuverParams::IDLE`] stops.
    pub fn start(&mut self, params: ManeuverParams) {
        self.controller.start(params);
        self.status = Status::default();
        self.gate.reset();
    }

    /// Stops the maneuver (the caller stops the car).
    pub fn stop(&mut self) {
        self.start(ManeuverParams::IDLE);
    }

    /// True while a maneuver runs.
    #[must_use]
    pub fn active(&self) -> bool {
        self.controller.law().is_some()
    }

    /// The running law's ID (0: none).
    #[must_use]
    pub fn law_id(&self) -> u8 {
        self.controller.law().map_or(0, AnyLaw::id)
    }

    /// The controller's status after the last step.
    #[must_use]
    pub fn status(&self) -> Status {
        self.status
    }

    /// The running law, if any.
    #[must_use]
    pub fn law(&self) -> Option<&AnyLaw> {
        self.controller.law()
    }

    /// Next waypoint of the running law; `false` when none runs.
    pub fn set_waypoint(&mut self, x: u16, y: u16) -> bool {
        self.controller.set_waypoint(x, y)
    }

    /// Role and phase to broadcast: the car the law says leads is the leader, every other car
    /// in a maneuver follows.
    #[must_use]
    pub fn mode(&self, id: u8) -> Mode {
        let role = match self.controller.law() {
            None => Role::Idle,
            Some(l) if l.leads(id) => Role::Leader,
            Some(_) => Role::Follower,
        };
        Mode {
            role,
            phase: self.status.phase.bits(),
        }
    }

    /// One control period at a STREAM sample: steps the controller with this car's pose and
    /// its neighbours' broadcast poses, and returns the command to send now, if any.
    /// `may_send` is false while an earlier group command is still with the LBC client.
    pub fn step<const N: usize>(
        &mut self,
        now_us: u64,
        id: u8,
        own: CarPose,
        table: Option<&NeighbourTable<N>>,
        may_send: bool,
    ) -> Option<Motion> {
        if !self.active() {
            return None;
        }
        let neighbours = neighbours(now_us, table);
        let out = self.controller.step(&Inputs {
            now_us,
            id,
            own,
            neighbours: &neighbours,
        });
        self.status = out.status;
        if !self.controller.law().is_some_and(AnyLaw::drives) {
            // Another part of the program (the camera follow) drives the car.
            return None;
        }
        self.gate.offer(now_us, out.command, may_send)
    }

    /// The command handed over by the last [`Group::step`] did not reach the LBC: send it
    /// again at the next chance.
    pub fn unsent(&mut self) {
        self.gate.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use maneuvers::Phase;

    const TABLE: Option<&NeighbourTable<4>> = None;

    fn pose(x: u16, y: u16, heading_mrad: u16) -> CarPose {
        CarPose {
            x,
            y,
            heading_mrad,
            velocity_mm_s: 0,
        }
    }

    #[test]
    fn idle_sends_nothing() {
        let mut g = Group::default();
        assert_eq!(g.step(0, 1, pose(100, 100, 0), TABLE, true), None);
        assert_eq!(g.mode(1), Mode::default());
    }

    #[test]
    fn goto_commands_are_rate_limited_and_refreshed() {
        let mut g = Group::default();
        g.start(maneuvers::GoTo::params(300, 600, 250).unwrap());
        let first = g.step(0, 1, pose(300, 400, 1571), TABLE, true);
        assert_eq!(
            first,
            Some(Motion::MoveSv {
                steering_mrad: 0,
                velocity_mm_s: 250
            })
        );
        assert_eq!(g.mode(1).role, Role::Follower);
        assert_eq!(g.mode(1).phase, Phase::Approach.bits());
        // The same command 33 ms later: nothing.
        assert_eq!(g.step(33_000, 1, pose(300, 410, 1571), TABLE, true), None);
        // Facing away a little: a different steering, but within the minimum interval.
        assert_eq!(g.step(66_000, 1, pose(300, 420, 1400), TABLE, true), None);
        let next = g.step(100_000, 1, pose(300, 420, 1400), TABLE, true);
        assert!(
            matches!(next, Some(Motion::MoveSv { steering_mrad, .. }) if steering_mrad > 100),
            "{next:?}"
        );
        // Unchanged for a second: sent again.
        assert_eq!(g.step(600_000, 1, pose(300, 420, 1400), TABLE, true), None);
        assert!(g
            .step(1_100_000, 1, pose(300, 420, 1400), TABLE, true)
            .is_some());
        // Not while the client still holds one, and again once it may.
        assert_eq!(
            g.step(2_200_000, 1, pose(300, 420, 1400), TABLE, false),
            None
        );
        assert!(g
            .step(2_233_000, 1, pose(300, 420, 1400), TABLE, true)
            .is_some());
    }

    #[test]
    fn arrival_stops_at_once() {
        let mut g = Group::default();
        g.start(maneuvers::GoTo::params(300, 600, 250).unwrap());
        assert!(g.step(0, 1, pose(300, 590, 1571), TABLE, true).is_some());
        assert_eq!(
            g.step(10_000, 1, pose(300, 597, 1571), TABLE, true),
            Some(Motion::Stop)
        );
        assert!(g.status().converged);
        assert_eq!(g.status().phase, Phase::Hold);
    }

    #[test]
    fn waypoints_for_any_running_law() {
        let mut g = Group::default();
        assert!(!g.set_waypoint(10, 10));
        g.start(maneuvers::Rendezvous::params(60, 200).unwrap());
        assert!(g.set_waypoint(10, 10));
        g.start(maneuvers::Formation::params(maneuvers::Shape::Line, 3, None, 60, 100).unwrap());
        assert!(g.set_waypoint(300, 300));
        assert_eq!(g.mode(3).role, Role::Leader);
        assert_eq!(g.mode(4).role, Role::Follower);
        let cmd = g.step(0, 3, pose(100, 300, 0), TABLE, true);
        assert!(
            matches!(
                cmd,
                Some(Motion::MoveSv {
                    velocity_mm_s: 100,
                    ..
                })
            ),
            "{cmd:?}"
        );
    }

    #[test]
    fn camera_follow_leaves_the_driving_to_the_camera() {
        let mut g = Group::default();
        g.start(maneuvers::CameraFollow::params(2, 80, 150).unwrap());
        assert!(g.active());
        assert_eq!(g.step(0, 1, pose(100, 100, 0), TABLE, true), None);
        assert_eq!(g.step(2_000_000, 1, pose(100, 100, 0), TABLE, true), None);
        assert_eq!(g.status().phase, Phase::Hold);
    }

    #[test]
    fn small_changes_are_not_sent() {
        let a = Motion::MoveSv {
            steering_mrad: 100,
            velocity_mm_s: 200,
        };
        let b = Motion::MoveSv {
            steering_mrad: 110,
            velocity_mm_s: 205,
        };
        assert!(!differs(a, b));
        assert!(differs(
            a,
            Motion::MoveSv {
                steering_mrad: 100,
                velocity_mm_s: -200
            }
        ));
        assert!(differs(a, Motion::Stop));
        assert!(differs(
            Motion::MoveXy { x: 1, y: 2 },
            Motion::MoveXy { x: 1, y: 3 }
        ));
        assert_eq!(
            lbc_command(Motion::MoveSv {
                steering_mrad: 600,
                velocity_mm_s: 0
            }),
            Command::Stop
        );
    }
}
