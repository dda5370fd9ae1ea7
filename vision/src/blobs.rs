//! Run-length connected components in one pass over the rows.
//!
//! Each row becomes runs of equal, non-background class. A run joins every run of the same class
//! in the previous row that it touches (8-connectivity: columns overlapping or diagonal), through
//! union-find over labels held in fixed arrays. Area, coordinate sums and bounding box are kept
//! per label and merged on union, so nothing is revisited; blobs come out when the frame ends.

use crate::colour::BACKGROUND;

/// Most runs kept for one row; further runs in that row are dropped (and counted).
pub const MAX_RUNS_PER_ROW: usize = 64;
/// Most labels per frame; runs that need a new label past this are dropped (and counted).
pub const MAX_LABELS: usize = 256;
/// Most blobs reported per frame (the largest are kept).
pub const MAX_BLOBS: usize = 32;

/// A horizontal run of one class: columns `start..end`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Run {
    pub start: u16,
    pub end: u16,
    pub class: u8,
}

/// A connected region of one colour class, in pixel coordinates of the processed rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Blob {
    pub class: u8,
    /// Pixels in the blob.
    pub area: u32,
    /// Sum of the column index over the blob's pixels.
    pub sum_x: u32,
    /// Sum of the row index over the blob's pixels.
    pub sum_y: u32,
    pub min_x: u16,
    pub min_y: u16,
    /// Inclusive.
    pub max_x: u16,
    /// Inclusive.
    pub max_y: u16,
}

impl Blob {
    /// Centroid in pixel indices (the mean column and row), exact to 1/256 pixel, rounded.
    pub fn centroid_q8(&self) -> (u32, u32) {
        let a = u64::from(self.area.max(1));
        let q = |s: u32| ((u64::from(s) * 256 + a / 2) / a) as u32;
        (q(self.sum_x), q(self.sum_y))
    }

    /// Centroid in pixel indices (the mean column and row).
    pub fn centroid(&self) -> (f32, f32) {
        let a = self.area.max(1) as f32;
        (self.sum_x as f32 / a, self.sum_y as f32 / a)
    }

    /// Bounding box width in pixels.
    pub fn width(&self) -> u16 {
        self.max_x - self.min_x + 1
    }

    /// Bounding box height in pixels.
    pub fn height(&self) -> u16 {
        self.max_y - self.min_y + 1
    }

    fn absorb(&mut self, o: &Blob) {
        self.area += o.area;
        self.sum_x = self.sum_x.wrapping_add(o.sum_x);
        self.sum_y = self.sum_y.wrapping_add(o.sum_y);
        self.min_x = self.min_x.min(o.min_x);
        self.min_y = self.min_y.min(o.min_y);
        self.max_x = self.max_x.max(o.max_x);
        self.max_y = self.max_y.max(o.max_y);
    }
}

/// What a frame lost to the fixed capacities; all zero on ordinary frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Dropped {
    /// Runs beyond [`MAX_RUNS_PER_ROW`] in some row.
    pub runs: u32,
    /// Runs that found no free label.
    pub unlabelled_runs: u32,
    /// Blobs beyond [`MAX_BLOBS`] (the smallest are dropped).
    pub blobs: u32,
}

/// The blobs of one frame, largest first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Detections {
    blobs: [Blob; MAX_BLOBS],
    len: usize,
    pub dropped: Dropped,
}

impl Default for Detections {
    fn default() -> Self {
        Detections {
            blobs: [Blob::default(); MAX_BLOBS],
            len: 0,
            dropped: Dropped::default(),
        }
    }
}

impl Detections {
    pub fn blobs(&self) -> &[Blob] {
        &self.blobs[..self.len]
    }

    /// The largest blob of `class`.
    pub fn largest_of_class(&self, class: u8) -> Option<&Blob> {
        self.blobs().iter().find(|b| b.class == class)
    }
}

const NO_LABEL: u16 = u16::MAX;

#[derive(Debug, Clone, Copy, Default)]
struct LabelledRun {
    run: Run,
    label: u16,
}

/// Connected-component state; reusable across frames, about 7.7 KiB (small enough for the
/// firmware's stack).
#[derive(Debug, Clone)]
pub struct BlobDetector {
    parent: [u16; MAX_LABELS],
    stats: [Blob; MAX_LABELS],
    labels: usize,
    /// Runs of the previous row and of the row being added; `prev` selects which is which, so
    /// no row is copied.
    rows: [[LabelledRun; MAX_RUNS_PER_ROW]; 2],
    prev: usize,
    prev_len: usize,
    prev_y: Option<u16>,
    row_step: u16,
    dropped: Dropped,
}

