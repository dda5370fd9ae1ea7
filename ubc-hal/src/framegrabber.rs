//! Frame grabber: the reader side of the frame-grabber window protocol (`vision::frame`,
//! `docs/camera.md`). The camera (or the host, through QEMU's shared RAM) publishes frames into
//! a window of RAM; [`FrameGrabber::with_latest`] copies the header with volatile reads, hands the
//! ready buffer to the caller in place (no copy), then re-reads the header and keeps the result
//! only if the writer did not start on that buffer meanwhile.
//!
//! The window is reached through [`WindowMemory`]: [`MmioWindow`] on the boards (the only
//! `unsafe` here), a plain byte slice in host tests.

use core::ops::Range;
use core::sync::atomic::{fence, Ordering};
use vision::frame::{field, FrameTicket, HeaderError, HeaderRepr, HEADER_LEN, MAGIC};
use vision::FrameGeometry;

/// Memory holding a frame-grabber window.
pub trait WindowMemory {
    /// Bytes of the window.
    fn len(&self) -> usize;
    /// Whether the window is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// A fresh copy of the header (volatile reads on the target: the writer changes it).
    fn read_header(&self) -> [u8; HEADER_LEN];
    /// A fresh read of the little-endian header word at `offset` (a multiple of 4 inside the
    /// header; 0 otherwise).
    fn read_word(&self, offset: usize) -> u32 {
        let h = self.read_header();
        h.get(offset..offset + 4)
            .and_then(|w| <[u8; 4]>::try_from(w).ok())
            .map_or(0, u32::from_le_bytes)
    }
    /// The bytes of `range` in place, or `None` if the range leaves the window.
    fn bytes(&self, range: Range<usize>) -> Option<&[u8]>;
}

/// A window at a fixed physical address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MmioWindow {
    base: usize,
    len: usize,
}

impl MmioWindow {
    /// The window of `len` bytes at `base`.
    ///
    /// # Safety
    ///
    /// `base..base + len` must be memory that stays mapped for the program's life, is 4-byte
    /// aligned, and is never written by Rust code (only by another agent: the camera, a DMA
    /// engine, the host through shared RAM). No Rust allocation may overlap it.
    pub const unsafe fn new(base: usize, len: usize) -> Self {
        MmioWindow { base, len }
    }

    /// The physical base address.
    pub const fn base(&self) -> usize {
        self.base
    }
}

impl WindowMemory for MmioWindow {
    fn len(&self) -> usize {
        self.len
    }

    // Out of line: its unrolled word reads inlined at each of the five uses cost the firmware
    // 860 bytes more, for a call once per frame.
    #[cfg_attr(target_arch = "riscv32", inline(never))]
    fn read_header(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        if self.len < HEADER_LEN {
            return out;
        }
        for (i, chunk) in out.chunks_exact_mut(4).enumerate() {
            let addr = self.base + 4 * i;
            // SAFETY: `MmioWindow::new`'s contract: the first `len >= HEADER_LEN` bytes at the
            // 4-byte aligned `base` are mapped memory no Rust code writes; a volatile word read
            // observes the writer's stores and is never merged or elided.
            let word = unsafe { core::ptr::read_volatile(addr as *const u32) };
            chunk.copy_from_slice(&word.to_le_bytes());
        }
        out
    }

    fn read_word(&self, offset: usize) -> u32 {
        if !offset.is_multiple_of(4) || offset + 4 > HEADER_LEN.min(self.len) {
            return 0;
        }
        // SAFETY: as in `read_header`: an aligned word inside the window's header.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    fn bytes(&self, range: Range<usize>) -> Option<&[u8]> {
        if range.start > range.end || range.end > self.len {
            return None;
        }
        // SAFETY: the range lies inside the window (checked above), which `MmioWindow::new`'s
        // contract makes mapped, aligned memory that no Rust code writes or owns, so no `&mut`
        // to it exists. Another agent may store into it while the slice is alive; the window
        // protocol makes that visible afterwards (`FrameTicket::verify`, `GrabError::Torn`) and
        // the result is then discarded, and a byte read here is at worst stale or new, never a
        // value outside `u8`. The slice lives no longer than `&self`.
        Some(unsafe {
            core::slice::from_raw_parts((self.base + range.start) as *const u8, range.len())
        })
    }
}

