//! Byte-at-a-time message deframer with resynchronisation.
//!
//! Header bytes (`0x80..=0xFE`) and the terminator (`0xFF`) never occur inside
//! data, so the deframer can always find the next message: a header starts one
//! (dropping an unterminated one), `0xFF` ends one. Everything else that does not
//! fit is reported as a typed [`DeframeError`] and counted in [`DeframerStats`].

use crate::header::TERMINATOR;
use crate::wire::{RawMessage, MAX_DATA_LEN};

/// A framing problem found in the byte stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum DeframeError {
    /// A data byte arrived outside any message.
    Garbage { byte: u8 },
    /// A terminator arrived outside any message.
    StrayTerminator,
    /// A new header arrived before the previous message was terminated;
    /// `received` bytes had followed its header.
    Truncated { header: u8, received: usize },
    /// The message had more than [`MAX_DATA_LEN`] data bytes; it is skipped.
    Oversize { header: u8 },
    /// Header followed directly by the terminator: no checksum byte.
    MissingChecksum { header: u8 },
    /// The checksum byte does not match.
    ChecksumMismatch { header: u8, expected: u8, got: u8 },
}

/// Counts of frames and of each kind of framing error.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct DeframerStats {
    /// Well-formed messages delivered.
    pub frames: u32,
    /// Data bytes seen outside a message.
    pub garbage_bytes: u32,
    /// Terminators seen outside a message.
    pub stray_terminators: u32,
    /// Messages cut off by a new header.
    pub truncated: u32,
    /// Messages longer than the maximum.
    pub oversize: u32,
    /// Messages with no checksum byte.
    pub missing_checksum: u32,
    /// Messages whose checksum did not match.
    pub checksum_errors: u32,
}

impl DeframerStats {
    /// Total of all error counters.
    #[must_use]
    pub fn errors(&self) -> u32 {
        self.garbage_bytes
            + self.stray_terminators
            + self.truncated
            + self.oversize
            + self.missing_checksum
            + self.checksum_errors
    }

