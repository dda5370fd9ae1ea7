//! The frame-grabber window: a RAM region holding a 64-byte header and two frame buffers.
//!
//! The writer (the camera, or the host renderer through QEMU's shared RAM) fills the buffer that is
//! not ready, then publishes it by updating the header. The reader never uses a torn frame: it
//! takes a [`FrameTicket`] from a header copy, processes the ready buffer in place, and keeps the
//! result only if a second header copy still shows that buffer holding the ticket's sequence
//! ([`FrameTicket::verify`]). The field table is in `docs/camera.md`; all fields are little-endian.

use core::ops::Range;

/// `b"ALFG"`.
pub const MAGIC: [u8; 4] = *b"ALFG";
/// Layout version written by this crate.
pub const VERSION: u16 = 1;
/// Bytes of the header at the start of the window.
pub const HEADER_LEN: usize = 64;
/// Number of frame buffers (double buffering).
pub const BUFFER_COUNT: usize = 2;
/// Frame buffers start on this alignment.
pub const BUFFER_ALIGN: usize = 4096;
/// Width of the upper board's camera (seed 1.1).
pub const CAMERA_WIDTH: u16 = 640;
/// Height of the upper board's camera (seed 1.1).
pub const CAMERA_HEIGHT: u16 = 480;
/// Largest accepted width or height.
pub const MAX_DIMENSION: u16 = 4096;
/// `buffer_seq` value while the writer is filling that buffer.
pub const WRITING: u32 = u32::MAX;
/// Size of the window the boards reserve: room for two 640x480 RGB565 frames.
pub const WINDOW_LEN: usize = 0x0013_0000;

/// Byte ranges of the header's fields (little-endian; the table in `docs/camera.md`).
pub mod field {
    use core::ops::Range;
    pub const MAGIC: Range<usize> = 0..4;
    pub const VERSION: Range<usize> = 4..6;
    pub const HEADER_LEN: Range<usize> = 6..8;
    pub const WIDTH: Range<usize> = 8..10;
    pub const HEIGHT: Range<usize> = 10..12;
    pub const FORMAT: Range<usize> = 12..14;
    pub const BUFFER_COUNT: Range<usize> = 14..16;
    pub const STRIDE: Range<usize> = 16..20;
    pub const BUFFER_OFFSET: [Range<usize>; 2] = [20..24, 24..28];
    pub const SEQUENCE: Range<usize> = 28..32;
    pub const READY: Range<usize> = 32..36;
    pub const BUFFER_SEQ: [Range<usize>; 2] = [36..40, 40..44];
    pub const RESERVED: Range<usize> = 44..48;
    pub const CAPTURE_US: [Range<usize>; 2] = [48..56, 56..64];
}

/// How pixels are stored in a frame buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PixelFormat {
    /// 16 bits per pixel, little-endian, `RRRRRGGG GGGBBBBB` (red in the high bits).
    Rgb565,
    /// 8 bits per pixel, `RRRGGGBB`: the grabber's default; half the memory and bandwidth of RGB565.
    Rgb332,
}

impl PixelFormat {
    /// Code stored in the header.
    pub const fn code(self) -> u16 {
        match self {
            PixelFormat::Rgb565 => 1,
            PixelFormat::Rgb332 => 2,
        }
    }

    /// The format with header code `code`, if any.
    pub const fn from_code(code: u16) -> Option<Self> {
        match code {
            1 => Some(PixelFormat::Rgb565),
            2 => Some(PixelFormat::Rgb332),
            _ => None,
        }
    }

    /// Bytes per pixel.
    pub const fn bytes_per_pixel(self) -> usize {
        match self {
            PixelFormat::Rgb565 => 2,
            PixelFormat::Rgb332 => 1,
        }
    }
}

