//! The run window: where a frame's run buffer ([`crate::runs`]) reaches the firmware. On the
//! SoC it is the vision unit's register block and run memory; on QEMU (which has no such
//! device) it is RAM at the same address that the host writes the same way. Either way the
//! reader sees a 64-byte header, two control words, the class table and two run buffers, and
//! uses a published buffer with the frame window's ticket rule: take a ticket from a header
//! copy (`buffer_seq[ready] == sequence`), read the ready buffer, and keep the result only if a
//! second copy shows that buffer still holding the ticket's sequence. Field tables in
//! `docs/hal.md`; all fields are little-endian 32-bit words.

use core::ops::Range;

use crate::frame::{u16_at, u32_at};
use crate::runs::MAX_CAPACITY;

/// `b"ALRN"`.
pub const MAGIC: [u8; 4] = *b"ALRN";
/// Layout version.
pub const VERSION: u16 = 1;
/// Bytes of the published header.
pub const HEADER_LEN: usize = 64;
/// `buffer_seq` of a buffer being written.
pub const WRITING: u32 = u32::MAX;
/// Offsets of the two run buffers from the window's start.
pub const BUFFER_OFFSET: [usize; 2] = [0x4000, 0x8000];
/// Offset of the class table: 256 entries of one byte (low 4 bits used), written by the
/// firmware; write-only on the SoC.
pub const LUT_OFFSET: usize = 0x100;
/// Bytes the window spans (header, control, class table, both buffers of up to
/// [`MAX_CAPACITY`] words).
pub const WINDOW_LEN: usize = 0xC000;

/// Byte offsets of the header's fields and of the control words.
pub mod field {
    use core::ops::Range;
    pub const MAGIC: Range<usize> = 0..4;
    pub const VERSION: Range<usize> = 4..6;
    pub const HEADER_LEN: Range<usize> = 6..8;
    pub const CAPACITY: Range<usize> = 8..12;
    pub const BUFFER_OFFSET: [Range<usize>; 2] = [12..16, 16..20];
    pub const SEQUENCE: Range<usize> = 20..24;
    pub const READY: Range<usize> = 24..28;
    pub const BUFFER_SEQ: [Range<usize>; 2] = [28..32, 32..36];
    pub const COUNT: [Range<usize>; 2] = [36..40, 40..44];
    pub const DROPPED: [Range<usize>; 2] = [44..48, 48..52];
    pub const SIZE: [Range<usize>; 2] = [52..56, 56..60];
    pub const RESERVED: Range<usize> = 60..64;
    /// Control (read and write): bit 0 enable, bit 1 interrupt enable.
    pub const CTRL: Range<usize> = 64..68;
    /// Status: bit 0 a frame was published (write 1 to clear), bit 1 the unit is processing
    /// frames (read only).
    pub const STATUS: Range<usize> = 68..72;
}

/// Control word bits.
pub mod ctrl {
    /// Process frames (from the end of the next frame on).
    pub const ENABLE: u32 = 1;
    /// Raise the interrupt while `status::FRAME` is set.
    pub const IRQ_ENABLE: u32 = 2;
}

/// Status word bits.
pub mod status {
    /// A frame was published since the bit was last cleared (write 1 to clear).
    pub const FRAME: u32 = 1;
    /// The unit is processing frames.
    pub const ACTIVE: u32 = 2;
}

/// Why a run-window header is rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HeaderError {
    /// Fewer than [`HEADER_LEN`] bytes.
    Truncated { got: usize },
    /// Not `ALRN`: no vision unit, and no host writing runs.
    BadMagic { got: [u8; 4] },
    /// Another layout version.
    UnsupportedVersion { got: u16 },
    /// The header length field is not [`HEADER_LEN`].
    BadHeaderLen { got: u16 },
    /// Capacity 0 or above [`MAX_CAPACITY`].
    BadCapacity { got: u32 },
    /// A buffer does not lie where the layout puts it.
    BadBufferOffset { index: u8, got: u32 },
    /// The ready index is not 0 or 1.
    BadReadyIndex { got: u32 },
    /// A buffer's word count is above the capacity.
    BadCount { index: u8, got: u32 },
    /// Nothing published yet.
    NoFrame,
    /// The ready buffer does not hold the published sequence: read mid-publish.
    Inconsistent { sequence: u32, buffer_seq: u32 },
    /// The buffer was overwritten while it was read.
    Torn { expected: u32, found: u32 },
}

/// The parsed header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// Words per buffer.
    pub capacity: u32,
    pub sequence: u32,
    pub ready: u32,
    pub buffer_seq: [u32; 2],
    /// Words written into each buffer.
    pub count: [u32; 2],
    /// Runs each buffer's frame could not hold.
    pub dropped: [u32; 2],
    /// Width and height of each buffer's frame.
    pub size: [(u16, u16); 2],
}

