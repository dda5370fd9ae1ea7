//! Camera-based leader following: steer to keep the leader's marker centred and drive to keep it
//! at a set range, using only what the camera sees (no broadcast pose).
//!
//! Each processed frame gives [`Follower::on_frame`] the leader's observation (or `None`); each
//! control period [`Follower::command`] gives a steering angle and a velocity for `MOVE_SV`.
//!
//! - Steering: `bearing * steer_gain_q8 / 256`, limited to the mechanical +/-523 mrad (positive
//!   bearing = marker to the left = steer left).
//! - Velocity: `(range - distance) * range_gain_q8 / 256` mm/s, limited to `0..=max_speed`, and
//!   halved while the marker is more than `turn_first_mrad` off centre. The car never reverses.
//! - Marker not seen for `coast_ms`: steering goes to zero and the last velocity ramps down to
//!   zero over `stop_ms`; then the follower reports [`FollowState::Lost`] and commands stop until
//!   the marker is seen again.

use crate::blobs::Detections;
use crate::pinhole::{CameraModel, MarkerModel, Observation};

/// Bearing and range of the largest blob of `class`, if any.
pub fn observe_class(
    detections: &Detections,
    class: u8,
    model: &CameraModel,
    marker: &MarkerModel,
) -> Option<Observation> {
    detections
        .largest_of_class(class)
        .map(|b| model.observe(b, marker))
}

/// The steering limit of the car (30 degrees), mrad.
pub const MAX_STEER_MRAD: i32 = 523;

/// Gains and timeouts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FollowConfig {
    /// Steering per bearing, Q8 (256 = 1 mrad of steering per mrad of bearing).
    pub steer_gain_q8: i32,
    /// Velocity per range error, Q8 (mm/s per mm; 384 = 1.5 per second).
    pub range_gain_q8: i32,
    /// Off-centre bearing above which the velocity is halved, mrad.
    pub turn_first_mrad: i32,
    /// Time without the marker before slowing down, ms.
    pub coast_ms: u32,
    /// Time (after `coast_ms`) over which the velocity ramps to zero, ms.
    pub stop_ms: u32,
    /// Observations further than this are ignored as implausible, mm.
    pub max_range_mm: u32,
}

impl Default for FollowConfig {
    fn default() -> Self {
        FollowConfig {
            steer_gain_q8: 256,
            range_gain_q8: 384,
            turn_first_mrad: 300,
            coast_ms: 300,
            stop_ms: 1500,
            max_range_mm: 3000,
        }
    }
}

/// What to follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FollowTarget {
    /// Colour class of the leader's marker.
    pub class: u8,
    /// Range to keep (camera to marker axis), mm.
    pub distance_mm: u32,
    /// Highest velocity, mm/s.
    pub max_speed_mm_s: u16,
}

/// Where the follower stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FollowState {
    /// Not seen yet since the start: stopped.
    Searching,
    /// The marker is in the latest frames.
    Tracking,
    /// Lost for a moment: slowing down.
    Coasting,
    /// Lost for longer than the timeouts: stopped.
    Lost,
}

impl FollowState {
    /// Wire code (console replies): 0 searching, 1 tracking, 2 coasting, 3 lost.
    pub const fn code(self) -> u8 {
        match self {
            FollowState::Searching => 0,
            FollowState::Tracking => 1,
            FollowState::Coasting => 2,
            FollowState::Lost => 3,
        }
    }
}

/// A motion command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FollowCommand {
    /// Steering angle, mrad, positive left.
    pub steering_mrad: i16,
    /// Velocity, mm/s, never negative.
    pub velocity_mm_s: i16,
}

/// The follower's state machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Follower {
    target: FollowTarget,
    config: FollowConfig,
    state: FollowState,
    last_seen_us: u64,
    last: Option<Observation>,
    tracking_command: FollowCommand,
}

impl Follower {
    pub fn new(target: FollowTarget, config: FollowConfig) -> Self {
        Follower {
            target,
            config,
            state: FollowState::Searching,
            last_seen_us: 0,
            last: None,
            tracking_command: FollowCommand::default(),
        }
    }

    pub fn target(&self) -> &FollowTarget {
        &self.target
    }

    pub fn state(&self) -> FollowState {
        self.state
    }

    /// The last observation used.
    pub fn last_observation(&self) -> Option<Observation> {
        self.last
    }

    /// A processed frame captured at `now_us`: the leader's marker as seen, or `None`.
    pub fn on_frame(&mut self, now_us: u64, leader: Option<Observation>) {
        let Some(o) = leader.filter(|o| {
            o.class == self.target.class && o.range_mm > 0 && o.range_mm <= self.config.max_range_mm
        }) else {
            return;
        };
        self.last = Some(o);
        self.last_seen_us = now_us;
        self.state = FollowState::Tracking;
        self.tracking_command = self.law(&o);
    }

