//! Seeded fault injection on the LBC's UART link, in the manner of a smoltcp `FaultInjector`.
//!
//! Drop and corruption act on single bytes in both directions (a corrupted byte has one random
//! bit flipped); delay holds every outgoing message back by a fixed time; suppression discards a
//! whole outgoing message; spontaneous resets restart the LBC at random instants whose mean
//! spacing is `reset_every_s` (a Poisson process). A given seed always produces the same faults
//! for the same traffic.

use core::fmt;
use core::str::FromStr;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Fault rates. All zero (the default) means a perfect link.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FaultConfig {
    /// Probability that a byte is lost, per byte, each direction.
    pub drop: f64,
    /// Probability that a byte has one bit flipped, per byte, each direction.
    pub corrupt: f64,
    /// Extra delay before each outgoing message enters the UART, microseconds.
    pub delay_us: u64,
    /// Probability that an outgoing message (reply or STREAM frame) is never sent.
    pub suppress: f64,
    /// Mean seconds between spontaneous resets; 0 disables them.
    pub reset_every_s: f64,
}

impl FaultConfig {
    /// Whether any fault is enabled.
    pub fn is_active(&self) -> bool {
        self.drop > 0.0
            || self.corrupt > 0.0
            || self.delay_us > 0
            || self.suppress > 0.0
            || self.reset_every_s > 0.0
    }
}

/// Why a `--faults` specification was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum FaultSpecError {
    /// An item is not `key=value`.
    MissingValue {
        /// The item as written.
        item: String,
    },
    /// The key is not one of drop, corrupt, delay-ms, suppress, reset-every-s.
    UnknownKey {
        /// The key as written.
        key: String,
    },
    /// The value does not parse as a number.
    BadNumber {
        /// The key whose value is wrong.
        key: &'static str,
        /// The value as written.
        value: String,
    },
    /// A probability outside 0..=1, or a negative time.
    OutOfRange {
        /// The key whose value is wrong.
        key: &'static str,
        /// The value as written.
        value: String,
    },
}

impl fmt::Display for FaultSpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MissingValue { item } => write!(f, "fault item `{item}` is not key=value"),
            Self::UnknownKey { key } => write!(
                f,
                "unknown fault `{key}` (known: drop, corrupt, delay-ms, suppress, reset-every-s)"
            ),
            Self::BadNumber { key, value } => write!(f, "fault `{key}`: `{value}` is not a number"),
            Self::OutOfRange { key, value } => write!(
                f,
                "fault `{key}`: `{value}` is out of range (probabilities 0..=1, times >= 0)"
            ),
        }
    }
}

impl std::error::Error for FaultSpecError {}

impl FromStr for FaultConfig {
    type Err = FaultSpecError;

    /// Parses `drop=0.01,corrupt=0.001,delay-ms=5,suppress=0.0,reset-every-s=0` (any subset, any
    /// order; an empty string is no faults).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut cfg = FaultConfig::default();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| FaultSpecError::MissingValue {
                    item: item.to_owned(),
                })?;
            let (k, v) = (k.trim(), v.trim());
            let key: &'static str = match k {
                "drop" => "drop",
                "corrupt" => "corrupt",
                "delay-ms" => "delay-ms",
                "suppress" => "suppress",
                "reset-every-s" => "reset-every-s",
                _ => return Err(FaultSpecError::UnknownKey { key: k.to_owned() }),
            };
            let x: f64 = v.parse().map_err(|_| FaultSpecError::BadNumber {
                key,
                value: v.to_owned(),
            })?;
            let is_prob = matches!(key, "drop" | "corrupt" | "suppress");
            if !x.is_finite() || x < 0.0 || (is_prob && x > 1.0) || (!is_prob && x > 1e9) {
                return Err(FaultSpecError::OutOfRange {
                    key,
                    value: v.to_owned(),
                });
            }
            match key {
                "drop" => cfg.drop = x,
                "corrupt" => cfg.corrupt = x,
                "delay-ms" => cfg.delay_us = (x * 1000.0).round() as u64,
                "suppress" => cfg.suppress = x,
                _ => cfg.reset_every_s = x,
            }
        }
        Ok(cfg)
    }
}

impl fmt::Display for FaultConfig {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "drop={},corrupt={},delay-ms={},suppress={},reset-every-s={}",
            self.drop,
            self.corrupt,
            self.delay_us as f64 / 1000.0,
            self.suppress,
            self.reset_every_s
        )
    }
}

/// Counters of injected faults.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FaultStats {
    /// Bytes dropped (both directions).
    pub dropped: u64,
    /// Bytes corrupted (both directions).
    pub corrupted: u64,
    /// Outgoing messages suppressed.
    pub suppressed: u64,
    /// Spontaneous resets.
    pub resets: u64,
}

/// The seeded fault source.
#[derive(Debug, Clone)]
pub struct FaultInjector {
    cfg: FaultConfig,
    rng: ChaCha8Rng,
    next_reset_us: Option<u64>,
    stats: FaultStats,
}