/// Why a header (or a frame read against it) is rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HeaderError {
    /// Fewer bytes than the header or the buffers it describes need.
    Truncated { needed: usize, got: usize },
    /// The first four bytes are not `ALFG`.
    BadMagic { got: [u8; 4] },
    /// A layout version this crate does not know.
    UnsupportedVersion { got: u16 },
    /// The header length field is not [`HEADER_LEN`].
    BadHeaderLen { got: u16 },
    /// Width or height is zero or above [`MAX_DIMENSION`].
    BadDimensions { width: u16, height: u16 },
    /// Unknown pixel format code.
    UnknownPixelFormat { code: u16 },
    /// The buffer count is not [`BUFFER_COUNT`].
    BadBufferCount { got: u16 },
    /// The stride is smaller than one row of pixels.
    StrideTooSmall { stride: u32, min: u32 },
    /// A buffer overlaps the header or the other buffer.
    BufferOverlap { index: u8 },
    /// The ready index is not 0 or 1.
    BadReadyIndex { got: u32 },
    /// No frame has been published yet (sequence 0).
    NoFrame,
    /// The ready buffer does not hold the published sequence: the header was read mid-publish.
    Inconsistent { sequence: u32, buffer_seq: u32 },
    /// The buffer was (or is being) overwritten while it was read.
    Torn { expected: u32, found: u32 },
}

/// The parsed header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HeaderRepr {
    pub width: u16,
    pub height: u16,
    pub format: PixelFormat,
    /// Bytes from one row to the next.
    pub stride: u32,
    /// Offsets of the two buffers from the start of the window.
    pub buffer_offset: [u32; 2],
    /// Sequence of the latest published frame; 0 before the first.
    pub sequence: u32,
    /// Index of the buffer holding frame `sequence`.
    pub ready: u32,
    /// Sequence each buffer holds, [`WRITING`] while being filled.
    pub buffer_seq: [u32; 2],
    /// Capture time of each buffer's frame, microseconds of the writer's clock.
    pub capture_us: [u64; 2],
}

/// Permission to use one published buffer, taken from a header copy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameTicket {
    /// Buffer index.
    pub index: usize,
    /// Frame sequence the buffer held when the ticket was taken.
    pub sequence: u32,
    /// Capture time of that frame.
    pub capture_us: u64,
}

impl FrameTicket {
    /// Checks a header copy taken after the frame was used: the frame was whole only if its buffer
    /// still holds the same sequence.
    pub fn verify(&self, later: &HeaderRepr) -> Result<(), HeaderError> {
        let found = later.buffer_seq[self.index];
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

/// The little-endian `u16` at `b[r]` (`r` two bytes long).
pub(crate) fn u16_at(b: &[u8], r: Range<usize>) -> u16 {
    let mut a = [0u8; 2];
    a.copy_from_slice(&b[r]);
    u16::from_le_bytes(a)
}

/// The little-endian `u32` at `b[r]` (`r` four bytes long).
// Out of line (header fields only): a byte-wise copy inlined at each of a dozen uses cost the
// firmware 384 bytes more.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub(crate) fn u32_at(b: &[u8], r: Range<usize>) -> u32 {
    let mut a = [0u8; 4];
    a.copy_from_slice(&b[r]);
    u32::from_le_bytes(a)
}

fn u64_at(b: &[u8], r: Range<usize>) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[r]);
    u64::from_le_bytes(a)
}

const fn align_up(n: usize, a: usize) -> usize {
    n.div_ceil(a) * a
}

impl HeaderRepr {
    /// A fresh header for a window with nothing published, buffers placed on [`BUFFER_ALIGN`].
    pub fn new(width: u16, height: u16, format: PixelFormat) -> Self {
        let stride = u32::from(width) * format.bytes_per_pixel() as u32;
        let frame_len = stride as usize * usize::from(height);
        let first = BUFFER_ALIGN;
        let second = first + align_up(frame_len, BUFFER_ALIGN);
        HeaderRepr {
            width,
            height,
            format,
            stride,
            buffer_offset: [first as u32, second as u32],
            sequence: 0,
            ready: 0,
            buffer_seq: [0, 0],
            capture_us: [0, 0],
        }
    }