    fn law(&self, o: &Observation) -> FollowCommand {
        let c = &self.config;
        let steer = (i64::from(o.bearing_mrad) * i64::from(c.steer_gain_q8) / 256)
            .clamp(-i64::from(MAX_STEER_MRAD), i64::from(MAX_STEER_MRAD));
        let error = i64::from(o.range_mm) - i64::from(self.target.distance_mm);
        let mut v = (error * i64::from(c.range_gain_q8) / 256).clamp(
            0,
            i64::from(self.target.max_speed_mm_s).min(i64::from(i16::MAX)),
        );
        if o.bearing_mrad.unsigned_abs() > c.turn_first_mrad.unsigned_abs() {
            v /= 2;
        }
        FollowCommand {
            steering_mrad: steer as i16,
            velocity_mm_s: v as i16,
        }
    }

    /// The command for now (call every control period).
    pub fn command(&mut self, now_us: u64) -> FollowCommand {
        if matches!(self.state, FollowState::Searching | FollowState::Lost) {
            return FollowCommand::default();
        }
        let since_ms = now_us.saturating_sub(self.last_seen_us) / 1000;
        let coast = u64::from(self.config.coast_ms);
        if since_ms <= coast {
            return self.tracking_command;
        }
        let into = since_ms - coast;
        let ramp = u64::from(self.config.stop_ms.max(1));
        if into >= ramp {
            self.state = FollowState::Lost;
            return FollowCommand::default();
        }
        self.state = FollowState::Coasting;
        let v = i64::from(self.tracking_command.velocity_mm_s) * (ramp - into) as i64 / ramp as i64;
        FollowCommand {
            steering_mrad: 0,
            velocity_mm_s: v as i16,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn target() -> FollowTarget {
        FollowTarget {
            class: 2,
            distance_mm: 500,
            max_speed_mm_s: 300,
        }
    }

    fn obs(bearing_mrad: i32, range_mm: u32) -> Option<Observation> {
        Some(Observation {
            class: 2,
            bearing_mrad,
            range_mm,
        })
    }

    #[test]
    fn steers_towards_the_marker_and_closes_the_range() {
        let mut f = Follower::new(target(), FollowConfig::default());
        assert_eq!(f.state(), FollowState::Searching);
        assert_eq!(f.command(0), FollowCommand::default());
        f.on_frame(1_000, obs(100, 700));
        assert_eq!(f.state(), FollowState::Tracking);
        // 200 mm too far at 1.5/s: 300 mm/s (the limit); 100 mrad left: steer 100 left.
        assert_eq!(
            f.command(2_000),
            FollowCommand {
                steering_mrad: 100,
                velocity_mm_s: 300
            }
        );
        f.on_frame(50_000, obs(-40, 600));
        assert_eq!(
            f.command(50_000),
            FollowCommand {
                steering_mrad: -40,
                velocity_mm_s: 150
            }
        );
        // Too close: stop, never reverse; far off centre: steering saturates, speed halves.
        f.on_frame(60_000, obs(0, 300));
        assert_eq!(f.command(60_000).velocity_mm_s, 0);
        f.on_frame(70_000, obs(-900, 600));
        assert_eq!(
            f.command(70_000),
            FollowCommand {
                steering_mrad: -523,
                velocity_mm_s: 75
            }
        );
    }

    #[test]
    fn other_classes_and_implausible_ranges_are_ignored() {
        let mut f = Follower::new(target(), FollowConfig::default());
        f.on_frame(
            0,
            Some(Observation {
                class: 3,
                bearing_mrad: 0,
                range_mm: 800,
            }),
        );
        f.on_frame(0, obs(0, 0));
        f.on_frame(0, obs(0, 10_000));
        assert_eq!(f.state(), FollowState::Searching);
        assert_eq!(f.last_observation(), None);
    }

    #[test]
    fn lost_marker_slows_down_then_stops_until_seen_again() {
        let mut f = Follower::new(target(), FollowConfig::default());
        f.on_frame(0, obs(50, 700));
        assert_eq!(f.command(300_000).velocity_mm_s, 300);
        f.on_frame(300_000, None);
        // 300 ms coast, then a 1.5 s ramp: half way at 1.05 s.
        let c = f.command(1_050_000);
        assert_eq!(f.state(), FollowState::Coasting);
        assert_eq!(
            c,
            FollowCommand {
                steering_mrad: 0,
                velocity_mm_s: 150
            }
        );
        assert_eq!(f.command(1_800_000), FollowCommand::default());
        assert_eq!(f.state(), FollowState::Lost);
        assert_eq!(f.command(5_000_000), FollowCommand::default());
        f.on_frame(5_000_000, obs(0, 600));
        assert_eq!(f.state(), FollowState::Tracking);
        assert_eq!(f.command(5_000_000).velocity_mm_s, 150);
    }
}
