//! Run buffers: the classified pixels of a frame as run-length words, one 32-bit word per run
//! and one per row that has runs, in the order the pixels arrive. This is what the SoC's vision
//! unit writes (`verilator-tb/rtl/vision_unit.v`), what the host writes for a QEMU car, and what
//! the firmware turns into blobs without touching a pixel ([`blobs_from_runs`]). The field
//! tables are in `docs/hal.md` ("Vision unit").
//!
//! Word kinds, told apart by the class field (bits 31..28):
//!
//! - **run** (class 1..=15): bits 23..12 the first column, bits 11..0 the last column
//!   (inclusive); bits 27..24 zero.
//! - **row end** (class 0): written after the last run of a row that has runs; bits 27..16 the
//!   number of runs of that row (1..=4095), bits 11..0 the row; bits 15..12 zero.
//!
//! A row without runs has no words at all. Runs of a row come left to right, never overlap, and
//! two neighbouring runs never have the same class (they would be one run).
//!
//! [`RunEncoder`] is the reference for the unit's behaviour, including what happens when the
//! buffer fills: a run is stored only while at least two words are free (its own and its row's
//! end), so every stored run is followed by its row end; the rest are counted as dropped.

use crate::blobs::{BlobDetector, Detections, Run, MAX_RUNS_PER_ROW};
use crate::colour::{rgb565_to_rgb332, ColourClasses, BACKGROUND};
use crate::frame::PixelFormat;
use crate::{FrameGeometry, PipelineConfig, PipelineError};

/// Largest column or row a word can hold, plus one.
pub const MAX_COORD: u16 = 4096;
/// Largest number of runs a row-end word can count.
pub const MAX_ROW_RUNS: u16 = 4095;
/// Largest run buffer, in words (so a row's runs always fit a row-end word's count).
pub const MAX_CAPACITY: usize = 4096;

/// Mask of the class field (bits 31..28).
const CLASS_SHIFT: u32 = 28;
const RUN_RESERVED: u32 = 0x0F00_0000;
const ROW_RESERVED: u32 = 0x0000_F000;

/// One word of a run buffer, decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RunWord {
    /// Columns `first..=last` of the current row have class `class` (1..=15).
    Run { class: u8, first: u16, last: u16 },
    /// Row `y` ended; it had `count` runs.
    RowEnd { y: u16, count: u16 },
}

/// Why a word cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// Class 0 or above 15, a column or row of 4096 or more, `first > last`, or a count of 0 or
    /// above [`MAX_ROW_RUNS`].
    OutOfRange,
}

impl RunWord {
    /// The 32-bit word.
    pub fn encode(self) -> Result<u32, EncodeError> {
        match self {
            RunWord::Run { class, first, last } => {
                if class == BACKGROUND || class > 15 || first > last || last >= MAX_COORD {
                    return Err(EncodeError::OutOfRange);
                }
                Ok(u32::from(class) << CLASS_SHIFT | u32::from(first) << 12 | u32::from(last))
            }
            RunWord::RowEnd { y, count } => {
                if y >= MAX_COORD || count == 0 || count > MAX_ROW_RUNS {
                    return Err(EncodeError::OutOfRange);
                }
                Ok(u32::from(count) << 16 | u32::from(y))
            }
        }
    }

    /// Decodes a word; `None` when reserved bits are set or a field is out of range.
    pub fn decode(w: u32) -> Option<Self> {
        let class = (w >> CLASS_SHIFT) as u8;
        if class != BACKGROUND {
            let (first, last) = (((w >> 12) & 0xFFF) as u16, (w & 0xFFF) as u16);
            (w & RUN_RESERVED == 0 && first <= last).then_some(RunWord::Run { class, first, last })
        } else {
            let (count, y) = (((w >> 16) & 0xFFF) as u16, (w & 0xFFF) as u16);
            (w & ROW_RESERVED == 0 && count != 0).then_some(RunWord::RowEnd { y, count })
        }
    }
}

/// The run of a run word (no checks: for words a [`RowIter`] has validated).
#[inline(always)]
pub fn run_of(w: u32) -> Run {
    Run {
        start: ((w >> 12) & 0xFFF) as u16,
        end: (w & 0xFFF) as u16 + 1,
        class: (w >> CLASS_SHIFT) as u8,
    }
}

/// What encoding one frame produced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RunSummary {
    /// Words written (runs and row ends).
    pub words: usize,
    /// Runs that did not fit (saturating at `u16::MAX`, as the unit's counter).
    pub dropped: u16,
    /// Pixels in the last row.
    pub width: u16,
    /// Rows.
    pub height: u16,
}

