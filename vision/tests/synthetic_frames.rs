//! Whole frames with shapes drawn in the test: the pipeline must report every shape exactly (area,
//! bounding box, coordinate sums, hence centroid), in both pixel formats, from aligned and
//! unaligned slices.

use proptest::prelude::*;
use vision::blobs::{Blob, BlobDetector, Detections};
use vision::colour::{Rgb, MARKER_CLASSES, MARKER_PALETTE};
use vision::frame::PixelFormat;
use vision::{process_frame, FrameGeometry, PipelineConfig};

const W: u16 = 640;
const H: u16 = 480;

/// A frame being drawn, with the exact statistics of every shape kept as it is drawn.
struct Canvas {
    format: PixelFormat,
    bytes: Vec<u8>,
    truth: Vec<Blob>,
}

impl Canvas {
    fn new(format: PixelFormat) -> Self {
        let mut c = Canvas {
            format,
            bytes: vec![0; usize::from(W) * usize::from(H) * format.bytes_per_pixel()],
            truth: Vec::new(),
        };
        // Grey floor with a darker band and some noise-like texture that is not a marker colour.
        for y in 0..H {
            for x in 0..W {
                let v = 100 + ((x * 7 + y * 13) % 40) as u8;
                c.put(x, y, Rgb::new(v, v, v.saturating_sub(10)));
            }
        }
        c
    }

    fn put(&mut self, x: u16, y: u16, c: Rgb) {
        let i = usize::from(y) * usize::from(W) + usize::from(x);
        match self.format {
            PixelFormat::Rgb332 => self.bytes[i] = c.to_rgb332(),
            PixelFormat::Rgb565 => {
                self.bytes[2 * i..2 * i + 2].copy_from_slice(&c.to_rgb565().to_le_bytes())
            }
        }
    }

    fn shape(&mut self, class: u8, pixels: impl Iterator<Item = (u16, u16)>) {
        let colour = MARKER_PALETTE[usize::from(class - 1)];
        let mut b = Blob {
            class,
            min_x: u16::MAX,
            min_y: u16::MAX,
            ..Blob::default()
        };
        for (x, y) in pixels {
            self.put(x, y, colour);
            b.area += 1;
            b.sum_x += u32::from(x);
            b.sum_y += u32::from(y);
            b.min_x = b.min_x.min(x);
            b.min_y = b.min_y.min(y);
            b.max_x = b.max_x.max(x);
            b.max_y = b.max_y.max(y);
        }
        self.truth.push(b);
    }

    fn rect(&mut self, class: u8, x: u16, y: u16, w: u16, h: u16) {
        self.shape(
            class,
            (y..y + h).flat_map(move |yy| (x..x + w).map(move |xx| (xx, yy))),
        );
    }

    fn disc(&mut self, class: u8, cx: i32, cy: i32, r: i32) {
        let pts: Vec<(u16, u16)> = (cy - r..=cy + r)
            .flat_map(|y| (cx - r..=cx + r).map(move |x| (x, y)))
            .filter(|&(x, y)| (x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r)
            .filter(|&(x, y)| x >= 0 && y >= 0 && x < i32::from(W) && y < i32::from(H))
            .map(|(x, y)| (x as u16, y as u16))
            .collect();
        self.shape(class, pts.into_iter());
    }

    fn detect(&self, bytes: &[u8], config: &PipelineConfig) -> Detections {
        let mut det = BlobDetector::new();
        let g = FrameGeometry::packed(W, H, self.format);
        process_frame(bytes, &g, &MARKER_CLASSES, config, &mut det).unwrap()
    }

    fn assert_exact(&self, det: &Detections) {
        let mut got: Vec<Blob> = det.blobs().to_vec();
        let mut want = self.truth.clone();
        got.sort_by_key(|b| (b.min_y, b.min_x, b.class));
        want.sort_by_key(|b| (b.min_y, b.min_x, b.class));
        assert_eq!(got, want);
        assert_eq!(det.dropped, Default::default());
    }
}

fn scene(format: PixelFormat) -> Canvas {
    let mut c = Canvas::new(format);
    c.rect(1, 10, 20, 31, 17); // odd x, odd size
    c.rect(2, 600, 0, 40, 10); // touches the top and right edges
    c.rect(3, 0, 470, 5, 10); // bottom-left corner
    c.disc(4, 320, 240, 25);
    c.disc(5, 101, 301, 12);
    // Two different classes side by side: two blobs.
    c.rect(6, 200, 100, 20, 20);
    c.rect(7, 220, 100, 20, 20);
    // An L shape (one blob) and a ring (one blob with a hole).
    let l: Vec<(u16, u16)> = (400..460)
        .map(|y| (500u16, y))
        .chain((501..540).map(|x| (x, 459)))
        .collect();
    c.shape(8, l.into_iter());
    let ring: Vec<(u16, u16)> = (350..390)
        .flat_map(|y| (50..90).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let (dx, dy) = (i32::from(x) - 70, i32::from(y) - 370);
            let d = dx * dx + dy * dy;
            (100..=361).contains(&d)
        })
        .collect();
    c.shape(1, ring.into_iter());
    c
}