    fn count(&mut self, e: &DeframeError) {
        let c = match e {
            DeframeError::Garbage { .. } => &mut self.garbage_bytes,
            DeframeError::StrayTerminator => &mut self.stray_terminators,
            DeframeError::Truncated { .. } => &mut self.truncated,
            DeframeError::Oversize { .. } => &mut self.oversize,
            DeframeError::MissingChecksum { .. } => &mut self.missing_checksum,
            DeframeError::ChecksumMismatch { .. } => &mut self.checksum_errors,
        };
        *c = c.wrapping_add(1);
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    InMessage { header: u8 },
    Skipping,
}

/// Splits a byte stream into messages. Holds at most one message.
#[derive(Debug, Clone)]
pub struct Deframer {
    state: State,
    // data bytes followed by the checksum byte
    buf: [u8; MAX_DATA_LEN + 1],
    len: usize,
    // XOR of the header and every byte in `buf`, kept as bytes arrive so that the
    // checksum needs no second pass over the message
    sum: u8,
    stats: DeframerStats,
}

impl Default for Deframer {
    fn default() -> Self {
        Self::new()
    }
}

impl Deframer {
    /// An idle deframer.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            state: State::Idle,
            buf: [0; MAX_DATA_LEN + 1],
            len: 0,
            sum: 0,
            stats: DeframerStats {
                frames: 0,
                garbage_bytes: 0,
                stray_terminators: 0,
                truncated: 0,
                oversize: 0,
                missing_checksum: 0,
                checksum_errors: 0,
            },
        }
    }

    /// Counters since creation.
    #[must_use]
    pub fn stats(&self) -> &DeframerStats {
        &self.stats
    }

    /// Drops any partial message.
    pub fn reset(&mut self) {
        self.state = State::Idle;
        self.len = 0;
    }

    /// True while a message has started but not ended.
    #[must_use]
    pub fn in_message(&self) -> bool {
        !matches!(self.state, State::Idle)
    }

    fn fail(&mut self, e: DeframeError) -> Option<Result<RawMessage<'_>, DeframeError>> {
        self.stats.count(&e);
        Some(Err(e))
    }

    /// Feeds bytes from the front of `input` up to the first one that completes a message
    /// or an error, which it returns, and advances `input` past the bytes consumed. `None`
    /// means `input` was used up. The results are exactly those of [`push`](Self::push)
    /// on each byte, but a run of data bytes inside a message is copied in one go, which
    /// makes this the cheaper way to feed a received block.
    pub fn push_slice(
        &mut self,
        input: &mut &[u8],
    ) -> Option<Result<RawMessage<'_>, DeframeError>> {
        loop {
            if let State::InMessage { .. } = self.state {
                let room = self.buf.get_mut(self.len..).unwrap_or_default();
                let mut copied = 0;
                let mut sum = self.sum;
                for (slot, &byte) in room.iter_mut().zip(input.iter()) {
                    if byte > 0x7F {
                        break;
                    }
                    *slot = byte;
                    sum ^= byte;
                    copied += 1;
                }
                self.sum = sum;
                self.len += copied;
                *input = input.get(copied..).unwrap_or_default();
            }
            let (&byte, rest) = input.split_first()?;
            *input = rest;
            let quiet = match (self.state, byte) {
                (State::Idle | State::Skipping, 0x80..=0xFE) | (State::Skipping, _) => true,
                (State::InMessage { .. }, 0x00..=0x7F) => self.len < self.buf.len(),
                _ => false,
            };
            if !quiet {
                return self.push(byte);
            }
            let none = self.push(byte);
            debug_assert!(none.is_none());
        }
    }

    /// Feeds one byte; returns a message or an error when one completes.
    pub fn push(&mut self, byte: u8) -> Option<Result<RawMessage<'_>, DeframeError>> {
        match (self.state, byte) {
            (State::Idle, TERMINATOR) => self.fail(DeframeError::StrayTerminator),
            (State::Idle, 0x00..=0x7F) => self.fail(DeframeError::Garbage { byte }),
            (State::Idle | State::Skipping, header @ 0x80..=0xFE) => {
                self.state = State::InMessage { header };
                self.len = 0;
                self.sum = header;
                None
            }
            (State::Skipping, TERMINATOR) => {
                self.state = State::Idle;
                None
            }
            (State::Skipping, _) => None,
            (State::InMessage { header }, TERMINATOR) => {
                self.state = State::Idle;
                let len = core::mem::take(&mut self.len);
                let Some(&got) = len.checked_sub(1).and_then(|i| self.buf.get(i)) else {
                    return self.fail(DeframeError::MissingChecksum { header });
                };
                // `sum` covers the header, the data and the checksum byte itself.
                let expected = (self.sum ^ got) & 0x7F;
                if expected != got {
                    return self.fail(DeframeError::ChecksumMismatch {
                        header,
                        expected,
                        got,
                    });
                }
                self.stats.frames = self.stats.frames.wrapping_add(1);
                Some(Ok(RawMessage {
                    header,
                    data: self.buf.get(..len - 1).unwrap_or_default(),
                }))
            }
            (State::InMessage { header: old }, new @ 0x80..=0xFE) => {
                let received = self.len;
                self.state = State::InMessage { header: new };
                self.len = 0;
                self.sum = new;
                self.fail(DeframeError::Truncated {
                    header: old,
                    received,
                })
            }
            (State::InMessage { header }, data @ 0x00..=0x7F) => {
                let Some(slot) = self.buf.get_mut(self.len) else {
                    self.state = State::Skipping;
                    self.len = 0;
                    return self.fail(DeframeError::Oversize { header });
                };
                *slot = data;
                self.len += 1;
                self.sum ^= data;
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::checksum;
    use proptest::prelude::*;
    use std::vec::Vec;

    #[derive(Debug, PartialEq)]
    enum Out {
        Msg(u8, Vec<u8>),
        Err(DeframeError),
    }

    fn run(d: &mut Deframer, bytes: &[u8]) -> Vec<Out> {
        let mut out = Vec::new();
        for &b in bytes {
            match d.push(b) {
                Some(Ok(m)) => out.push(Out::Msg(m.header, m.data.to_vec())),
                Some(Err(e)) => out.push(Out::Err(e)),
                None => {}
            }
        }
        out
    }

    #[test]
    fn deframes_back_to_back_messages() {
        let mut d = Deframer::new();
        let out = run(&mut d, &[0xE8, 0x68, 0xFF, 0xE8, 0x05, 0x6D, 0xFF]);
        assert_eq!(out, [Out::Msg(0xE8, vec![]), Out::Msg(0xE8, vec![0x05])]);
        assert_eq!(d.stats().frames, 2);
        assert_eq!(d.stats().errors(), 0);
    }

    #[test]
    fn reports_each_error_kind() {
        let mut d = Deframer::new();
        let out = run(
            &mut d,
            &[
                0x11, 0xFF, // garbage, stray terminator
                0xE8, 0x01, 0xC0, 0x40, 0xFF, // truncated READ_ID, then STOP
                0xB1, 0x30, 0xFF, // the seed's UPD_SF error example
                0xC0, 0xFF, // no checksum
            ],
        );
        assert_eq!(
            out,
            [
                Out::Err(DeframeError::Garbage { byte: 0x11 }),
                Out::Err(DeframeError::StrayTerminator),
                Out::Err(DeframeError::Truncated {
                    header: 0xE8,
                    received: 1
                }),
                Out::Msg(0xC0, vec![]),
                Out::Err(DeframeError::ChecksumMismatch {
                    header: 0xB1,
                    expected: 0x31,
                    got: 0x30
                }),
                Out::Err(DeframeError::MissingChecksum { header: 0xC0 }),
            ]
        );
        let s = d.stats();
        assert_eq!(
            (
                s.garbage_bytes,
                s.stray_terminators,
                s.truncated,
                s.checksum_errors,
                s.missing_checksum
            ),
            (1, 1, 1, 1, 1)
        );
    }

    #[test]
    fn oversize_message_is_skipped_until_terminator() {
        let mut d = Deframer::new();
        let mut bytes = vec![0xFC];
        bytes.extend(std::iter::repeat_n(0x01, MAX_DATA_LEN + 5));
        bytes.extend([0xFF, 0xE0, 0x60, 0xFF]);
        let out = run(&mut d, &bytes);
        assert_eq!(
            out,
            [
                Out::Err(DeframeError::Oversize { header: 0xFC }),
                Out::Msg(0xE0, vec![])
            ]
        );
    }

    #[test]
    fn longest_data_field_is_accepted() {
        let mut d = Deframer::new();
        let data = [0x01u8; MAX_DATA_LEN];
        let mut bytes = vec![0xFC];
        bytes.extend_from_slice(&data);
        bytes.push(checksum(0xFC, &data));
        bytes.push(0xFF);
        assert_eq!(run(&mut d, &bytes), [Out::Msg(0xFC, data.to_vec())]);
    }

    /// Feeds `bytes` through `push_slice`, collecting what it returns.
    fn run_slices(d: &mut Deframer, bytes: &[u8]) -> Vec<Out> {
        let mut out = Vec::new();
        let mut input = bytes;
        while !input.is_empty() {
            match d.push_slice(&mut input) {
                Some(Ok(m)) => out.push(Out::Msg(m.header, m.data.to_vec())),
                Some(Err(e)) => out.push(Out::Err(e)),
                None => assert!(input.is_empty()),
            }
        }
        out
    }

    #[test]
    fn push_slice_stops_after_each_result() {
        let mut d = Deframer::new();
        let mut input: &[u8] = &[0xE8, 0x68, 0xFF, 0x11, 0xE8, 0x05];
        let first = d.push_slice(&mut input).map(|r| r.map(|m| m.header));
        assert_eq!(first, Some(Ok(0xE8)));
        assert_eq!(input, &[0x11, 0xE8, 0x05]);
        assert_eq!(
            d.push_slice(&mut input).map(|r| r.map(|m| m.header)),
            Some(Err(DeframeError::Garbage { byte: 0x11 }))
        );
        assert!(d.push_slice(&mut input).is_none());
        assert!(input.is_empty());
        assert!(d.in_message());
    }

    proptest! {
        #[test]
        fn push_slice_matches_push(
            chunks in proptest::collection::vec(
                proptest::collection::vec(
                    prop_oneof![Just(0xFFu8), Just(0xFCu8), 0u8..0x80, any::<u8>()],
                    0..90,
                ),
                0..6,
            )
        ) {
            let mut one = Deframer::new();
            let mut bulk = Deframer::new();
            let mut expected = Vec::new();
            let mut got = Vec::new();
            for chunk in &chunks {
                expected.extend(run(&mut one, chunk));
                got.extend(run_slices(&mut bulk, chunk));
            }
            prop_assert_eq!(got, expected);
            prop_assert_eq!(bulk.stats(), one.stats());
            prop_assert_eq!(bulk.in_message(), one.in_message());
        }

        /// The running checksum equals `wire::checksum`, for good and bad checksum bytes.
        #[test]
        fn checksum_is_checked(
            header in 0x80u8..0xFF,
            data in proptest::collection::vec(0u8..0x80, 0..MAX_DATA_LEN),
            got in 0u8..0x80,
        ) {
            let expected = checksum(header, &data);
            let mut bytes = vec![header];
            bytes.extend_from_slice(&data);
            bytes.extend([got, 0xFF]);
            let want = if got == expected {
                Out::Msg(header, data.clone())
            } else {
                Out::Err(DeframeError::ChecksumMismatch { header, expected, got })
            };
            prop_assert_eq!(run(&mut Deframer::new(), &bytes), vec![want]);
        }

        #[test]
        fn never_panics_and_resynchronises(garbage in proptest::collection::vec(any::<u8>(), 0..300)) {
            let mut d = Deframer::new();
            let _ = run(&mut d, &garbage);
            // Whatever came before, a complete message is found afterwards.
            let cs = checksum(0xE9, &[0x02, 0x40, 0x03, 0x60]);
            let out = run(&mut d, &[0xE9, 0x02, 0x40, 0x03, 0x60, cs, 0xFF]);
            prop_assert_eq!(out.last(), Some(&Out::Msg(0xE9, vec![0x02, 0x40, 0x03, 0x60])));
        }
    }
}
