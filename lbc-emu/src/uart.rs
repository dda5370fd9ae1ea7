//! The LBC's transmit side of the 115200 8N1 UART.
//!
//! One byte is ten bit times (start, 8 data, stop) = 86.8 us, so bytes leave no faster than that.
//! Messages are queued with the earliest time they may start; each byte is stamped with the time
//! its stop bit ends, which is when the other side has it. The queue is bounded like the real
//! COMM Merger's buffer; a message that does not fit is dropped whole and counted.

use std::collections::VecDeque;

/// Line rate, bit/s.
pub const BAUD: u64 = 115_200;
/// Bits per byte on the line (8N1).
pub const BITS_PER_BYTE: u64 = 10;
/// Queue capacity, bytes.
pub const TX_QUEUE_BYTES: usize = 4096;

/// Time one byte occupies the line, nanoseconds (rounded down; [`UartTx`] keeps exact time).
pub const BYTE_TIME_NS: u64 = BITS_PER_BYTE * 1_000_000_000 / BAUD;

/// Paced transmitter.
#[derive(Debug, Clone, Default)]
pub struct UartTx {
    queue: VecDeque<(u64, u8)>,
    /// Line busy until this time, in units of 1/BAUD us (one bit time = 1_000_000 units).
    line_free_bitus: u128,
    dropped_messages: u64,
    sent_bytes: u64,
}

impl UartTx {
    /// An idle transmitter.
    pub fn new() -> Self {
        Self::default()
    }

    /// Queues a whole message that may start no earlier than `ready_us`. Returns `false` (and
    /// queues nothing) when it does not fit.
    pub fn push_message(&mut self, ready_us: u64, bytes: &[u8]) -> bool {
        if self.queue.len() + bytes.len() > TX_QUEUE_BYTES {
            self.dropped_messages += 1;
            return false;
        }
        self.queue.extend(bytes.iter().map(|&b| (ready_us, b)));
        true
    }

    /// The next byte that has completely left the line by `until_us`, with that time.
    pub fn pop(&mut self, until_us: u64) -> Option<(u64, u8)> {
        let &(ready_us, b) = self.queue.front()?;
        // Work in "bit-microseconds": t_us * BAUD, so one byte is exactly 10 * 1e6 units.
        let ready = u128::from(ready_us) * u128::from(BAUD);
        let start = ready.max(self.line_free_bitus);
        let done = start + u128::from(BITS_PER_BYTE) * 1_000_000;
        let done_us = done.div_ceil(u128::from(BAUD)) as u64;
        if done_us > until_us {
            return None;
        }
        self.queue.pop_front();
        self.line_free_bitus = done;
        self.sent_bytes += 1;
        Some((done_us, b))
    }

    /// Bytes waiting.
    pub fn pending(&self) -> usize {
        self.queue.len()
    }

    /// Time at which the next byte will have left, if one is queued.
    pub fn next_departure_us(&self) -> Option<u64> {
        let &(ready_us, _) = self.queue.front()?;
        let ready = u128::from(ready_us) * u128::from(BAUD);
        let done = ready.max(self.line_free_bitus) + u128::from(BITS_PER_BYTE) * 1_000_000;
        Some(done.div_ceil(u128::from(BAUD)) as u64)
    }

    /// Discards everything queued (an LBC reset); the byte on the line, if any, still finishes.
    pub fn clear(&mut self) {
        self.queue.clear();
    }

    /// Messages dropped because the queue was full.
    pub fn dropped_messages(&self) -> u64 {
        self.dropped_messages
    }

    /// Bytes sent so far.
    pub fn sent_bytes(&self) -> u64 {
        self.sent_bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_leave_at_line_rate() {
        let mut tx = UartTx::new();
        assert!(tx.push_message(1000, &[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]));
        assert_eq!(tx.pop(1000), None);
        let mut times = Vec::new();
        while let Some((t, _)) = tx.pop(u64::MAX) {
            times.push(t);
        }
        assert_eq!(times.len(), 10);
        assert_eq!(times[0], 1087); // 86.8 us after it may start
                                    // Ten bytes take 868.06 us.
        assert_eq!(times[9], 1000 + 869);
        for w in times.windows(2) {
            assert!((86..=87).contains(&(w[1] - w[0])));
        }
        assert_eq!(BYTE_TIME_NS, 86_805);
    }

    #[test]
    fn a_later_message_waits_for_the_line_and_for_its_ready_time() {
        let mut tx = UartTx::new();
        tx.push_message(0, &[0xAA; 3]);
        tx.push_message(100, &[0xBB]);
        tx.push_message(10_000, &[0xCC]);
        let all: Vec<_> = std::iter::from_fn(|| tx.pop(u64::MAX)).collect();
        assert_eq!(all[3], (348, 0xBB)); // line busy until 260.4 us, then 86.8 us
        assert_eq!(all[4], (10_087, 0xCC));
    }

    #[test]
    fn queue_is_bounded() {
        let mut tx = UartTx::new();
        assert!(tx.push_message(0, &[0; TX_QUEUE_BYTES]));
        assert!(!tx.push_message(0, &[0]));
        assert_eq!(tx.dropped_messages(), 1);
        tx.clear();
        assert_eq!(tx.pending(), 0);
    }
}