#[test]
fn drawn_shapes_are_detected_exactly_rgb332() {
    let c = scene(PixelFormat::Rgb332);
    let config = PipelineConfig {
        row_step: 1,
        min_area: 1,
    };
    c.assert_exact(&c.detect(&c.bytes, &config));
    // The same frame one byte off word alignment takes the byte path: same answer.
    let mut shifted = vec![0u8; c.bytes.len() + 1];
    shifted[1..].copy_from_slice(&c.bytes);
    c.assert_exact(&c.detect(&shifted[1..], &config));
}

#[test]
fn drawn_shapes_are_detected_exactly_rgb565() {
    let c = scene(PixelFormat::Rgb565);
    c.assert_exact(&c.detect(
        &c.bytes,
        &PipelineConfig {
            row_step: 1,
            min_area: 1,
        },
    ));
}

#[test]
fn centroid_of_a_disc_is_its_centre() {
    let mut c = Canvas::new(PixelFormat::Rgb332);
    c.disc(2, 333, 222, 30);
    let det = c.detect(&c.bytes, &PipelineConfig::default());
    let b = det.blobs()[0];
    assert_eq!(b.centroid_q8(), (333 * 256, 222 * 256));
    assert_eq!((b.width(), b.height()), (61, 61));
}

#[test]
fn row_subsampling_counts_sampled_pixels() {
    let mut c = Canvas::new(PixelFormat::Rgb332);
    c.rect(1, 100, 100, 40, 30); // rows 100..130: 15 even rows
    let det = c.detect(
        &c.bytes,
        &PipelineConfig {
            row_step: 2,
            min_area: 1,
        },
    );
    let b = det.blobs()[0];
    assert_eq!(det.blobs().len(), 1);
    assert_eq!(b.area, 40 * 15);
    assert_eq!((b.min_y, b.max_y, b.min_x, b.max_x), (100, 128, 100, 139));
    assert_eq!(b.sum_y, 40 * (100..130).step_by(2).sum::<u32>());
}

#[test]
fn min_area_drops_specks() {
    let mut c = Canvas::new(PixelFormat::Rgb332);
    c.rect(1, 10, 10, 1, 1);
    c.rect(2, 50, 50, 3, 3);
    let det = c.detect(
        &c.bytes,
        &PipelineConfig {
            row_step: 1,
            min_area: 4,
        },
    );
    assert_eq!(det.blobs().len(), 1);
    assert_eq!(det.blobs()[0].area, 9);
}

fn arb_rects() -> impl Strategy<Value = Vec<(u8, u16, u16, u16, u16)>> {
    // Rectangles on a 16 x 12 grid of 40-pixel cells, each inside its own cell with a margin, so
    // they never touch.
    proptest::collection::btree_map(
        (0u16..16, 0u16..12),
        (1u8..=8, 0u16..10, 0u16..10, 1u16..30, 1u16..30),
        0..12,
    )
    .prop_map(|m| {
        m.into_iter()
            .map(|((gx, gy), (class, ox, oy, w, h))| (class, gx * 40 + ox, gy * 40 + oy, w, h))
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn random_separate_rectangles_are_exact(rects in arb_rects(), rgb565 in any::<bool>()) {
        let format = if rgb565 { PixelFormat::Rgb565 } else { PixelFormat::Rgb332 };
        let mut c = Canvas::new(format);
        for &(class, x, y, w, h) in &rects {
            c.rect(class, x, y, w, h);
        }
        let det = c.detect(&c.bytes, &PipelineConfig { row_step: 1, min_area: 1 });
        c.assert_exact(&det);
    }
}