impl FaultInjector {
    /// A fault source with its own random stream derived from `seed`.
    pub fn new(cfg: FaultConfig, seed: u64) -> Self {
        let mut s = Self {
            cfg,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0xFA17_FA17_FA17_FA17),
            next_reset_us: None,
            stats: FaultStats::default(),
        };
        s.schedule_reset(0);
        s
    }

    /// The configuration.
    pub fn config(&self) -> &FaultConfig {
        &self.cfg
    }

    /// Counters so far.
    pub fn stats(&self) -> FaultStats {
        self.stats
    }

    /// Applies drop and corruption to one byte; `None` if it is lost.
    pub fn byte(&mut self, b: u8) -> Option<u8> {
        if self.cfg.drop > 0.0 && self.rng.random_bool(self.cfg.drop) {
            self.stats.dropped += 1;
            return None;
        }
        if self.cfg.corrupt > 0.0 && self.rng.random_bool(self.cfg.corrupt) {
            self.stats.corrupted += 1;
            return Some(b ^ (1 << self.rng.random_range(0..8)));
        }
        Some(b)
    }

    /// Whether the next outgoing message is suppressed.
    pub fn suppress(&mut self) -> bool {
        let s = self.cfg.suppress > 0.0 && self.rng.random_bool(self.cfg.suppress);
        if s {
            self.stats.suppressed += 1;
        }
        s
    }

    /// Delay for outgoing messages, microseconds.
    pub fn delay_us(&self) -> u64 {
        self.cfg.delay_us
    }

    /// Time of the next spontaneous reset, if any is scheduled.
    pub fn next_reset_us(&self) -> Option<u64> {
        self.next_reset_us
    }

    /// Records that the reset scheduled for `now_us` happened and schedules the next.
    pub fn reset_taken(&mut self, now_us: u64) {
        self.stats.resets += 1;
        self.schedule_reset(now_us);
    }

    fn schedule_reset(&mut self, now_us: u64) {
        self.next_reset_us = if self.cfg.reset_every_s > 0.0 {
            let u: f64 = self.rng.random::<f64>().max(1e-12);
            let gap_s = -u.ln() * self.cfg.reset_every_s;
            Some(now_us + (gap_s * 1e6).max(1.0) as u64)
        } else {
            None
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_parses_every_key_and_rejects_nonsense() {
        let c: FaultConfig = "drop=0.01,corrupt=0.001,delay-ms=5,suppress=0.5,reset-every-s=2"
            .parse()
            .unwrap();
        assert_eq!(
            c,
            FaultConfig {
                drop: 0.01,
                corrupt: 0.001,
                delay_us: 5000,
                suppress: 0.5,
                reset_every_s: 2.0
            }
        );
        assert_eq!("".parse::<FaultConfig>().unwrap(), FaultConfig::default());
        assert_eq!(
            "drop".parse::<FaultConfig>(),
            Err(FaultSpecError::MissingValue {
                item: "drop".into()
            })
        );
        assert_eq!(
            "loss=0.1".parse::<FaultConfig>(),
            Err(FaultSpecError::UnknownKey { key: "loss".into() })
        );
        assert_eq!(
            "drop=x".parse::<FaultConfig>(),
            Err(FaultSpecError::BadNumber {
                key: "drop",
                value: "x".into()
            })
        );
        assert_eq!(
            "drop=1.5".parse::<FaultConfig>(),
            Err(FaultSpecError::OutOfRange {
                key: "drop",
                value: "1.5".into()
            })
        );
        assert_eq!(
            "delay-ms=-1".parse::<FaultConfig>(),
            Err(FaultSpecError::OutOfRange {
                key: "delay-ms",
                value: "-1".into()
            })
        );
        assert_eq!(c.to_string().parse::<FaultConfig>().unwrap(), c);
    }

    #[test]
    fn rates_are_roughly_honoured_and_seeded() {
        let cfg = FaultConfig {
            drop: 0.1,
            corrupt: 0.1,
            ..Default::default()
        };
        let mut a = FaultInjector::new(cfg, 42);
        let mut b = FaultInjector::new(cfg, 42);
        let out_a: Vec<_> = (0..10_000u32).map(|i| a.byte(i as u8)).collect();
        let out_b: Vec<_> = (0..10_000u32).map(|i| b.byte(i as u8)).collect();
        assert_eq!(out_a, out_b, "same seed, same faults");
        let s = a.stats();
        assert!((800..1200).contains(&s.dropped), "{s:?}");
        assert!((700..1100).contains(&s.corrupted), "{s:?}");
        let flipped = out_a
            .iter()
            .enumerate()
            .filter_map(|(i, o)| o.map(|b| (i as u8 ^ b).count_ones()))
            .filter(|&n| n != 0)
            .collect::<Vec<_>>();
        assert!(flipped.iter().all(|&n| n == 1));
    }

    proptest::proptest! {
        #[test]
        fn display_parses_back(
            drop in 0.0f64..=1.0,
            corrupt in 0.0f64..=1.0,
            delay_us in 0u64..10_000_000,
            suppress in 0.0f64..=1.0,
            reset in 0.0f64..1e6,
        ) {
            let c = FaultConfig { drop, corrupt, delay_us: delay_us / 1000 * 1000, suppress, reset_every_s: reset };
            proptest::prop_assert_eq!(c.to_string().parse::<FaultConfig>(), Ok(c));
        }

        #[test]
        fn parser_never_panics(s in ".{0,80}") {
            let _ = s.parse::<FaultConfig>();
        }
    }

    #[test]
    fn resets_follow_the_mean_interval() {
        let cfg = FaultConfig {
            reset_every_s: 1.0,
            ..Default::default()
        };
        let mut f = FaultInjector::new(cfg, 7);
        let mut t = 0;
        for _ in 0..200 {
            t = f.next_reset_us().unwrap();
            f.reset_taken(t);
        }
        let mean_s = t as f64 / 1e6 / 200.0;
        assert!((0.8..1.2).contains(&mean_s), "{mean_s}");
        assert_eq!(
            FaultInjector::new(FaultConfig::default(), 7).next_reset_us(),
            None
        );
    }
}
