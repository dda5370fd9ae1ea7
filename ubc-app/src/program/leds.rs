//! What the two LBC LEDs show (WRIT_LED): green for the program's health, red for warnings.
//!
//! | green | meaning |
//! |---|---|
//! | on | running, ground station heard |
//! | 1 Hz blink | running, no ground station |
//! | off | LBC not brought up (the LBC cannot show anything then) |
//!
//! | red (first that applies) | meaning |
//! |---|---|
//! | 5 Hz blink | chip over temperature |
//! | on | battery low |
//! | 2 Hz blink | the LBC link failed recently (for `error_led_ms` after it recovers) |
//! | 1 Hz blink | the user link was lost |
//! | off | nothing to report |

use lbc_link::{Duty, LedPattern, LedRate};

/// Inputs of the LED policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LedState {
    /// Running (bring-up complete).
    pub running: bool,
    /// The ground station was heard within the timeout.
    pub user_link: bool,
    /// The user link was lost (and not heard since).
    pub user_link_lost: bool,
    /// Over temperature.
    pub over_temperature: bool,
    /// Battery low.
    pub battery_low: bool,
    /// The LBC link failed recently.
    pub lbc_error: bool,
}

const HALF: Duty = match Duty::new(5) {
    Ok(d) => d,
    Err(_) => Duty::ON,
};

impl LedState {
    /// The (green, red) patterns to show.
    #[must_use]
    pub fn patterns(&self) -> (LedPattern, LedPattern) {
        let green = match (self.running, self.user_link) {
            (false, _) => LedPattern::new(LedRate::Blink1Hz, Duty::OFF),
            (true, true) => LedPattern::new(LedRate::Blink1Hz, Duty::ON),
            (true, false) => LedPattern::new(LedRate::Blink1Hz, HALF),
        };
        let red = if self.over_temperature {
            LedPattern::new(LedRate::Blink5Hz, HALF)
        } else if self.battery_low {
            LedPattern::new(LedRate::Blink1Hz, Duty::ON)
        } else if self.lbc_error {
            LedPattern::new(LedRate::Blink2Hz, HALF)
        } else if self.user_link_lost {
            LedPattern::new(LedRate::Blink1Hz, HALF)
        } else {
            LedPattern::new(LedRate::Blink1Hz, Duty::OFF)
        };
        (green, red)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warnings_take_priority_on_red() {
        let s = LedState {
            running: true,
            over_temperature: true,
            battery_low: true,
            ..LedState::default()
        };
        assert_eq!(s.patterns().1.rate(), LedRate::Blink5Hz);
        let s = LedState {
            battery_low: true,
            lbc_error: true,
            ..s
        };
        let s = LedState {
            over_temperature: false,
            ..s
        };
        assert_eq!(s.patterns().1.duty(), Duty::ON);
        let quiet = LedState {
            running: true,
            user_link: true,
            ..LedState::default()
        };
        assert_eq!(quiet.patterns().1.duty(), Duty::OFF);
        assert_eq!(quiet.patterns().0.duty(), Duty::ON);
    }
}