    /// Bytes of one frame buffer.
    pub fn frame_len(&self) -> usize {
        self.stride as usize * usize::from(self.height)
    }

    /// Bytes of window the header describes (header and both buffers).
    pub fn window_len(&self) -> usize {
        let end = |i: usize| self.buffer_offset[i] as usize + self.frame_len();
        end(0).max(end(1))
    }

    /// Byte range of buffer `index` (0 or 1) inside the window.
    pub fn buffer_range(&self, index: usize) -> Range<usize> {
        let start = self.buffer_offset[index & 1] as usize;
        start..start + self.frame_len()
    }

    /// Parses and checks a header copy. Only the first [`HEADER_LEN`] bytes are read.
    pub fn parse(bytes: &[u8]) -> Result<Self, HeaderError> {
        if bytes.len() < HEADER_LEN {
            return Err(HeaderError::Truncated {
                needed: HEADER_LEN,
                got: bytes.len(),
            });
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
        let width = u16_at(bytes, field::WIDTH);
        let height = u16_at(bytes, field::HEIGHT);
        if width == 0 || height == 0 || width > MAX_DIMENSION || height > MAX_DIMENSION {
            return Err(HeaderError::BadDimensions { width, height });
        }
        let code = u16_at(bytes, field::FORMAT);
        let format =
            PixelFormat::from_code(code).ok_or(HeaderError::UnknownPixelFormat { code })?;
        let count = u16_at(bytes, field::BUFFER_COUNT);
        if usize::from(count) != BUFFER_COUNT {
            return Err(HeaderError::BadBufferCount { got: count });
        }
        let stride = u32_at(bytes, field::STRIDE);
        let min = u32::from(width) * format.bytes_per_pixel() as u32;
        // Bounded so that stride * height stays far inside u32 and usize on a 32-bit core.
        if stride < min || stride > 4 * u32::from(MAX_DIMENSION) {
            return Err(HeaderError::StrideTooSmall { stride, min });
        }
        let repr = HeaderRepr {
            width,
            height,
            format,
            stride,
            buffer_offset: [
                u32_at(bytes, field::BUFFER_OFFSET[0].clone()),
                u32_at(bytes, field::BUFFER_OFFSET[1].clone()),
            ],
            sequence: u32_at(bytes, field::SEQUENCE),
            ready: u32_at(bytes, field::READY),
            buffer_seq: [
                u32_at(bytes, field::BUFFER_SEQ[0].clone()),
                u32_at(bytes, field::BUFFER_SEQ[1].clone()),
            ],
            capture_us: [
                u64_at(bytes, field::CAPTURE_US[0].clone()),
                u64_at(bytes, field::CAPTURE_US[1].clone()),
            ],
        };
        let len = repr.frame_len() as u64;
        let span = |i: usize| {
            let s = u64::from(repr.buffer_offset[i]);
            (s, s + len)
        };
        let (a0, a1) = span(0);
        let (b0, b1) = span(1);
        if a0 < HEADER_LEN as u64 || a1 > u64::from(u32::MAX) {
            return Err(HeaderError::BufferOverlap { index: 0 });
        }
        if b0 < HEADER_LEN as u64 || b1 > u64::from(u32::MAX) || (a0 < b1 && b0 < a1) {
            return Err(HeaderError::BufferOverlap { index: 1 });
        }
        if repr.ready > 1 {
            return Err(HeaderError::BadReadyIndex { got: repr.ready });
        }
        Ok(repr)
    }

    /// Writes this header into the first [`HEADER_LEN`] bytes of `out`.
    pub fn emit(&self, out: &mut [u8]) -> Result<(), HeaderError> {
        if out.len() < HEADER_LEN {
            return Err(HeaderError::Truncated {
                needed: HEADER_LEN,
                got: out.len(),
            });
        }
        out[field::MAGIC].copy_from_slice(&MAGIC);
        out[field::VERSION].copy_from_slice(&VERSION.to_le_bytes());
        out[field::HEADER_LEN].copy_from_slice(&(HEADER_LEN as u16).to_le_bytes());
        out[field::WIDTH].copy_from_slice(&self.width.to_le_bytes());
        out[field::HEIGHT].copy_from_slice(&self.height.to_le_bytes());
        out[field::FORMAT].copy_from_slice(&self.format.code().to_le_bytes());
        out[field::BUFFER_COUNT].copy_from_slice(&(BUFFER_COUNT as u16).to_le_bytes());
        out[field::STRIDE].copy_from_slice(&self.stride.to_le_bytes());
        out[field::SEQUENCE].copy_from_slice(&self.sequence.to_le_bytes());
        out[field::READY].copy_from_slice(&self.ready.to_le_bytes());
        out[field::RESERVED].fill(0);
        for i in 0..BUFFER_COUNT {
            out[field::BUFFER_OFFSET[i].clone()]
                .copy_from_slice(&self.buffer_offset[i].to_le_bytes());
            out[field::BUFFER_SEQ[i].clone()].copy_from_slice(&self.buffer_seq[i].to_le_bytes());
            out[field::CAPTURE_US[i].clone()].copy_from_slice(&self.capture_us[i].to_le_bytes());
        }
        Ok(())
    }

    /// The published frame, if this header copy shows one consistently.
    pub fn ticket(&self) -> Result<FrameTicket, HeaderError> {
        if self.sequence == 0 {
            return Err(HeaderError::NoFrame);
        }
        let index = (self.ready & 1) as usize;
        let buffer_seq = self.buffer_seq[index];
        if buffer_seq != self.sequence {
            return Err(HeaderError::Inconsistent {
                sequence: self.sequence,
                buffer_seq,
            });
        }
        Ok(FrameTicket {
            index,
            sequence: self.sequence,
            capture_us: self.capture_us[index],
        })
    }
}

/// A checked view of a whole window (header and buffers), for readers that see the window as one
/// slice (the host, tests) and for writers (`T: AsMut<[u8]>`).
#[derive(Debug)]
pub struct FrameWindow<T> {
    bytes: T,
    header: HeaderRepr,
}

impl<T: AsRef<[u8]>> FrameWindow<T> {
    /// Checks the header and that the window holds both buffers.
    pub fn new_checked(bytes: T) -> Result<Self, HeaderError> {
        let header = HeaderRepr::parse(bytes.as_ref())?;
        let got = bytes.as_ref().len();
        if got < header.window_len() {
            return Err(HeaderError::Truncated {
                needed: header.window_len(),
                got,
            });
        }
        Ok(FrameWindow { bytes, header })
    }