/// Permission to use one published run buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunTicket {
    /// Buffer index.
    pub index: usize,
    /// Frame sequence it held.
    pub sequence: u32,
    /// Words in it.
    pub count: usize,
    /// Runs the frame lost for lack of room.
    pub dropped: u32,
    pub width: u16,
    pub height: u16,
}

impl RunTicket {
    /// Byte range of the ticket's words in the window.
    pub fn range(&self) -> Range<usize> {
        let start = BUFFER_OFFSET[self.index & 1];
        start..start + 4 * self.count
    }

    /// Checks a header copy taken after the buffer was used.
    pub fn verify(&self, later: &Header) -> Result<(), HeaderError> {
        let found = later.buffer_seq[self.index & 1];
        if found == self.sequence {
            Ok(())
        } else {
            Err(HeaderError::Torn {
                expected: self.sequence,
                found,
            })
        }
    }
}

impl Header {
    /// An empty header for buffers of `capacity` words (nothing published; buffer 0 is
    /// written first).
    pub fn new(capacity: u32) -> Self {
        Header {
            capacity,
            sequence: 0,
            ready: 1,
            buffer_seq: [WRITING, 0],
            count: [0; 2],
            dropped: [0; 2],
            size: [(0, 0); 2],
        }
    }

    /// Parses and checks a header copy (the first [`HEADER_LEN`] bytes).
    pub fn parse(bytes: &[u8]) -> Result<Self, HeaderError> {
        if bytes.len() < HEADER_LEN {
            return Err(HeaderError::Truncated { got: bytes.len() });
        }
        let mut magic = [0u8; 4];
        magic.copy_from_slice(&bytes[field::MAGIC]);
        if magic != MAGIC {
            return Err(HeaderError::BadMagic { got: magic });
        }
        let version = u16_at(bytes, field::VERSION);
        if version != VERSION {
            return Err(HeaderError::UnsupportedVersion { got: version });
        }
        let header_len = u16_at(bytes, field::HEADER_LEN);
        if usize::from(header_len) != HEADER_LEN {
            return Err(HeaderError::BadHeaderLen { got: header_len });
        }
        let capacity = u32_at(bytes, field::CAPACITY);
        if capacity == 0 || capacity as usize > MAX_CAPACITY {
            return Err(HeaderError::BadCapacity { got: capacity });
        }
        for (i, &want) in BUFFER_OFFSET.iter().enumerate() {
            let got = u32_at(bytes, field::BUFFER_OFFSET[i].clone());
            if got as usize != want {
                return Err(HeaderError::BadBufferOffset {
                    index: i as u8,
                    got,
                });
            }
        }
        let ready = u32_at(bytes, field::READY);
        if ready > 1 {
            return Err(HeaderError::BadReadyIndex { got: ready });
        }
        let count = [
            u32_at(bytes, field::COUNT[0].clone()),
            u32_at(bytes, field::COUNT[1].clone()),
        ];
        for (i, &c) in count.iter().enumerate() {
            if c > capacity {
                return Err(HeaderError::BadCount {
                    index: i as u8,
                    got: c,
                });
            }
        }
        let size = |i: usize| {
            let s = u32_at(bytes, field::SIZE[i].clone());
            (s as u16, (s >> 16) as u16)
        };
        Ok(Header {
            capacity,
            sequence: u32_at(bytes, field::SEQUENCE),
            ready,
            buffer_seq: [
                u32_at(bytes, field::BUFFER_SEQ[0].clone()),
                u32_at(bytes, field::BUFFER_SEQ[1].clone()),
            ],
            count,
            dropped: [
                u32_at(bytes, field::DROPPED[0].clone()),
                u32_at(bytes, field::DROPPED[1].clone()),
            ],
            size: [size(0), size(1)],
        })
    }

    /// Writes the header into the first [`HEADER_LEN`] bytes of `out` (shorter: nothing).
    pub fn emit(&self, out: &mut [u8]) {
        let Some(out) = out.get_mut(..HEADER_LEN) else {
            return;
        };
        let mut put = |r: Range<usize>, v: u32| out[r].copy_from_slice(&v.to_le_bytes());
        put(field::MAGIC, u32::from_le_bytes(MAGIC));
        put(
            field::VERSION.start..field::HEADER_LEN.end,
            u32::from(VERSION) | (HEADER_LEN as u32) << 16,
        );
        put(field::CAPACITY, self.capacity);
        put(field::SEQUENCE, self.sequence);
        put(field::READY, self.ready);
        put(field::RESERVED, 0);
        for (i, &offset) in BUFFER_OFFSET.iter().enumerate() {
            put(field::BUFFER_OFFSET[i].clone(), offset as u32);
            put(field::BUFFER_SEQ[i].clone(), self.buffer_seq[i]);
            put(field::COUNT[i].clone(), self.count[i]);
            put(field::DROPPED[i].clone(), self.dropped[i]);
            let (w, h) = self.size[i];
            put(field::SIZE[i].clone(), u32::from(w) | u32::from(h) << 16);
        }
    }