impl WindowMemory for [u8] {
    fn len(&self) -> usize {
        <[u8]>::len(self)
    }

    fn read_header(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        if let Some(h) = self.get(..HEADER_LEN) {
            out.copy_from_slice(h);
        }
        out
    }

    fn bytes(&self, range: Range<usize>) -> Option<&[u8]> {
        self.get(range)
    }
}

impl<M: WindowMemory + ?Sized> WindowMemory for &M {
    fn len(&self) -> usize {
        (**self).len()
    }
    fn read_header(&self) -> [u8; HEADER_LEN] {
        (**self).read_header()
    }
    fn read_word(&self, offset: usize) -> u32 {
        (**self).read_word(offset)
    }
    fn bytes(&self, range: Range<usize>) -> Option<&[u8]> {
        (**self).bytes(range)
    }
}

/// Why no frame could be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GrabError {
    /// The header is invalid, nothing is published yet (`NoFrame`), it was read mid-publish
    /// (`Inconsistent`), or the frame was overwritten while in use (`Torn`).
    Header(HeaderError),
    /// The header describes buffers beyond the window.
    OutsideWindow { needed: usize, window: usize },
}

impl From<HeaderError> for GrabError {
    fn from(e: HeaderError) -> Self {
        GrabError::Header(e)
    }
}

/// A published frame, in place in the window.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Which buffer, which frame, and when it was captured.
    pub ticket: FrameTicket,
    /// Shape of the pixels.
    pub geometry: FrameGeometry,
    /// The buffer's bytes (4 KiB aligned in the window).
    pub pixels: &'a [u8],
}

/// Counters of the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GrabStats {
    /// Frames used and verified whole.
    pub frames: u32,
    /// Frames discarded because the writer started on their buffer during the read.
    pub torn: u32,
    /// Header copies taken mid-publish.
    pub inconsistent: u32,
    /// Published frames never used (the reader was busy when they came and went).
    pub skipped: u32,
}

/// The reader of one frame-grabber window.
#[derive(Debug)]
pub struct FrameGrabber<M> {
    memory: M,
    last_sequence: u32,
    stats: GrabStats,
}

impl<M: WindowMemory> FrameGrabber<M> {
    pub fn new(memory: M) -> Self {
        FrameGrabber {
            memory,
            last_sequence: 0,
            stats: GrabStats::default(),
        }
    }

    /// The window memory.
    pub fn memory(&self) -> &M {
        &self.memory
    }

    /// Reader counters.
    pub fn stats(&self) -> GrabStats {
        self.stats
    }

    /// Sequence of the last frame used whole (0 before the first).
    pub fn last_sequence(&self) -> u32 {
        self.last_sequence
    }

    /// The header as the writer left it now.
    pub fn header(&self) -> Result<HeaderRepr, GrabError> {
        let h = HeaderRepr::parse(&self.memory.read_header())?;
        let needed = h.window_len();
        if needed > self.memory.len() {
            return Err(GrabError::OutsideWindow {
                needed,
                window: self.memory.len(),
            });
        }
        Ok(h)
    }

    /// Whether a frame newer than the last one used is published: two word reads when none
    /// is (the program asks often), the whole header when one may be.
    pub fn has_new_frame(&self) -> bool {
        if self.memory.read_word(field::MAGIC.start) != u32::from_le_bytes(MAGIC) {
            return false;
        }
        let sequence = self.memory.read_word(field::SEQUENCE.start);
        if sequence == 0 || sequence == self.last_sequence {
            return false;
        }
        matches!(self.header(), Ok(h) if h.sequence != 0 && h.sequence != self.last_sequence)
    }