/// The vision unit's run-length encoder, pixel by pixel, into a buffer of fixed capacity.
#[derive(Debug)]
pub struct RunEncoder<'a> {
    out: &'a mut [u32],
    words: usize,
    dropped: u16,
    x: u16,
    y: u16,
    cur: u8,
    start: u16,
    row_runs: u16,
    width: u16,
}

impl<'a> RunEncoder<'a> {
    /// An encoder writing into `out` (its length is the capacity, at most [`MAX_CAPACITY`]
    /// words are used). Rows and columns past [`MAX_COORD`] keep only their low 12 bits in the
    /// words.
    pub fn new(out: &'a mut [u32]) -> Self {
        let cap = out.len().min(MAX_CAPACITY);
        RunEncoder {
            out: &mut out[..cap],
            words: 0,
            dropped: 0,
            x: 0,
            y: 0,
            cur: BACKGROUND,
            start: 0,
            row_runs: 0,
            width: 0,
        }
    }

    fn close(&mut self) {
        if self.cur == BACKGROUND {
            return;
        }
        // room for the run and its row's end
        if self.words + 1 < self.out.len() {
            let last = u32::from(self.x.wrapping_sub(1)) & 0xFFF;
            let first = u32::from(self.start) & 0xFFF;
            self.out[self.words] = u32::from(self.cur) << CLASS_SHIFT | first << 12 | last;
            self.words += 1;
            self.row_runs += 1;
        } else {
            self.dropped = self.dropped.saturating_add(1);
        }
    }

    /// The next pixel of the current row, as its class (0 background, 1..=15).
    #[inline(always)]
    pub fn pixel(&mut self, class: u8) {
        let class = class & 15;
        if class != self.cur {
            self.close();
            self.cur = class;
            self.start = self.x;
        }
        self.x = self.x.wrapping_add(1);
    }

    /// Ends the current row.
    pub fn end_row(&mut self) {
        self.close();
        if self.row_runs != 0 {
            // a row end always has room: its runs were stored with room for it
            if let Some(slot) = self.out.get_mut(self.words) {
                *slot = u32::from(self.row_runs) << 16 | (u32::from(self.y) & 0xFFF);
                self.words += 1;
            }
        }
        self.width = self.x;
        self.y = self.y.wrapping_add(1);
        self.x = 0;
        self.cur = BACKGROUND;
        self.row_runs = 0;
    }

    /// Ends the frame (a row in progress is ended first).
    pub fn finish(mut self) -> RunSummary {
        if self.x != 0 || self.cur != BACKGROUND {
            self.end_row();
        }
        RunSummary {
            words: self.words,
            dropped: self.dropped,
            width: self.width,
            height: self.y,
        }
    }
}

/// Encodes a frame of RGB332 codes (`width` per row, rows packed) with a class per code
/// (`lut[code] & 15`, as the unit's 4-bit table holds it) into `out`.
pub fn encode_codes(codes: &[u8], width: u16, lut: &[u8; 256], out: &mut [u32]) -> RunSummary {
    let mut enc = RunEncoder::new(out);
    if width == 0 {
        return enc.finish();
    }
    for row in codes.chunks(usize::from(width)) {
        for &c in row {
            enc.pixel(lut[usize::from(c)]);
        }
        enc.end_row();
    }
    enc.finish()
}

/// Encodes a frame as the host does for a QEMU car: the geometry's pixels (RGB332, or RGB565
/// through its top bits) classified with `classes`.
pub fn encode_frame(
    frame: &[u8],
    geometry: &FrameGeometry,
    classes: &ColourClasses,
    out: &mut [u32],
) -> Result<RunSummary, PipelineError> {
    let bpp = geometry.format.bytes_per_pixel();
    let row_len = usize::from(geometry.width) * bpp;
    if geometry.stride < row_len || geometry.width > MAX_COORD || geometry.height > MAX_COORD {
        return Err(PipelineError::BadGeometry {
            width: geometry.width,
            stride: geometry.stride,
        });
    }
    let needed = geometry.frame_len();
    if frame.len() < needed {
        return Err(PipelineError::FrameTooShort {
            needed,
            got: frame.len(),
        });
    }
    let mut enc = RunEncoder::new(out);
    for y in 0..usize::from(geometry.height) {
        let row = &frame[y * geometry.stride..y * geometry.stride + row_len];
        match geometry.format {
            PixelFormat::Rgb332 => {
                for &p in row {
                    enc.pixel(classes.class_of_rgb332(p));
                }
            }
            PixelFormat::Rgb565 => {
                for p in row.chunks_exact(2) {
                    let code = rgb565_to_rgb332(u16::from_le_bytes([p[0], p[1]]));
                    enc.pixel(classes.class_of_rgb332(code));
                }
            }
        }
        enc.end_row();
    }
    Ok(enc.finish())
}

