//! Splits the radio byte stream into frames at `0x00` delimiters and decodes them.
//!
//! Garbage, truncated frames and overlong runs are reported as typed errors and the deframer
//! restarts at the next delimiter, so one lost byte costs at most the frame it belonged to.
//!
//! The COBS encoding is undone as the bytes arrive (a car receives some 450 state frames a
//! second in a full channel, and its processor's time is its budget): each code byte says how
//! many data bytes follow before the next code byte, with a zero between blocks unless the code
//! was 0xFF. The result is the same as decoding the whole frame at its delimiter (property test
//! against the `cobs` crate).

use crate::wire::{Frame, FrameError, MAX_ENCODED, MAX_RAW};

/// Stream-to-frame decoder.
#[derive(Debug)]
pub struct Deframer {
    raw: [u8; MAX_RAW],
    /// Decoded bytes so far.
    len: usize,
    /// Encoded bytes so far (0: between frames).
    encoded: usize,
    /// Data bytes left in the current block.
    left: u8,
    /// The current block's code was below 0xFF: a zero precedes the next block's data.
    zero_next: bool,
    /// The frame outgrew the buffers: reported as oversize at its delimiter.
    overflowed: bool,
}

impl Default for Deframer {
    fn default() -> Self {
        Self::new()
    }
}

impl Deframer {
    /// An empty deframer.
    pub const fn new() -> Self {
        Self {
            raw: [0; MAX_RAW],
            len: 0,
            encoded: 0,
            left: 0,
            zero_next: false,
            overflowed: false,
        }
    }

    fn put(&mut self, b: u8) {
        match self.raw.get_mut(self.len) {
            Some(slot) => {
                *slot = b;
                self.len += 1;
            }
            None => self.overflowed = true,
        }
    }

    /// Feed one byte; returns a result when a delimiter closes a non-empty frame.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, FrameError>> {
        let res = self.push_raw(byte)?;
        let frame = res.and_then(|n| Frame::parse(self.raw.get(..n).unwrap_or(&[])));
        Some(frame)
    }

    /// Feed one byte; when a delimiter closes a non-empty frame, the length of its decoded
    /// bytes (at the start of the buffer until the next byte) or why it is not one.
    fn push_raw(&mut self, byte: u8) -> Option<Result<usize, FrameError>> {
        if byte != 0 {
            self.encoded += 1;
            if self.encoded > MAX_ENCODED {
                self.overflowed = true;
            } else if self.left > 0 {
                self.left -= 1;
                self.put(byte);
            } else {
                // A code byte: the zero ending the previous block, then `byte - 1` data bytes.
                if self.zero_next {
                    self.put(0);
                }
                self.left = byte - 1;
                self.zero_next = byte < 0xFF;
            }
            return None;
        }
        if self.encoded == 0 {
            return None;
        }
        let res = if self.overflowed {
            Err(FrameError::Oversize)
        } else if self.left > 0 {
            // The last block ends before its code said.
            Err(FrameError::Cobs)
        } else {
            Ok(self.len)
        };
        self.len = 0;
        self.encoded = 0;
        self.left = 0;
        self.zero_next = false;
        self.overflowed = false;
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

    /// Whole-frame COBS decoding with the `cobs` crate, for comparison: the decoded bytes of a
    /// frame, or why there are none.
    #[derive(Default)]
    struct Reference {
        buf: std::vec::Vec<u8>,
        overflowed: bool,
    }

    impl Reference {
        fn push(&mut self, byte: u8) -> Option<Result<std::vec::Vec<u8>, FrameError>> {
            if byte != 0 {
                if self.buf.len() < MAX_ENCODED {
                    self.buf.push(byte);
                } else {
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
                Ok(report) => Ok(raw[..report.frame_size()].to_vec()),
                Err(cobs::DecodeError::TargetBufTooSmall) => Err(FrameError::Oversize),
                Err(_) => Err(FrameError::Cobs),
            };
            self.buf.clear();
            Some(res)
        }
    }

    fn same_as_reference(stream: &[u8]) -> Result<(), proptest::test_runner::TestCaseError> {
        let mut d = Deframer::new();
        let mut r = Reference::default();
        for &b in stream {
            let got = d.push_raw(b).map(|x| x.map(|n| d.raw[..n].to_vec()));
            proptest::prop_assert_eq!(got, r.push(b));
        }
        Ok(())
    }

    use proptest::prelude::Strategy;

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(512))]
        /// Any stream (noise, encoded payloads of any length, frames cut short, long runs)
        /// decodes to the same bytes as whole-frame decoding.
        #[test]
        fn incremental_decoding_equals_whole_frame_decoding(
            parts in proptest::collection::vec(
                proptest::prop_oneof![
                    proptest::collection::vec(proptest::prelude::any::<u8>(), 0..40),
                    proptest::collection::vec(1u8..=255, 0..300),
                    // real COBS encodings of payloads around the block sizes (253, 254, 255)
                    (proptest::collection::vec(proptest::prelude::any::<u8>(), 0..20), 240usize..270)
                        .prop_map(|(seed, n)| {
                            let raw: std::vec::Vec<u8> =
                                (0..n).map(|k| seed.get(k % seed.len().max(1)).copied().unwrap_or(1) | (k == 0) as u8).collect();
                            let mut enc = std::vec![0u8; n + n / 254 + 2];
                            let m = cobs::encode(&raw, &mut enc);
                            enc.truncate(m);
                            enc.push(0);
                            enc
                        }),
                    (1u8..=126, proptest::prelude::any::<u8>(), 0usize..20).prop_map(|(id, seq, cut)| {
                        let f = encode_frame(&state(id, seq)).unwrap();
                        f[..f.len().saturating_sub(cut % 3)].to_vec()
                    }),
                ],
                0..12,
            )
        ) {
            same_as_reference(&parts.concat())?;
        }
    }

    #[test]
    fn blocks_of_every_boundary_length() {
        for n in [1usize, 2, 252, 253, 254, 255, 256, 507, 508] {
            let raw: std::vec::Vec<u8> = (0..n).map(|k| (k % 7) as u8).collect();
            let mut enc = std::vec![0u8; n + n / 254 + 2];
            let m = cobs::encode(&raw, &mut enc);
            enc.truncate(m);
            enc.push(0);
            same_as_reference(&enc).unwrap();
        }
    }

    #[test]
    fn idle_delimiters_are_silent() {
        let mut d = Deframer::new();
        assert!(feed(&mut d, &[0, 0, 0]).is_empty());
    }
}