impl Default for BlobDetector {
    fn default() -> Self {
        Self::new()
    }
}

impl BlobDetector {
    pub const fn new() -> Self {
        BlobDetector {
            parent: [0; MAX_LABELS],
            stats: [Blob {
                class: 0,
                area: 0,
                sum_x: 0,
                sum_y: 0,
                min_x: 0,
                min_y: 0,
                max_x: 0,
                max_y: 0,
            }; MAX_LABELS],
            labels: 0,
            rows: [[LabelledRun {
                run: Run {
                    start: 0,
                    end: 0,
                    class: 0,
                },
                label: 0,
            }; MAX_RUNS_PER_ROW]; 2],
            prev: 0,
            prev_len: 0,
            prev_y: None,
            row_step: 1,
            dropped: Dropped {
                runs: 0,
                unlabelled_runs: 0,
                blobs: 0,
            },
        }
    }

    /// Forgets the previous frame; rows `row_step` apart will count as adjacent.
    pub fn begin_frame(&mut self, row_step: u16) {
        self.row_step = row_step.max(1);
        self.labels = 0;
        self.prev_len = 0;
        self.prev_y = None;
        self.dropped = Dropped::default();
    }

    /// Counts runs a row could not keep.
    pub fn note_dropped_runs(&mut self, n: u32) {
        self.dropped.runs += n;
    }

    fn find(&mut self, mut i: u16) -> u16 {
        while self.parent[usize::from(i)] != i {
            let p = self.parent[usize::from(i)];
            let gp = self.parent[usize::from(p)];
            self.parent[usize::from(i)] = gp;
            i = gp;
        }
        i
    }

