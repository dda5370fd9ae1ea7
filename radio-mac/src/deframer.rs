//! Splits the radio byte stream into frames at `0x00` delimiters and decodes them.
//!
//! Garbage, truncated frames and overlong runs are reported as typed errors and the deframer
//! restarts at the next delimiter, so one lost byte costs at most the frame it belonged to.

use crate::wire::{Frame, FrameError, MAX_ENCODED, MAX_RAW};
use heapless::Vec;

/// Stream-to-frame decoder.
#[derive(Debug, Default)]
pub struct Deframer {
    buf: Vec<u8, MAX_ENCODED>,
    overflowed: bool,
}

impl Deframer {
    /// An empty deframer.
    pub const fn new() -> Self {
        Self {
            buf: Vec::new(),
            overflowed: false,
        }
    }

    /// Feed one byte; returns a result when a delimiter closes a non-empty frame.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, FrameError>> {
        if byte != 0 {
            if self.buf.push(byte).is_err() {
                self.overflowed = true;
            }
            return None;
        }
        if self.overflowed {
            self.overflowed = false;
            self.buf.clear();
            return Some(Err(FrameError::Oversize));
        }
        if self.buf.is_empty() {
            return None;
        }
        let mut raw = [0u8; MAX_RAW];
        let res = match cobs::decode(&self.buf, &mut raw) {
            Ok(report) => Frame::parse(raw.get(..report.frame_size()).unwrap_or(&[])),
            Err(cobs::DecodeError::TargetBufTooSmall) => Err(FrameError::Oversize),
            Err(_) => Err(FrameError::Cobs),
        };
        self.buf.clear();
        Some(res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::addr::CarId;
    use crate::wire::{encode_frame, CarState};

    fn state(id: u8, seq: u8) -> Frame {
        Frame::State {
            src: CarId::new(id).unwrap(),
            seq,
            state: CarState {
                x: 100,
                y: 200,
                ..CarState::default()
            },
        }
    }

    fn feed(d: &mut Deframer, bytes: &[u8]) -> std::vec::Vec<Result<Frame, FrameError>> {
        bytes.iter().filter_map(|b| d.push(*b)).collect()
    }

    #[test]
    fn resyncs_after_garbage_and_truncation() {
        let mut d = Deframer::new();
        let a = encode_frame(&state(1, 1)).unwrap();
        let b = encode_frame(&state(2, 2)).unwrap();
        let mut stream = std::vec::Vec::new();
        stream.extend_from_slice(&[0x55, 0xAA, 0x13]);
        stream.extend_from_slice(&a[..5]); // truncated frame runs into the next one
        stream.extend_from_slice(&b);
        stream.extend_from_slice(&a);
        let out = feed(&mut d, &stream);
        assert_eq!(out.len(), 2);
        assert!(out[0].is_err());
        assert_eq!(out[1], Ok(state(1, 1)));
        // The garbage swallowed frame b; the next delimiter restarted cleanly.
        let out = feed(&mut d, &b);
        assert_eq!(out, [Ok(state(2, 2))]);
    }

    #[test]
    fn oversize_is_reported_once() {
        let mut d = Deframer::new();
        let out = feed(&mut d, &[0x01; 200]);
        assert!(out.is_empty());
        assert_eq!(d.push(0), Some(Err(FrameError::Oversize)));
        let a = encode_frame(&state(3, 9)).unwrap();
        assert_eq!(feed(&mut d, &a), [Ok(state(3, 9))]);
    }

    #[test]
    fn idle_delimiters_are_silent() {
        let mut d = Deframer::new();
        assert!(feed(&mut d, &[0, 0, 0]).is_empty());
    }
}