    /// A ticket for the ready buffer.
    pub fn ticket(&self) -> Result<RunTicket, HeaderError> {
        if self.sequence == 0 {
            return Err(HeaderError::NoFrame);
        }
        let index = (self.ready & 1) as usize;
        if self.buffer_seq[index] != self.sequence {
            return Err(HeaderError::Inconsistent {
                sequence: self.sequence,
                buffer_seq: self.buffer_seq[index],
            });
        }
        let (width, height) = self.size[index];
        Ok(RunTicket {
            index,
            sequence: self.sequence,
            count: self.count[index] as usize,
            dropped: self.dropped[index],
            width,
            height,
        })
    }
}

/// The writer's side of the protocol for a host that emulates the unit (QEMU): publishes one
/// frame's run words into the buffer that is not ready, through `put(offset, bytes)` (each call
/// one write, made in this order): `buffer_seq = WRITING`, the words, the buffer's count,
/// dropped runs and size, then `buffer_seq`, `ready` and `sequence`. `header` is the writer's
/// copy, updated; the new sequence is returned. Words beyond the capacity are not written.
pub fn publish<E>(
    header: &mut Header,
    words: &[u32],
    dropped: u32,
    size: (u16, u16),
    mut put: impl FnMut(usize, &[u8]) -> Result<(), E>,
) -> Result<u32, E> {
    let w = if header.sequence == 0 {
        0
    } else {
        ((header.ready & 1) ^ 1) as usize
    };
    let n = words.len().min(header.capacity as usize);
    header.buffer_seq[w] = WRITING;
    put(field::BUFFER_SEQ[w].start, &WRITING.to_le_bytes())?;
    let mut bytes = [0u8; 256];
    for (k, chunk) in words[..n].chunks(bytes.len() / 4).enumerate() {
        for (b, word) in bytes.chunks_exact_mut(4).zip(chunk) {
            b.copy_from_slice(&word.to_le_bytes());
        }
        put(BUFFER_OFFSET[w] + k * 256, &bytes[..4 * chunk.len()])?;
    }
    let next = next_sequence(header.sequence);
    header.count[w] = n as u32;
    header.dropped[w] = dropped;
    header.size[w] = size;
    put(field::COUNT[w].start, &(n as u32).to_le_bytes())?;
    put(field::DROPPED[w].start, &dropped.to_le_bytes())?;
    let sz = u32::from(size.0) | u32::from(size.1) << 16;
    put(field::SIZE[w].start, &sz.to_le_bytes())?;
    put(field::BUFFER_SEQ[w].start, &next.to_le_bytes())?;
    put(field::READY.start, &(w as u32).to_le_bytes())?;
    put(field::SEQUENCE.start, &next.to_le_bytes())?;
    header.buffer_seq[w] = next;
    header.ready = w as u32;
    header.sequence = next;
    Ok(next)
}