    fn union(&mut self, a: u16, b: u16) -> u16 {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return ra;
        }
        let (keep, gone) = if ra < rb { (ra, rb) } else { (rb, ra) };
        self.parent[usize::from(gone)] = keep;
        let g = self.stats[usize::from(gone)];
        self.stats[usize::from(keep)].absorb(&g);
        keep
    }

    /// Adds row `y`'s runs (sorted by `start`, not overlapping, class not background). Rows must
    /// come in increasing `y`; a row is connected to the previous one only if it is `row_step`
    /// below it.
    pub fn push_row(&mut self, y: u16, runs: &[Run]) {
        let adjacent = matches!(self.prev_y, Some(p) if p.wrapping_add(self.row_step) == y);
        let prev_len = if adjacent { self.prev_len } else { 0 };
        let n = runs.len().min(MAX_RUNS_PER_ROW);
        self.dropped.runs += (runs.len() - n) as u32;
        let (ps, cs) = (self.prev, self.prev ^ 1);
        let mut j = 0;
        for (i, &run) in runs[..n].iter().enumerate() {
            let mut label = NO_LABEL;
            while j < prev_len && self.rows[ps][j].run.end < run.start {
                j += 1;
            }
            let mut k = j;
            while k < prev_len && self.rows[ps][k].run.start <= run.end {
                let p = self.rows[ps][k];
                if p.run.class == run.class && p.label != NO_LABEL {
                    label = if label == NO_LABEL {
                        self.find(p.label)
                    } else {
                        self.union(label, p.label)
                    };
                }
                k += 1;
            }
            if label == NO_LABEL && run.class != BACKGROUND {
                if self.labels < MAX_LABELS {
                    label = self.labels as u16;
                    self.parent[self.labels] = label;
                    self.stats[self.labels] = Blob {
                        class: run.class,
                        area: 0,
                        sum_x: 0,
                        sum_y: 0,
                        min_x: run.start,
                        min_y: y,
                        max_x: run.start,
                        max_y: y,
                    };
                    self.labels += 1;
                } else {
                    self.dropped.unlabelled_runs += 1;
                }
            }
            if label != NO_LABEL {
                let len = u32::from(run.end - run.start);
                let s = &mut self.stats[usize::from(label)];
                s.area += len;
                // Sum of start..end, exact: one of the two factors is even.
                let xs = (u32::from(run.start) + u32::from(run.end) - 1) * len / 2;
                s.sum_x = s.sum_x.wrapping_add(xs);
                s.sum_y = s.sum_y.wrapping_add(u32::from(y) * len);
                s.min_x = s.min_x.min(run.start);
                s.max_x = s.max_x.max(run.end - 1);
                s.max_y = s.max_y.max(y);
            }
            self.rows[cs][i] = LabelledRun { run, label };
        }
        self.prev = cs;
        self.prev_len = n;
        self.prev_y = Some(y);
    }

    /// Ends the frame: blobs of at least `min_area` pixels, largest first.
    pub fn finish(&mut self, min_area: u32) -> Detections {
        let mut out = Detections {
            dropped: self.dropped,
            ..Detections::default()
        };
        for i in 0..self.labels {
            if usize::from(self.parent[i]) != i {
                continue;
            }
            let b = self.stats[i];
            if b.area < min_area.max(1) {
                continue;
            }
            // Insertion into the size-ordered list; the smallest falls off the end.
            let mut pos = out.len;
            while pos > 0 && out.blobs[pos - 1].area < b.area {
                pos -= 1;
            }
            if pos >= MAX_BLOBS {
                out.dropped.blobs += 1;
                continue;
            }
            if out.len == MAX_BLOBS {
                out.dropped.blobs += 1;
            } else {
                out.len += 1;
            }
            let mut m = out.len - 1;
            while m > pos {
                out.blobs[m] = out.blobs[m - 1];
                m -= 1;
            }
            out.blobs[pos] = b;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(start: u16, end: u16, class: u8) -> Run {
        Run { start, end, class }
    }

    #[test]
    fn detector_state_size_is_as_documented() {
        let size = core::mem::size_of::<BlobDetector>();
        assert!((7 * 1024..8 * 1024).contains(&size), "{size}");
    }

    #[test]
    fn u_shape_merges_into_one_blob() {
        // Rows 0..3: two columns of class 1 joined by a bottom bar.
        // X...X
        // X...X
        // XXXXX
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        d.push_row(0, &[run(0, 1, 1), run(4, 5, 1)]);
        d.push_row(1, &[run(0, 1, 1), run(4, 5, 1)]);
        d.push_row(2, &[run(0, 5, 1)]);
        let det = d.finish(1);
        assert_eq!(det.blobs().len(), 1);
        let b = det.blobs()[0];
        assert_eq!(b.area, 9);
        assert_eq!((b.min_x, b.min_y, b.max_x, b.max_y), (0, 0, 4, 2));
        assert_eq!(b.sum_x, 2 * 4 + 10);
        assert_eq!(b.sum_y, 2 + 10);
    }

    #[test]
    fn diagonal_touch_connects_and_classes_stay_apart() {
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        d.push_row(0, &[run(0, 2, 1), run(5, 6, 2)]);
        // Diagonal neighbour of (1, 0) at (2, 1); class 2 below class 2 at column 5 but as class 3.
        d.push_row(1, &[run(2, 3, 1), run(5, 6, 3)]);
        // Gap of one column from (2, 1): not touching.
        d.push_row(2, &[run(4, 5, 1)]);
        let det = d.finish(1);
        let mut areas: Vec<(u8, u32)> = det.blobs().iter().map(|b| (b.class, b.area)).collect();
        areas.sort();
        assert_eq!(areas, vec![(1, 1), (1, 3), (2, 1), (3, 1)]);
    }

    #[test]
    fn skipped_row_breaks_connectivity() {
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        d.push_row(0, &[run(0, 4, 1)]);
        d.push_row(2, &[run(0, 4, 1)]);
        assert_eq!(d.finish(1).blobs().len(), 2);
    }

    #[test]
    fn capacities_are_counted_not_panicking() {
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        let runs: Vec<Run> = (0..200).map(|i| run(i * 3, i * 3 + 1, 1)).collect();
        for y in (0..20).step_by(2) {
            d.push_row(y, &runs);
        }
        let det = d.finish(1);
        let rows = 10u32;
        let kept = MAX_RUNS_PER_ROW as u32;
        assert_eq!(det.dropped.runs, rows * (200 - kept));
        assert_eq!(det.dropped.unlabelled_runs, rows * kept - MAX_LABELS as u32);
        assert_eq!(det.blobs().len(), MAX_BLOBS);
        assert_eq!(det.dropped.blobs, (MAX_LABELS - MAX_BLOBS) as u32);
    }

    #[test]
    fn blobs_come_largest_first_and_min_area_filters() {
        let mut d = BlobDetector::new();
        d.begin_frame(1);
        d.push_row(0, &[run(0, 1, 1), run(3, 10, 2), run(12, 15, 3)]);
        let det = d.finish(2);
        let got: Vec<u32> = det.blobs().iter().map(|b| b.area).collect();
        assert_eq!(got, vec![7, 3]);
        assert_eq!(det.largest_of_class(3).map(|b| b.area), Some(3));
        assert_eq!(det.largest_of_class(1), None);
    }
}