    /// The header as checked at construction or updated by the last write.
    pub fn header(&self) -> &HeaderRepr {
        &self.header
    }

    /// Re-reads the header from the window (another party may have changed it).
    pub fn reload(&mut self) -> Result<&HeaderRepr, HeaderError> {
        let header = HeaderRepr::parse(self.bytes.as_ref())?;
        if header.window_len() > self.bytes.as_ref().len() {
            return Err(HeaderError::Truncated {
                needed: header.window_len(),
                got: self.bytes.as_ref().len(),
            });
        }
        self.header = header;
        Ok(&self.header)
    }

    /// Takes a ticket for the ready frame from a fresh header read.
    pub fn ticket(&mut self) -> Result<FrameTicket, HeaderError> {
        self.reload()?.ticket()
    }

    /// Bytes of the ticket's buffer (valid only if [`FrameWindow::verify`] agrees afterwards).
    pub fn frame(&self, ticket: &FrameTicket) -> &[u8] {
        &self.bytes.as_ref()[self.header.buffer_range(ticket.index)]
    }

    /// Re-reads the header and checks that the ticket's buffer was not overwritten.
    pub fn verify(&mut self, ticket: &FrameTicket) -> Result<(), HeaderError> {
        let later = *self.reload()?;
        ticket.verify(&later)
    }

