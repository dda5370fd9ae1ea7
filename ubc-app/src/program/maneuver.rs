//! The go-to-points maneuver: MOVE_XY to each point in turn, advancing when the streamed
//! position is within the arrival radius, then STOP.

use super::console::{Point, Points};

/// Where the maneuver stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ManeuverState {
    /// No maneuver.
    Idle,
    /// Driving to point `index`.
    Driving { index: u8 },
    /// All points reached.
    Done,
    /// Stopped before the end (user, link loss or an LBC refusal).
    Aborted,
}

/// A go-to-points maneuver.
#[derive(Debug, Clone)]
pub struct Maneuver {
    points: Points,
    state: ManeuverState,
}

impl Default for Maneuver {
    fn default() -> Self {
        Self {
            points: Points::new(),
            state: ManeuverState::Idle,
        }
    }
}

impl Maneuver {
    /// Starts driving through `points`; returns the first target.
    pub fn start(&mut self, points: Points) -> Option<Point> {
        self.points = points;
        self.state = ManeuverState::Driving { index: 0 };
        self.points.first().copied()
    }

    /// State.
    #[must_use]
    pub fn state(&self) -> ManeuverState {
        self.state
    }

    /// Points of the current or last maneuver.
    #[must_use]
    pub fn points(&self) -> &Points {
        &self.points
    }

    /// True while driving.
    #[must_use]
    pub fn active(&self) -> bool {
        matches!(self.state, ManeuverState::Driving { .. })
    }

    /// The point being driven to.
    #[must_use]
    pub fn target(&self) -> Option<Point> {
        match self.state {
            ManeuverState::Driving { index } => self.points.get(usize::from(index)).copied(),
            _ => None,
        }
    }

    /// Stops the maneuver early.
    pub fn abort(&mut self) {
        if self.active() {
            self.state = ManeuverState::Aborted;
        }
    }

    /// A new position: returns the next target when the current one is reached, and
    /// `Some(None)` when the last one is reached (the maneuver is then done).
    pub fn update(&mut self, x: u16, y: u16, radius: u16) -> Option<Option<Point>> {
        let ManeuverState::Driving { index } = self.state else {
            return None;
        };
        let target = self.points.get(usize::from(index))?;
        let dx = i32::from(x) - i32::from(target.x);
        let dy = i32::from(y) - i32::from(target.y);
        let r = i32::from(radius);
        if dx * dx + dy * dy > r * r {
            return None;
        }
        let next = index + 1;
        match self.points.get(usize::from(next)) {
            Some(p) => {
                self.state = ManeuverState::Driving { index: next };
                Some(Some(*p))
            }
            None => {
                self.state = ManeuverState::Done;
                Some(None)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advances_through_points_then_is_done() {
        let mut m = Maneuver::default();
        let mut pts = Points::new();
        pts.push(Point { x: 100, y: 100 }).unwrap();
        pts.push(Point { x: 200, y: 100 }).unwrap();
        assert_eq!(m.start(pts), Some(Point { x: 100, y: 100 }));
        assert_eq!(m.update(50, 50, 10), None);
        assert_eq!(m.update(105, 95, 10), Some(Some(Point { x: 200, y: 100 })));
        assert_eq!(m.target(), Some(Point { x: 200, y: 100 }));
        assert_eq!(m.update(200, 111, 10), None);
        assert_eq!(m.update(200, 110, 10), Some(None));
        assert_eq!(m.state(), ManeuverState::Done);
        assert_eq!(m.update(200, 100, 10), None);
    }
}