/// Why a run buffer is rejected; `index` is the word where it went wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RunError {
    /// Reserved bits set, a run with its first column after its last, or a row end counting 0.
    BadWord { index: usize },
    /// A run starts at or before the end of the previous run of its row, or right after a run
    /// of the same class.
    Unordered { index: usize },
    /// A run reaches past the frame's width, or a row end names a row past its height.
    OutsideFrame { index: usize },
    /// A row end counts a different number of runs than precede it.
    CountMismatch { index: usize },
    /// A row end names a row at or above the previous row end's.
    RowOrder { index: usize },
    /// Runs after the last row end.
    Unterminated { index: usize },
}

/// One row of a run buffer: its runs in place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Row<'a> {
    /// The row.
    pub y: u16,
    /// Its run words (decode with [`run_of`]).
    pub runs: &'a [u32],
}

/// The rows of a run buffer, each checked before it is handed out; the first error ends the
/// iteration.
#[derive(Debug, Clone)]
pub struct RowIter<'a> {
    words: &'a [u32],
    pos: usize,
    width: u16,
    height: u16,
    next_y: u16,
    failed: bool,
}

impl<'a> RowIter<'a> {
    /// Rows of `words` from a frame of `width` x `height` pixels.
    pub fn new(words: &'a [u32], width: u16, height: u16) -> Self {
        RowIter {
            words,
            pos: 0,
            width,
            height,
            next_y: 0,
            failed: false,
        }
    }

    fn row(&mut self) -> Result<Row<'a>, RunError> {
        let start = self.pos;
        let mut prev: Option<(u8, u16)> = None;
        while let Some(&w) = self.words.get(self.pos) {
            let index = self.pos;
            self.pos += 1;
            match RunWord::decode(w).ok_or(RunError::BadWord { index })? {
                RunWord::Run { class, first, last } => {
                    if let Some((pc, pl)) = prev {
                        if first <= pl || (first == pl + 1 && class == pc) {
                            return Err(RunError::Unordered { index });
                        }
                    }
                    if last >= self.width {
                        return Err(RunError::OutsideFrame { index });
                    }
                    prev = Some((class, last));
                }
                RunWord::RowEnd { y, count } => {
                    if usize::from(count) != index - start {
                        return Err(RunError::CountMismatch { index });
                    }
                    if y < self.next_y {
                        return Err(RunError::RowOrder { index });
                    }
                    if y >= self.height {
                        return Err(RunError::OutsideFrame { index });
                    }
                    self.next_y = y + 1;
                    return Ok(Row {
                        y,
                        runs: &self.words[start..index],
                    });
                }
            }
        }
        Err(RunError::Unterminated { index: start })
    }
}

impl<'a> Iterator for RowIter<'a> {
    type Item = Result<Row<'a>, RunError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed || self.pos >= self.words.len() {
            return None;
        }
        let r = self.row();
        self.failed = r.is_err();
        Some(r)
    }
}

/// Checks a whole run buffer; the number of runs it holds.
pub fn check(words: &[u32], width: u16, height: u16) -> Result<usize, RunError> {
    RowIter::new(words, width, height).try_fold(0, |n, r| r.map(|row| n + row.runs.len()))
}

/// The blobs of a frame from its run buffer: the connected-component pass of
/// [`crate::process_frame`] over rows that are already runs. With the same frame and classes
/// the detections are the same as `process_frame`'s (every row, or every `row_step`-th row);
/// `unit_dropped` (runs the buffer could not hold) is added to the dropped runs.
pub fn blobs_from_runs(
    words: &[u32],
    width: u16,
    height: u16,
    unit_dropped: u32,
    config: &PipelineConfig,
    detector: &mut BlobDetector,
) -> Result<Detections, RunError> {
    let step = config.row_step.max(1);
    detector.begin_frame(step);
    detector.note_dropped_runs(unit_dropped);
    let mut runs = [Run::default(); MAX_RUNS_PER_ROW];
    for row in RowIter::new(words, width, height) {
        let row = row?;
        if row.y % step != 0 {
            continue;
        }
        let kept = row.runs.len().min(MAX_RUNS_PER_ROW);
        for (slot, &w) in runs.iter_mut().zip(&row.runs[..kept]) {
            *slot = run_of(w);
        }
        detector.note_dropped_runs((row.runs.len() - kept) as u32);
        detector.push_row(row.y, &runs[..kept]);
    }
    Ok(detector.finish(config.min_area))
}

#[cfg(test)]
mod tests;
