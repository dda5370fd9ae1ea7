//! On-board vision of the ALMC upper board.
//!
//! A frame from the frame-grabber window ([`frame`]) goes through one pass: each row is turned into
//! runs of colour class ([`colour`]; a 256-entry table, and a word test that skips four
//! background RGB332 pixels at a time), the runs are joined into connected blobs ([`blobs`]),
//! and a blob that is a car's marker gives a bearing and a range through the camera model
//! ([`pinhole`]); [`follow`] turns that into steering and speed to follow a leader. No heap, no
//! floating point per pixel; all state lives in fixed arrays sized by named constants.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod blobs;
pub mod colour;
pub mod follow;
pub mod frame;
pub mod pinhole;
pub mod run_window;
pub mod runs;

use blobs::{BlobDetector, Detections, Run, MAX_RUNS_PER_ROW};
use colour::{ColourClasses, BACKGROUND};
use frame::{HeaderRepr, PixelFormat};

/// Shape of the pixels in a frame buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameGeometry {
    pub width: u16,
    pub height: u16,
    /// Bytes from one row to the next.
    pub stride: usize,
    pub format: PixelFormat,
}

impl FrameGeometry {
    /// Tightly packed rows.
    pub fn packed(width: u16, height: u16, format: PixelFormat) -> Self {
        FrameGeometry {
            width,
            height,
            stride: usize::from(width) * format.bytes_per_pixel(),
            format,
        }
    }

    /// Bytes a frame of this shape needs.
    pub fn frame_len(&self) -> usize {
        if self.height == 0 {
            return 0;
        }
        self.stride * (usize::from(self.height) - 1)
            + usize::from(self.width) * self.format.bytes_per_pixel()
    }
}

impl From<&HeaderRepr> for FrameGeometry {
    fn from(h: &HeaderRepr) -> Self {
        FrameGeometry {
            width: h.width,
            height: h.height,
            stride: h.stride as usize,
            format: h.format,
        }
    }
}

/// Pipeline settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineConfig {
    /// Process rows `0, k, 2k, ...` only; `1` processes every row. With `k > 1`, areas count
    /// sampled pixels and rows `k` apart count as adjacent.
    pub row_step: u16,
    /// Smaller blobs are not reported.
    pub min_area: u32,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        PipelineConfig {
            row_step: 1,
            min_area: 4,
        }
    }
}

/// Why a frame could not be processed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PipelineError {
    /// The slice is shorter than the geometry says.
    FrameTooShort { needed: usize, got: usize },
    /// Rows overlap (stride below a row), or the width does not fit the run coordinates.
    BadGeometry { width: u16, stride: usize },
}

struct RunBuilder<'a> {
    out: &'a mut [Run],
    n: usize,
    dropped: u32,
    cur: u8,
    start: u16,
}

impl<'a> RunBuilder<'a> {
    fn new(out: &'a mut [Run]) -> Self {
        RunBuilder {
            out,
            n: 0,
            dropped: 0,
            cur: BACKGROUND,
            start: 0,
        }
    }

    #[inline(always)]
    fn step(&mut self, x: u16, class: u8) {
        if class != self.cur {
            self.close(x);
            self.start = x;
            self.cur = class;
        }
    }

    #[inline(always)]
    fn close(&mut self, x: u16) {
        if self.cur != BACKGROUND {
            match self.out.get_mut(self.n) {
                Some(slot) => {
                    *slot = Run {
                        start: self.start,
                        end: x,
                        class: self.cur,
                    };
                    self.n += 1;
                }
                None => self.dropped += 1,
            }
        }
    }
}

/// Runs of one RGB332 row into `out`; returns how many were stored and how many did not fit.
/// One table lookup per pixel (the path for rows that are not word-aligned).
pub fn row_runs_rgb332(row: &[u8], classes: &ColourClasses, out: &mut [Run]) -> (usize, u32) {
    let mut rb = RunBuilder::new(out);
    let mut x: u16 = 0;
    for &p in row {
        rb.step(x, classes.class_of_rgb332(p));
        x = x.wrapping_add(1);
    }
    rb.close(x);
    (rb.n, rb.dropped)
}

/// [`row_runs_rgb332`] over a row read as little-endian 32-bit words (four pixels each, first
/// pixel in the low byte); `width` pixels are used. This is the board's path: outside a marker
/// run, a word that [`ColourClasses::word_is_background`] clears costs one load and a few ALU
/// instructions; other words are classified pixel by pixel through the 256-entry table.
pub fn row_runs_rgb332_words(
    row: &[u32],
    width: u16,
    classes: &ColourClasses,
    out: &mut [Run],
) -> (usize, u32) {
    let mut rb = RunBuilder::new(out);
    let full = (usize::from(width) / 4).min(row.len());
    let words = &row[..full];
    let mut i = 0;
    while i < full {
        if rb.cur == BACKGROUND {
            // Skip background words; this loop is where almost all of a frame goes.
            while i < full && classes.word_is_background(words[i]) {
                i += 1;
            }
            if i == full {
                break;
            }
        }
        let x = (i * 4) as u16;
        for (k, &p) in words[i].to_le_bytes().iter().enumerate() {
            rb.step(x + k as u16, classes.class_of_rgb332(p));
        }
        i += 1;
    }
    let mut x = (full * 4) as u16;
    if let Some(&w) = row.get(full) {
        for &p in w.to_le_bytes().iter().take(usize::from(width) % 4) {
            rb.step(x, classes.class_of_rgb332(p));
            x += 1;
        }
    }
    rb.close(x);
    (rb.n, rb.dropped)
}