    /// Runs `use_frame` on the newest published frame, in place, if it is newer than the last
    /// one used; `Ok(None)` when there is none. The result is returned only if the frame was
    /// still whole afterwards; otherwise `Err(GrabError::Header(HeaderError::Torn { .. }))`.
    pub fn with_latest<R>(
        &mut self,
        use_frame: impl FnOnce(&Frame<'_>) -> R,
    ) -> Result<Option<(FrameTicket, R)>, GrabError> {
        let header = self.header()?;
        let ticket = match header.ticket() {
            Ok(t) => t,
            Err(HeaderError::NoFrame) => return Ok(None),
            Err(e) => {
                if matches!(e, HeaderError::Inconsistent { .. }) {
                    self.stats.inconsistent = self.stats.inconsistent.wrapping_add(1);
                }
                return Err(e.into());
            }
        };
        if ticket.sequence == self.last_sequence {
            return Ok(None);
        }
        let range = header.buffer_range(ticket.index);
        let pixels = self
            .memory
            .bytes(range.clone())
            .ok_or(GrabError::OutsideWindow {
                needed: range.end,
                window: self.memory.len(),
            })?;
        let frame = Frame {
            ticket,
            geometry: FrameGeometry::from(&header),
            pixels,
        };
        let result = use_frame(&frame);
        // Every read of the frame happens before the header is read again.
        fence(Ordering::SeqCst);
        let later = HeaderRepr::parse(&self.memory.read_header())?;
        if let Err(e) = ticket.verify(&later) {
            self.stats.torn = self.stats.torn.wrapping_add(1);
            return Err(e.into());
        }
        let gap = ticket.sequence.wrapping_sub(self.last_sequence);
        if self.last_sequence != 0 && gap > 1 && gap < u32::MAX / 2 {
            self.stats.skipped = self.stats.skipped.wrapping_add(gap - 1);
        }
        self.last_sequence = ticket.sequence;
        self.stats.frames = self.stats.frames.wrapping_add(1);
        Ok(Some((ticket, result)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::cell::RefCell;
    use vision::colour::{Rgb, MARKER_CLASSES, MARKER_PALETTE};
    use vision::frame::{FrameWindow, PixelFormat, WINDOW_LEN, WRITING};
    use vision::{process_frame, PipelineConfig};

    fn window_with_frames(frames: &[u8]) -> Vec<u8> {
        let mut mem = vec![0u8; WINDOW_LEN];
        let mut w = FrameWindow::init(&mut mem[..], 640, 480, PixelFormat::Rgb332).unwrap();
        for (k, &fill) in frames.iter().enumerate() {
            let i = w.begin_write();
            w.buffer_mut(i).fill(fill);
            w.publish(i, 1000 * k as u64);
        }
        mem
    }

    #[test]
    fn nothing_published_gives_none_and_bad_memory_is_typed() {
        let mem = window_with_frames(&[]);
        let mut g = FrameGrabber::new(&mem[..]);
        assert!(!g.has_new_frame());
        assert_eq!(g.with_latest(|_| ()), Ok(None));

        let zero = vec![0u8; WINDOW_LEN];
        let mut g = FrameGrabber::new(&zero[..]);
        assert_eq!(
            g.with_latest(|_| ()),
            Err(GrabError::Header(HeaderError::BadMagic { got: [0; 4] }))
        );

        let short = &mem[..0x1000];
        let mut g = FrameGrabber::new(short);
        assert!(matches!(
            g.with_latest(|_| ()),
            Err(GrabError::OutsideWindow { window: 0x1000, .. })
        ));
    }

    #[test]
    fn newest_frame_once_in_place_and_skips_counted() {
        let mem = window_with_frames(&[0x11, 0x22, 0x33]);
        let mut g = FrameGrabber::new(&mem[..]);
        assert!(g.has_new_frame());
        let (t, (first, len, ptr)) = g
            .with_latest(|f| (f.pixels[0], f.pixels.len(), f.pixels.as_ptr()))
            .unwrap()
            .unwrap();
        assert_eq!((t.sequence, t.index, t.capture_us), (3, 0, 2000));
        assert_eq!((first, len), (0x33, 640 * 480));
        // In place: the slice points into the window.
        assert_eq!(ptr, mem[0x1000..].as_ptr());
        assert!(!g.has_new_frame());
        assert_eq!(g.with_latest(|_| ()), Ok(None));
        assert_eq!(g.stats().frames, 1);
        assert_eq!(g.last_sequence(), 3);
    }

    /// Memory whose header changes between reads, as a concurrent writer would make it.
    struct Scripted {
        mem: Vec<u8>,
        headers: RefCell<Vec<[u8; HEADER_LEN]>>,
    }

    impl WindowMemory for Scripted {
        fn len(&self) -> usize {
            self.mem.len()
        }
        fn read_header(&self) -> [u8; HEADER_LEN] {
            let mut h = self.headers.borrow_mut();
            if h.len() > 1 {
                h.remove(0)
            } else {
                h[0]
            }
        }
        fn bytes(&self, range: Range<usize>) -> Option<&[u8]> {
            self.mem.get(range)
        }
    }

    #[test]
    fn torn_and_mid_publish_reads_are_discarded() {
        let mem = window_with_frames(&[0x11, 0x22]);
        let mut before = [0u8; HEADER_LEN];
        before.copy_from_slice(&mem[..HEADER_LEN]);
        // The writer starts frame 3 in buffer 0 ... and then in buffer 1 (the one read).
        let mut h = HeaderRepr::parse(&before).unwrap();
        h.buffer_seq[1] = WRITING;
        let mut torn = [0u8; HEADER_LEN];
        h.emit(&mut torn).unwrap();
        let mem2 = Scripted {
            mem: mem.clone(),
            headers: RefCell::new(vec![before, torn]),
        };
        let mut g = FrameGrabber::new(mem2);
        assert_eq!(
            g.with_latest(|f| f.pixels[0]),
            Err(GrabError::Header(HeaderError::Torn {
                expected: 2,
                found: WRITING
            }))
        );
        assert_eq!(g.stats().torn, 1);
        assert_eq!(g.last_sequence(), 0);

        // Copied between the writer's `ready` and `sequence` stores.
        let mut mid = HeaderRepr::parse(&before).unwrap();
        mid.ready = 0;
        let mut m = [0u8; HEADER_LEN];
        mid.emit(&mut m).unwrap();
        let mut g = FrameGrabber::new(Scripted {
            mem,
            headers: RefCell::new(vec![m]),
        });
        assert!(matches!(
            g.with_latest(|_| ()),
            Err(GrabError::Header(HeaderError::Inconsistent { .. }))
        ));
        assert_eq!(g.stats().inconsistent, 1);
    }

    #[test]
    fn vision_on_the_grabbed_frame_finds_drawn_markers_exactly() {
        let mut mem = vec![0u8; WINDOW_LEN];
        let mut w = FrameWindow::init(&mut mem[..], 640, 480, PixelFormat::Rgb332).unwrap();
        let i = w.begin_write();
        let buf = w.buffer_mut(i);
        buf.fill(Rgb::new(150, 140, 120).to_rgb332());
        let red = MARKER_PALETTE[0].to_rgb332();
        let cyan = MARKER_PALETTE[5].to_rgb332();
        for y in 100..130 {
            buf[y * 640 + 301..y * 640 + 341].fill(red);
        }
        for y in 400..405 {
            buf[y * 640 + 3..y * 640 + 10].fill(cyan);
        }
        w.publish(i, 5);
        let mut g = FrameGrabber::new(&mem[..]);
        let mut det = vision::blobs::BlobDetector::new();
        let (t, d) = g
            .with_latest(|f| {
                process_frame(
                    f.pixels,
                    &f.geometry,
                    &MARKER_CLASSES,
                    &PipelineConfig::default(),
                    &mut det,
                )
            })
            .unwrap()
            .unwrap();
        let d = d.unwrap();
        assert_eq!(t.sequence, 1);
        let b = d.blobs();
        assert_eq!(b.len(), 2);
        assert_eq!(
            (b[0].class, b[0].area, b[0].min_x, b[0].max_x, b[0].min_y, b[0].max_y),
            (1, 1200, 301, 340, 100, 129)
        );
        assert_eq!(b[0].centroid_q8(), (320 * 256 + 128, 114 * 256 + 128));
        assert_eq!((b[1].class, b[1].area), (6, 35));
    }
}