/// The sequence after `s`: never 0 (nothing published) or [`WRITING`].
pub const fn next_sequence(s: u32) -> u32 {
    if s >= WRITING - 1 {
        1
    } else {
        s + 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn arb_header() -> impl Strategy<Value = Header> {
        (
            1..=MAX_CAPACITY as u32,
            any::<u32>(),
            0..2u32,
            any::<[u32; 2]>(),
            any::<[u32; 2]>(),
            any::<[(u16, u16); 2]>(),
            any::<[u32; 2]>(),
        )
            .prop_map(
                |(capacity, sequence, ready, buffer_seq, c, size, dropped)| Header {
                    capacity,
                    sequence,
                    ready,
                    buffer_seq,
                    count: [c[0] % (capacity + 1), c[1] % (capacity + 1)],
                    dropped,
                    size,
                },
            )
    }

    proptest! {
        #[test]
        fn emit_then_parse_is_identity(h in arb_header()) {
            let mut b = [0u8; HEADER_LEN];
            h.emit(&mut b);
            prop_assert_eq!(Header::parse(&b), Ok(h));
        }

        #[test]
        fn parse_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
            let _ = Header::parse(&bytes);
        }
    }

    #[test]
    fn layout_is_byte_exact() {
        let mut h = Header::new(4096);
        h.sequence = 7;
        h.ready = 0;
        h.buffer_seq = [7, WRITING];
        h.count = [3, 0];
        h.dropped = [2, 0];
        h.size = [(640, 480), (0, 0)];
        let mut b = [0u8; HEADER_LEN];
        h.emit(&mut b);
        assert_eq!(&b[0..8], b"ALRN\x01\x00\x40\x00");
        assert_eq!(&b[8..12], &4096u32.to_le_bytes());
        assert_eq!(&b[12..20], &[0, 0x40, 0, 0, 0, 0x80, 0, 0]);
        assert_eq!(&b[20..28], &[7, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(&b[28..36], &[7, 0, 0, 0, 0xff, 0xff, 0xff, 0xff]);
        assert_eq!(
            &b[36..52],
            &[3, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(&b[52..56], &[0x80, 2, 0xe0, 1]);
        let t = Header::parse(&b).unwrap().ticket().unwrap();
        assert_eq!(
            t,
            RunTicket {
                index: 0,
                sequence: 7,
                count: 3,
                dropped: 2,
                width: 640,
                height: 480
            }
        );
        assert_eq!(t.range(), 0x4000..0x400c);
    }

    #[test]
    fn every_rejection() {
        let mut good = [0u8; HEADER_LEN];
        Header::new(16).emit(&mut good);
        assert_eq!(
            Header::parse(&good[..10]),
            Err(HeaderError::Truncated { got: 10 })
        );
        let patch = |r: Range<usize>, v: &[u8]| {
            let mut b = good;
            b[r].copy_from_slice(v);
            Header::parse(&b)
        };
        assert!(matches!(
            patch(field::MAGIC, b"ALFG"),
            Err(HeaderError::BadMagic { .. })
        ));
        assert_eq!(
            patch(field::VERSION, &[2, 0]),
            Err(HeaderError::UnsupportedVersion { got: 2 })
        );
        assert_eq!(
            patch(field::HEADER_LEN, &[32, 0]),
            Err(HeaderError::BadHeaderLen { got: 32 })
        );
        assert_eq!(
            patch(field::CAPACITY, &0u32.to_le_bytes()),
            Err(HeaderError::BadCapacity { got: 0 })
        );
        assert_eq!(
            patch(field::CAPACITY, &4097u32.to_le_bytes()),
            Err(HeaderError::BadCapacity { got: 4097 })
        );
        assert_eq!(
            patch(field::BUFFER_OFFSET[1].clone(), &0x100u32.to_le_bytes()),
            Err(HeaderError::BadBufferOffset {
                index: 1,
                got: 0x100
            })
        );
        assert_eq!(
            patch(field::READY, &2u32.to_le_bytes()),
            Err(HeaderError::BadReadyIndex { got: 2 })
        );
        assert_eq!(
            patch(field::COUNT[0].clone(), &17u32.to_le_bytes()),
            Err(HeaderError::BadCount { index: 0, got: 17 })
        );
        assert_eq!(
            Header::parse(&good).unwrap().ticket(),
            Err(HeaderError::NoFrame)
        );
    }

    #[test]
    fn tickets_and_torn_reads() {
        let mut h = Header::new(16);
        h.sequence = 3;
        h.ready = 1;
        h.buffer_seq = [WRITING, 2];
        assert_eq!(
            h.ticket(),
            Err(HeaderError::Inconsistent {
                sequence: 3,
                buffer_seq: 2
            })
        );
        h.buffer_seq[1] = 3;
        let t = h.ticket().unwrap();
        assert_eq!(t.verify(&h), Ok(()));
        h.buffer_seq[1] = WRITING;
        assert_eq!(
            t.verify(&h),
            Err(HeaderError::Torn {
                expected: 3,
                found: WRITING
            })
        );
    }

    #[test]
    fn published_frames_alternate_buffers_and_read_back() {
        let mut mem = [0u8; WINDOW_LEN];
        let mut h = Header::new(8);
        h.emit(&mut mem);
        let mut put = |off: usize, b: &[u8]| -> Result<(), ()> {
            mem.get_mut(off..off + b.len())
                .ok_or(())?
                .copy_from_slice(b);
            Ok(())
        };
        assert_eq!(publish(&mut h, &[1, 2, 3], 0, (640, 480), &mut put), Ok(1));
        assert_eq!(publish(&mut h, &[4; 12], 5, (640, 480), &mut put), Ok(2));
        let got = Header::parse(&mem).unwrap();
        assert_eq!(got, h);
        let t = got.ticket().unwrap();
        assert_eq!((t.index, t.sequence, t.count, t.dropped), (1, 2, 8, 5));
        assert_eq!(&mem[0x4000..0x400c], &[1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0]);
        assert_eq!(&mem[t.range()][..4], &[4, 0, 0, 0]);
        assert_eq!(got.count, [3, 8]);
    }

    #[test]
    fn sequences_skip_zero_and_writing() {
        assert_eq!(next_sequence(0), 1);
        assert_eq!(next_sequence(41), 42);
        assert_eq!(next_sequence(WRITING - 1), 1);
        assert_eq!(next_sequence(WRITING), 1);
    }
}