/// Runs of one RGB565 (little-endian) row into `out`, one pixel at a time.
pub fn row_runs_rgb565(row: &[u8], classes: &ColourClasses, out: &mut [Run]) -> (usize, u32) {
    let mut rb = RunBuilder::new(out);
    let mut x: u16 = 0;
    for p in row.chunks_exact(2) {
        rb.step(x, classes.class_of_rgb565(u16::from_le_bytes([p[0], p[1]])));
        x = x.wrapping_add(1);
    }
    rb.close(x);
    (rb.n, rb.dropped)
}

/// `bytes` as little-endian 32-bit words, if the slice is 4-byte aligned and a whole number of
/// words long (frame-grabber buffers are).
pub fn as_words(bytes: &[u8]) -> Option<&[u32]> {
    bytemuck::try_cast_slice(bytes).ok()
}

/// Finds the colour blobs of a whole frame held in `frame` (a frame buffer of the window, or a
/// copy). `detector` carries the connected-component state (about 7.7 KiB, so it is passed in
/// rather than put on the stack).
pub fn process_frame(
    frame: &[u8],
    geometry: &FrameGeometry,
    classes: &ColourClasses,
    config: &PipelineConfig,
    detector: &mut BlobDetector,
) -> Result<Detections, PipelineError> {
    let bpp = geometry.format.bytes_per_pixel();
    let row_len = usize::from(geometry.width) * bpp;
    if geometry.stride < row_len || geometry.width == u16::MAX {
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
    let step = config.row_step.max(1);
    detector.begin_frame(step);
    let mut runs = [Run::default(); MAX_RUNS_PER_ROW];
    // Word-aligned RGB332 frames (every frame-grabber buffer) take the four-pixel path.
    let words: Option<&[u32]> = match geometry.format {
        PixelFormat::Rgb332 if geometry.stride.is_multiple_of(4) => {
            as_words(&frame[..frame.len() & !3])
        }
        _ => None,
    };
    let row_words = usize::from(geometry.width).div_ceil(4);
    let mut y: u16 = 0;
    while y < geometry.height {
        let start = usize::from(y) * geometry.stride;
        let row = &frame[start..start + row_len];
        let word_row = words.and_then(|w| w.get(start / 4..start / 4 + row_words));
        let (n, dropped) = match (geometry.format, word_row) {
            (PixelFormat::Rgb332, Some(w)) => {
                row_runs_rgb332_words(w, geometry.width, classes, &mut runs)
            }
            (PixelFormat::Rgb332, None) => row_runs_rgb332(row, classes, &mut runs),
            (PixelFormat::Rgb565, _) => row_runs_rgb565(row, classes, &mut runs),
        };
        detector.note_dropped_runs(dropped);
        detector.push_row(y, &runs[..n]);
        y = match y.checked_add(step) {
            Some(v) => v,
            None => break,
        };
    }
    Ok(detector.finish(config.min_area))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::MARKER_CLASSES;

    #[test]
    fn runs_of_a_row_with_odd_width_and_pair_boundaries() {
        let red = colour::MARKER_PALETTE[0].to_rgb332();
        let blue = colour::MARKER_PALETTE[2].to_rgb332();
        let g = 0x92; // grey
                      // columns: 0 g, 1 red, 2 red, 3 blue, 4 g, 5 g, 6 red (odd width 7)
        let row = [g, red, red, blue, g, g, red];
        let mut out = [Run::default(); 8];
        let (n, d) = row_runs_rgb332(&row, &MARKER_CLASSES, &mut out);
        assert_eq!(d, 0);
        assert_eq!(
            &out[..n],
            &[
                Run {
                    start: 1,
                    end: 3,
                    class: 1
                },
                Run {
                    start: 3,
                    end: 4,
                    class: 3
                },
                Run {
                    start: 6,
                    end: 7,
                    class: 1
                },
            ]
        );
        let row565: Vec<u8> = row
            .iter()
            .flat_map(|&p| colour::Rgb::from_rgb332(p).to_rgb565().to_le_bytes())
            .collect();
        let mut out2 = [Run::default(); 8];
        let (n2, _) = row_runs_rgb565(&row565, &MARKER_CLASSES, &mut out2);
        assert_eq!(&out2[..n2], &out[..n]);
        let words: Vec<u32> = row
            .chunks(4)
            .map(|c| {
                let mut b = [0u8; 4];
                b[..c.len()].copy_from_slice(c);
                u32::from_le_bytes(b)
            })
            .collect();
        let mut out3 = [Run::default(); 8];
        let (n3, _) = row_runs_rgb332_words(&words, 7, &MARKER_CLASSES, &mut out3);
        assert_eq!(&out3[..n3], &out[..n]);
        let mut small = [Run::default(); 2];
        assert_eq!(row_runs_rgb332(&row, &MARKER_CLASSES, &mut small), (2, 1));
    }

    #[test]
    fn short_frames_and_bad_geometry_are_errors() {
        let mut det = BlobDetector::new();
        let g = FrameGeometry::packed(640, 480, PixelFormat::Rgb332);
        let cfg = PipelineConfig::default();
        assert_eq!(
            process_frame(&[0u8; 100], &g, &MARKER_CLASSES, &cfg, &mut det),
            Err(PipelineError::FrameTooShort {
                needed: 640 * 480,
                got: 100
            })
        );
        let bad = FrameGeometry { stride: 10, ..g };
        assert_eq!(
            process_frame(&[0u8; 100], &bad, &MARKER_CLASSES, &cfg, &mut det),
            Err(PipelineError::BadGeometry {
                width: 640,
                stride: 10
            })
        );
    }
}