    /// Gives back the underlying bytes.
    pub fn into_inner(self) -> T {
        self.bytes
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> FrameWindow<T> {
    /// Writes a fresh header (nothing published) for a `width` x `height` window of `format`.
    pub fn init(
        mut bytes: T,
        width: u16,
        height: u16,
        format: PixelFormat,
    ) -> Result<Self, HeaderError> {
        if width == 0 || height == 0 || width > MAX_DIMENSION || height > MAX_DIMENSION {
            return Err(HeaderError::BadDimensions { width, height });
        }
        let header = HeaderRepr::new(width, height, format);
        let got = bytes.as_ref().len();
        if got < header.window_len() {
            return Err(HeaderError::Truncated {
                needed: header.window_len(),
                got,
            });
        }
        header.emit(bytes.as_mut())?;
        Ok(FrameWindow { bytes, header })
    }

    /// Writer step 1: marks the buffer that is not ready as being written and returns its index.
    pub fn begin_write(&mut self) -> usize {
        let index = ((self.header.ready & 1) ^ 1) as usize;
        // Before the first publish both buffers are free; fill buffer 0 first.
        let index = if self.header.sequence == 0 { 0 } else { index };
        self.header.buffer_seq[index] = WRITING;
        let range = field::BUFFER_SEQ[index].clone();
        self.bytes.as_mut()[range].copy_from_slice(&WRITING.to_le_bytes());
        index
    }

    /// Writer step 2: the pixels of buffer `index`.
    pub fn buffer_mut(&mut self, index: usize) -> &mut [u8] {
        let range = self.header.buffer_range(index);
        &mut self.bytes.as_mut()[range]
    }

    /// Writer step 3: publishes buffer `index` as the next frame; returns its sequence. Stores go
    /// in reader-safe order: the buffer's sequence and capture time, then `ready`, then `sequence`.
    pub fn publish(&mut self, index: usize, capture_us: u64) -> u32 {
        let index = index & 1;
        let mut next = self.header.sequence.wrapping_add(1);
        if next == 0 || next == WRITING {
            next = 1;
        }
        let b = self.bytes.as_mut();
        b[field::CAPTURE_US[index].clone()].copy_from_slice(&capture_us.to_le_bytes());
        b[field::BUFFER_SEQ[index].clone()].copy_from_slice(&next.to_le_bytes());
        b[field::READY].copy_from_slice(&(index as u32).to_le_bytes());
        b[field::SEQUENCE].copy_from_slice(&next.to_le_bytes());
        self.header.capture_us[index] = capture_us;
        self.header.buffer_seq[index] = next;
        self.header.ready = index as u32;
        self.header.sequence = next;
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn layout_of_a_fresh_640x480_header_byte_exact() {
        let h = HeaderRepr::new(640, 480, PixelFormat::Rgb565);
        let mut out = [0xAAu8; HEADER_LEN];
        h.emit(&mut out).unwrap();
        let expected: [u8; HEADER_LEN] = [
            b'A', b'L', b'F', b'G', 1, 0, 64, 0, // magic, version, header_len
            0x80, 0x02, 0xE0, 0x01, 1, 0, 2, 0, // 640, 480, RGB565, 2 buffers
            0x00, 0x05, 0, 0, // stride 1280
            0x00, 0x10, 0, 0, // buffer 0 at 0x1000
            0x00, 0x70, 0x09, 0, // buffer 1 at 0x1000 + 0x96000
            0, 0, 0, 0, 0, 0, 0, 0, // sequence, ready
            0, 0, 0, 0, 0, 0, 0, 0, // buffer_seq
            0, 0, 0, 0, // reserved
            0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, // capture times
        ];
        assert_eq!(out, expected);
        assert_eq!(h.window_len(), 0x1000 + 0x96000 + 640 * 480 * 2);
        assert!(h.window_len() <= WINDOW_LEN);
    }

    fn good() -> [u8; HEADER_LEN] {
        let mut h = HeaderRepr::new(640, 480, PixelFormat::Rgb332);
        h.sequence = 7;
        h.ready = 1;
        h.buffer_seq = [6, 7];
        let mut out = [0u8; HEADER_LEN];
        h.emit(&mut out).unwrap();
        out
    }

    #[test]
    fn invalid_headers_are_rejected_with_reasons() {
        assert_eq!(
            HeaderRepr::parse(&good()[..63]),
            Err(HeaderError::Truncated {
                needed: 64,
                got: 63
            })
        );
        let mut b = good();
        b[0] = b'X';
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BadMagic { got: *b"XLFG" })
        );
        let mut b = good();
        b[4] = 2;
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::UnsupportedVersion { got: 2 })
        );
        let mut b = good();
        b[6] = 32;
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BadHeaderLen { got: 32 })
        );
        let mut b = good();
        b[8..10].copy_from_slice(&0u16.to_le_bytes());
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BadDimensions {
                width: 0,
                height: 480
            })
        );
        let mut b = good();
        b[12] = 9;
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::UnknownPixelFormat { code: 9 })
        );
        let mut b = good();
        b[14] = 3;
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BadBufferCount { got: 3 })
        );
        let mut b = good();
        b[16..20].copy_from_slice(&639u32.to_le_bytes());
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::StrideTooSmall {
                stride: 639,
                min: 640
            })
        );
        let mut b = good();
        b[24..28].copy_from_slice(&0x2000u32.to_le_bytes());
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BufferOverlap { index: 1 })
        );
        let mut b = good();
        b[20..24].copy_from_slice(&16u32.to_le_bytes());
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BufferOverlap { index: 0 })
        );
        let mut b = good();
        b[32] = 2;
        assert_eq!(
            HeaderRepr::parse(&b),
            Err(HeaderError::BadReadyIndex { got: 2 })
        );
    }

    #[test]
    fn torn_and_mid_publish_headers_give_no_frame() {
        let h = HeaderRepr::parse(&good()).unwrap();
        let t = h.ticket().unwrap();
        assert_eq!((t.index, t.sequence), (1, 7));
        // The writer started overwriting buffer 1 after the ticket was taken.
        let mut later = h;
        later.buffer_seq[1] = WRITING;
        assert_eq!(
            t.verify(&later),
            Err(HeaderError::Torn {
                expected: 7,
                found: WRITING
            })
        );
        // ... and finished it as frame 9.
        later.buffer_seq[1] = 9;
        assert_eq!(
            t.verify(&later),
            Err(HeaderError::Torn {
                expected: 7,
                found: 9
            })
        );
        // A header copied between the writer's `ready` and `sequence` stores.
        let mut mid = h;
        mid.ready = 0;
        assert_eq!(
            mid.ticket(),
            Err(HeaderError::Inconsistent {
                sequence: 7,
                buffer_seq: 6
            })
        );
        let fresh = HeaderRepr::new(640, 480, PixelFormat::Rgb332);
        assert_eq!(fresh.ticket(), Err(HeaderError::NoFrame));
    }

    #[test]
    fn writer_and_reader_over_one_window() {
        let mut mem = vec![0u8; WINDOW_LEN];
        let mut w = FrameWindow::init(&mut mem[..], 640, 480, PixelFormat::Rgb332).unwrap();
        let i = w.begin_write();
        assert_eq!(i, 0);
        w.buffer_mut(i).fill(0x11);
        assert_eq!(w.publish(i, 1000), 1);
        let i = w.begin_write();
        assert_eq!(i, 1);
        w.buffer_mut(i).fill(0x22);
        assert_eq!(w.publish(i, 2000), 2);

        let mut r = FrameWindow::new_checked(&mem[..]).unwrap();
        let t = r.ticket().unwrap();
        assert_eq!((t.index, t.sequence, t.capture_us), (1, 2, 2000));
        assert!(r.frame(&t).iter().all(|&p| p == 0x22));
        assert_eq!(r.verify(&t), Ok(()));
    }

    #[test]
    fn reader_detects_overwrite_while_reading() {
        let mut mem = vec![0u8; WINDOW_LEN];
        let mut w = FrameWindow::init(&mut mem[..], 64, 48, PixelFormat::Rgb565).unwrap();
        let i = w.begin_write();
        w.publish(i, 0);
        let ticket = HeaderRepr::parse(&mem).unwrap().ticket().unwrap();
        assert_eq!(ticket.index, 0);
        let mut w = FrameWindow::new_checked(&mut mem[..]).unwrap();
        // Frame 2 goes to buffer 1: the reader's buffer 0 is untouched.
        let i = w.begin_write();
        assert_eq!(i, 1);
        w.publish(i, 1);
        assert_eq!(ticket.verify(&HeaderRepr::parse(&mem).unwrap()), Ok(()));
        // Frame 3 starts in buffer 0: the reader's frame is torn.
        let mut w = FrameWindow::new_checked(&mut mem[..]).unwrap();
        let i = w.begin_write();
        assert_eq!(i, 0);
        assert_eq!(
            ticket.verify(&HeaderRepr::parse(&mem).unwrap()),
            Err(HeaderError::Torn {
                expected: 1,
                found: WRITING
            })
        );
    }

    #[test]
    fn short_window_is_rejected() {
        let mut mem = vec![0u8; 1000];
        assert!(matches!(
            FrameWindow::init(&mut mem[..], 640, 480, PixelFormat::Rgb332),
            Err(HeaderError::Truncated { .. })
        ));
        let mut mem = vec![0u8; WINDOW_LEN];
        FrameWindow::init(&mut mem[..], 640, 480, PixelFormat::Rgb565).unwrap();
        assert!(matches!(
            FrameWindow::new_checked(&mem[..WINDOW_LEN / 2]),
            Err(HeaderError::Truncated { .. })
        ));
    }

    fn arb_repr() -> impl Strategy<Value = HeaderRepr> {
        (
            1u16..=MAX_DIMENSION,
            1u16..=MAX_DIMENSION,
            prop_oneof![Just(PixelFormat::Rgb565), Just(PixelFormat::Rgb332)],
            0u32..64,
            any::<u32>(),
            0u32..=1,
            any::<[u32; 2]>(),
            any::<[u64; 2]>(),
        )
            .prop_map(|(w, h, f, pad, seq, ready, bseq, cap)| {
                let mut r = HeaderRepr::new(w, h, f);
                r.stride += pad;
                let len = r.frame_len() as u32;
                r.buffer_offset = [HEADER_LEN as u32, HEADER_LEN as u32 + len];
                r.sequence = seq;
                r.ready = ready;
                r.buffer_seq = bseq;
                r.capture_us = cap;
                r
            })
    }

    proptest! {
        #[test]
        fn emit_then_parse_is_identity(r in arb_repr()) {
            let mut out = [0u8; HEADER_LEN];
            r.emit(&mut out).unwrap();
            prop_assert_eq!(HeaderRepr::parse(&out), Ok(r));
        }

        #[test]
        fn parse_never_panics_and_reemits_same_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
            if let Ok(r) = HeaderRepr::parse(&bytes) {
                let mut out = [0u8; HEADER_LEN];
                r.emit(&mut out).unwrap();
                // Reserved bytes are written as zero; everything else round-trips.
                prop_assert_eq!(&out[..44], &bytes[..44]);
                prop_assert_eq!(&out[48..64], &bytes[48..64]);
            }
        }

        #[test]
        fn mostly_valid_headers_parse_or_fail_cleanly(r in arb_repr(), pos in 0usize..HEADER_LEN, v in any::<u8>()) {
            let mut out = [0u8; HEADER_LEN];
            r.emit(&mut out).unwrap();
            out[pos] = v;
            let _ = HeaderRepr::parse(&out).map(|h| h.ticket());
        }
    }
}
