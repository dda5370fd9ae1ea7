//! The LBC's periodic tasks (seed Table 2-2) released at their rates from a common epoch.
//!
//! Release times are exact on average: task `k`'s n-th release is at `epoch + ceil(n * 1e6 /
//! rate)` microseconds, so the 30 Hz streaming task alternates 33 333 and 33 334 us periods.
//! Tasks released at the same instant run in priority order (highest first), ties in table order,
//! as FreeRTOS would run them. The user-defined tasks of the seed are empty and not scheduled.

/// One LBC task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Task {
    /// Drive motor PID.
    VelocityControl,
    /// Encoder-based velocity estimate.
    VelocityEstimation,
    /// Overhead tracking input.
    TrackingReceiver,
    /// All ADC channels and the die temperature; gyro integration.
    AdcSampling,
    /// MOVE_XY / MOVE_SV targets to velocity and steering.
    PathGeneration,
    /// Decodes commands from the UBC and answers the quick ones.
    CommParser,
    /// Sends queued messages to the UART.
    CommMerger,
    /// EEPROM reads, writes, commits and restores.
    Eeprom,
    /// STREAM frames.
    DataStreaming,
    /// Battery level and die temperature warnings.
    Monitor,
    /// User LED patterns.
    Led,
    /// User GPIO patterns.
    Gpio,
}

impl Task {
    /// Every scheduled task, in seed table order.
    pub const ALL: [Task; 12] = [
        Task::VelocityControl,
        Task::VelocityEstimation,
        Task::TrackingReceiver,
        Task::AdcSampling,
        Task::PathGeneration,
        Task::CommParser,
        Task::CommMerger,
        Task::Eeprom,
        Task::DataStreaming,
        Task::Monitor,
        Task::Led,
        Task::Gpio,
    ];

    /// Release rate, Hz (Table 2-2).
    pub const fn rate_hz(self) -> u64 {
        match self {
            Task::VelocityControl
            | Task::VelocityEstimation
            | Task::TrackingReceiver
            | Task::CommParser
            | Task::CommMerger
            | Task::Led
            | Task::Gpio => 1000,
            Task::AdcSampling => 500,
            Task::PathGeneration => 50,
            Task::DataStreaming => 30,
            Task::Eeprom => 10,
            Task::Monitor => 1,
        }
    }

    /// Priority above the idle task (ITP + n), Table 2-2.
    pub const fn priority(self) -> u8 {
        match self {
            Task::VelocityControl => 6,
            Task::VelocityEstimation | Task::TrackingReceiver => 5,
            Task::AdcSampling => 4,
            Task::PathGeneration => 3,
            Task::CommParser | Task::CommMerger | Task::Eeprom | Task::DataStreaming => 2,
            Task::Monitor | Task::Led | Task::Gpio => 1,
        }
    }
}

/// Release bookkeeping for every task.
#[derive(Debug, Clone)]
pub struct Scheduler {
    epoch_us: u64,
    released: [u64; Task::ALL.len()],
}

impl Scheduler {
    /// Every task's first release is at `epoch_us`.
    pub fn new(epoch_us: u64) -> Self {
        Self {
            epoch_us,
            released: [0; Task::ALL.len()],
        }
    }

    fn due(&self, i: usize) -> u64 {
        let rate = Task::ALL[i].rate_hz();
        self.epoch_us + (self.released[i] * 1_000_000).div_ceil(rate)
    }

    /// Time of the next release.
    pub fn next_release_us(&self) -> u64 {
        (0..Task::ALL.len())
            .map(|i| self.due(i))
            .min()
            .unwrap_or(u64::MAX)
    }

    /// If the next release is at or before `until_us`, takes every task released at that instant
    /// (in run order) and returns the instant.
    pub fn release(&mut self, until_us: u64, out: &mut Vec<Task>) -> Option<u64> {
        out.clear();
        let t = self.next_release_us();
        if t > until_us {
            return None;
        }
        for i in 0..Task::ALL.len() {
            if self.due(i) == t {
                out.push(Task::ALL[i]);
                self.released[i] += 1;
            }
        }
        out.sort_by_key(|task| core::cmp::Reverse(task.priority()));
        Some(t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_second_releases_each_task_at_its_rate() {
        let mut s = Scheduler::new(5);
        let mut counts = std::collections::HashMap::new();
        let mut buf = Vec::new();
        while s.release(5 + 999_999, &mut buf).is_some() {
            for t in &buf {
                *counts.entry(*t).or_insert(0u64) += 1;
            }
        }
        for t in Task::ALL {
            assert_eq!(counts[&t], t.rate_hz(), "{t:?}");
        }
    }

    #[test]
    fn simultaneous_releases_run_by_priority() {
        let mut s = Scheduler::new(0);
        let mut buf = Vec::new();
        assert_eq!(s.release(0, &mut buf), Some(0));
        assert_eq!(buf.len(), 12);
        assert_eq!(buf[0], Task::VelocityControl);
        assert_eq!(buf[1], Task::VelocityEstimation);
        assert_eq!(buf[2], Task::TrackingReceiver);
        assert_eq!(buf[3], Task::AdcSampling);
        assert_eq!(buf[4], Task::PathGeneration);
        assert_eq!(*buf.last().unwrap(), Task::Gpio);
        assert!(buf.windows(2).all(|w| w[0].priority() >= w[1].priority()));
        assert_eq!(s.release(999, &mut buf), None);
        assert_eq!(s.release(1000, &mut buf), Some(1000));
        assert!(!buf.contains(&Task::AdcSampling));
        assert_eq!(s.release(2000, &mut buf), Some(2000));
        assert!(buf.contains(&Task::AdcSampling));
    }

    #[test]
    fn streaming_period_alternates_to_an_exact_30_hz() {
        let mut s = Scheduler::new(0);
        let mut buf = Vec::new();
        let mut times = Vec::new();
        while let Some(t) = s.release(200_000, &mut buf) {
            if buf.contains(&Task::DataStreaming) {
                times.push(t);
            }
        }
        assert_eq!(
            times,
            vec![0, 33_334, 66_667, 100_000, 133_334, 166_667, 200_000]
        );
    }
}
