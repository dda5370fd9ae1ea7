use super::*;
use crate::blobs::BlobDetector;
use crate::colour::{Rgb, MARKER_CLASSES, MARKER_PALETTE};
use crate::{process_frame, row_runs_rgb332};
use proptest::prelude::*;

fn lut_of(classes: &ColourClasses) -> [u8; 256] {
    *classes.table()
}

/// Runs of a row computed the plain way (every pixel, no capacity).
fn naive_rows(codes: &[u8], width: usize, lut: &[u8; 256]) -> Vec<(u16, Vec<Run>)> {
    let mut rows = Vec::new();
    for (y, row) in codes.chunks(width).enumerate() {
        let mut runs = Vec::new();
        let mut x = 0;
        while x < row.len() {
            let c = lut[usize::from(row[x])] & 15;
            let start = x;
            while x < row.len() && lut[usize::from(row[x])] & 15 == c {
                x += 1;
            }
            if c != 0 {
                runs.push(Run {
                    start: start as u16,
                    end: x as u16,
                    class: c,
                });
            }
        }
        if !runs.is_empty() {
            rows.push((y as u16, runs));
        }
    }
    rows
}

fn decoded_rows(words: &[u32], w: u16, h: u16) -> Vec<(u16, Vec<Run>)> {
    RowIter::new(words, w, h)
        .map(|r| {
            let r = r.unwrap();
            (r.y, r.runs.iter().map(|&w| run_of(w)).collect())
        })
        .collect()
}

#[test]
fn words_have_the_documented_layout() {
    let run = RunWord::Run {
        class: 3,
        first: 0x123,
        last: 0x456,
    };
    assert_eq!(run.encode(), Ok(0x3012_3456));
    assert_eq!(RunWord::decode(0x3012_3456), Some(run));
    let end = RunWord::RowEnd { y: 479, count: 2 };
    assert_eq!(end.encode(), Ok(0x0002_01DF));
    assert_eq!(RunWord::decode(0x0002_01DF), Some(end));
    // reserved bits, first after last, empty row end
    assert_eq!(RunWord::decode(0x3112_3456), None);
    assert_eq!(RunWord::decode(0x3045_6123), None);
    assert_eq!(RunWord::decode(0x0000_0005), None);
    assert_eq!(RunWord::decode(0x0002_1005), None);
    for bad in [
        RunWord::Run {
            class: 0,
            first: 0,
            last: 0,
        },
        RunWord::Run {
            class: 16,
            first: 0,
            last: 0,
        },
        RunWord::Run {
            class: 1,
            first: 2,
            last: 1,
        },
        RunWord::Run {
            class: 1,
            first: 0,
            last: 4096,
        },
        RunWord::RowEnd { y: 0, count: 0 },
        RunWord::RowEnd { y: 4096, count: 1 },
        RunWord::RowEnd { y: 0, count: 4096 },
    ] {
        assert_eq!(bad.encode(), Err(EncodeError::OutOfRange), "{bad:?}");
    }
}

proptest! {
    #[test]
    fn word_encode_decode_round_trip(class in 1u8..16, a in 0u16..4096, b in 0u16..4096,
                                     y in 0u16..4096, count in 1u16..4096) {
        let run = RunWord::Run { class, first: a.min(b), last: a.max(b) };
        prop_assert_eq!(RunWord::decode(run.encode().unwrap()), Some(run));
        let end = RunWord::RowEnd { y, count };
        prop_assert_eq!(RunWord::decode(end.encode().unwrap()), Some(end));
    }

    #[test]
    fn any_decodable_word_encodes_back(w in any::<u32>()) {
        if let Some(d) = RunWord::decode(w) {
            prop_assert_eq!(d.encode(), Ok(w));
        }
    }

    /// The encoder's words parse back into the plain runs of every row.
    #[test]
    fn encoder_matches_plain_runs(
        width in 1usize..40,
        height in 1usize..12,
        seed in proptest::collection::vec(0u8..6, 1..480),
        lut_seed in any::<[u8; 16]>(),
    ) {
        let mut lut = [0u8; 256];
        for (i, e) in lut.iter_mut().enumerate() {
            *e = if i < 6 { lut_seed[i] % 4 } else { 0 };
        }
        let codes: Vec<u8> = (0..width * height).map(|i| seed[i % seed.len()]).collect();
        let mut out = vec![0u32; MAX_CAPACITY];
        let s = encode_codes(&codes, width as u16, &lut, &mut out);
        prop_assert_eq!(s.dropped, 0);
        prop_assert_eq!((s.width, s.height), (width as u16, height as u16));
        let words = &out[..s.words];
        prop_assert_eq!(
            decoded_rows(words, width as u16, height as u16),
            naive_rows(&codes, width, &lut)
        );
    }

    /// A full buffer keeps every stored run with its row end and counts the rest.
    #[test]
    fn capacity_is_respected(cap in 1usize..64, width in 1usize..30, height in 1usize..10,
                             seed in proptest::collection::vec(0u8..3, 1..64)) {
        let lut = {
            let mut l = [0u8; 256];
            l[1] = 1;
            l[2] = 2;
            l
        };
        let codes: Vec<u8> = (0..width * height).map(|i| seed[i % seed.len()]).collect();
        let mut big = vec![0u32; MAX_CAPACITY];
        let all = encode_codes(&codes, width as u16, &lut, &mut big);
        let mut small = vec![0u32; cap];
        let s = encode_codes(&codes, width as u16, &lut, &mut small);
        prop_assert!(s.words <= cap);
        let stored = check(&small[..s.words], width as u16, height as u16).unwrap();
        let total = check(&big[..all.words], width as u16, height as u16).unwrap();
        prop_assert_eq!(stored + usize::from(s.dropped), total);
    }

    #[test]
    fn parsers_never_panic(words in proptest::collection::vec(any::<u32>(), 0..64),
                           w in any::<u16>(), h in any::<u16>()) {
        let _ = check(&words, w, h);
        let mut d = BlobDetector::new();
        let _ = blobs_from_runs(&words, w, h, 0, &PipelineConfig::default(), &mut d);
    }
}

#[test]
fn a_full_buffer_drops_runs_but_never_a_row_end() {
    // one run per row: class 1 at columns 1..=2 of a 4-wide row
    let lut = {
        let mut l = [0u8; 256];
        l[9] = 1;
        l
    };
    let codes: Vec<u8> = (0..5).flat_map(|_| [0u8, 9, 9, 0]).collect();
    let mut out = [0u32; 5];
    let s = encode_codes(&codes, 4, &lut, &mut out);
    // rows 0 and 1 fit (4 words), row 2's run would leave no room for its end
    assert_eq!(s.words, 4);
    assert_eq!(s.dropped, 3);
    assert_eq!((s.width, s.height), (4, 5));
    assert_eq!(
        out[..4],
        [0x1000_1002, 0x0001_0000, 0x1000_1002, 0x0001_0001]
    );
    assert_eq!(check(&out[..4], 4, 5), Ok(2));
    // capacity 1: nothing fits
    let mut one = [0u32; 1];
    assert_eq!(encode_codes(&codes, 4, &lut, &mut one).words, 0);
}

#[test]
fn runs_at_both_edges_and_single_pixels() {
    let lut = {
        let mut l = [0u8; 256];
        l[1] = 1;
        l[2] = 2;
        l[0x13] = 0x13; // only the low 4 bits are kept, as in the unit's table
        l
    };
    let codes = [1u8, 2, 1, 0, 0x13, 0x13, 2, 2];
    let mut out = [0u32; 16];
    let s = encode_codes(&codes, 8, &lut, &mut out);
    let runs: Vec<Run> = decoded_rows(&out[..s.words], 8, 1).remove(0).1;
    let want = [(0, 1, 1), (1, 2, 2), (2, 3, 1), (4, 6, 3), (6, 8, 2)];
    let want: Vec<Run> = want
        .iter()
        .map(|&(start, end, class)| Run { start, end, class })
        .collect();
    assert_eq!(runs, want);
}

#[test]
fn every_rejection_of_the_parser() {
    let run = |class: u32, a: u32, b: u32| class << 28 | a << 12 | b;
    let end = |count: u32, y: u32| count << 16 | y;
    let cases: &[(&[u32], RunError)] = &[
        (&[run(1, 0, 3) | 1 << 24], RunError::BadWord { index: 0 }),
        (&[run(1, 4, 3)], RunError::BadWord { index: 0 }),
        (&[end(0, 1)], RunError::BadWord { index: 0 }),
        (
            &[run(1, 0, 3), run(2, 3, 4), end(2, 0)],
            RunError::Unordered { index: 1 },
        ),
        (
            &[run(1, 0, 3), run(1, 4, 4), end(2, 0)],
            RunError::Unordered { index: 1 },
        ),
        (
            &[run(1, 0, 10), end(1, 0)],
            RunError::OutsideFrame { index: 0 },
        ),
        (
            &[run(1, 0, 3), end(1, 8)],
            RunError::OutsideFrame { index: 1 },
        ),
        (
            &[run(1, 0, 3), end(2, 0)],
            RunError::CountMismatch { index: 1 },
        ),
        (
            &[run(1, 0, 3), end(1, 2), run(1, 0, 3), end(1, 2)],
            RunError::RowOrder { index: 3 },
        ),
        (
            &[run(1, 0, 3), end(1, 2), run(1, 0, 3)],
            RunError::Unterminated { index: 2 },
        ),
    ];
    for (words, err) in cases {
        assert_eq!(check(words, 8, 8), Err(*err), "{words:x?}");
        let mut d = BlobDetector::new();
        assert_eq!(
            blobs_from_runs(words, 8, 8, 0, &PipelineConfig::default(), &mut d),
            Err(*err)
        );
    }
    // a neighbouring run of another class, and an empty buffer, are fine
    assert_eq!(check(&[run(1, 0, 3), run(2, 4, 4), end(2, 7)], 8, 8), Ok(2));
    assert_eq!(check(&[], 8, 8), Ok(0));
}

/// A textured frame with marker-coloured shapes and noise specks.
fn scene(width: u16, height: u16, seed: u32) -> Vec<u8> {
    let mut f = Vec::with_capacity(usize::from(width) * usize::from(height));
    let mut s = seed | 1;
    for y in 0..height {
        for x in 0..width {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let v = 90 + ((u32::from(x) * 7 + u32::from(y) * 13) % 50) as u8;
            let mut c = Rgb::new(v, v, v);
            let k = usize::from(x / 37 + y / 29) % 8;
            if (x % 37) < 20 && (y % 29) < 14 && (x / 37 + y / 29) % 3 == 0 {
                c = MARKER_PALETTE[k];
            }
            if s.is_multiple_of(1999) {
                c = MARKER_PALETTE[(s as usize >> 8) % 8];
            }
            f.push(c.to_rgb332());
        }
    }
    f
}

#[test]
fn blobs_from_runs_equal_the_software_pipeline() {
    for (w, h, seed) in [(640u16, 480u16, 1u32), (320, 240, 7), (123, 77, 99)] {
        let frame = scene(w, h, seed);
        let g = FrameGeometry::packed(w, h, PixelFormat::Rgb332);
        let mut out = vec![0u32; MAX_CAPACITY];
        let s = encode_frame(&frame, &g, &MARKER_CLASSES, &mut out).unwrap();
        assert_eq!((s.width, s.height, s.dropped), (w, h, 0));
        for row_step in [1, 2, 3] {
            let cfg = PipelineConfig {
                row_step,
                ..PipelineConfig::default()
            };
            let mut a = BlobDetector::new();
            let mut b = BlobDetector::new();
            let want = process_frame(&frame, &g, &MARKER_CLASSES, &cfg, &mut a).unwrap();
            let got = blobs_from_runs(&out[..s.words], w, h, 0, &cfg, &mut b).unwrap();
            assert_eq!(got, want, "{w}x{h} step {row_step}");
            assert!(!want.blobs().is_empty());
        }
        // the same runs as the software row scan
        let rows = decoded_rows(&out[..s.words], w, h);
        for (y, runs) in rows {
            let row = &frame[usize::from(y) * usize::from(w)..][..usize::from(w)];
            let mut sw = [Run::default(); 256];
            let (n, _) = row_runs_rgb332(row, &MARKER_CLASSES, &mut sw);
            assert_eq!(runs, sw[..n].to_vec(), "row {y}");
        }
    }
}

#[test]
fn rgb565_frames_encode_like_their_rgb332_codes() {
    let frame = scene(160, 120, 5);
    let wide: Vec<u8> = frame
        .iter()
        .flat_map(|&p| Rgb::from_rgb332(p).to_rgb565().to_le_bytes())
        .collect();
    let g332 = FrameGeometry::packed(160, 120, PixelFormat::Rgb332);
    let g565 = FrameGeometry::packed(160, 120, PixelFormat::Rgb565);
    let (mut a, mut b) = (vec![0u32; 4096], vec![0u32; 4096]);
    let sa = encode_frame(&frame, &g332, &MARKER_CLASSES, &mut a).unwrap();
    let sb = encode_frame(&wide, &g565, &MARKER_CLASSES, &mut b).unwrap();
    assert_eq!(sa, sb);
    assert_eq!(a, b);
    let lut = lut_of(&MARKER_CLASSES);
    let mut c = vec![0u32; 4096];
    assert_eq!(encode_codes(&frame, 160, &lut, &mut c), sa);
    assert_eq!(a, c);
}

#[test]
fn bad_geometry_and_short_frames_are_errors() {
    let g = FrameGeometry::packed(64, 8, PixelFormat::Rgb332);
    let mut out = [0u32; 8];
    assert_eq!(
        encode_frame(&[0; 10], &g, &MARKER_CLASSES, &mut out),
        Err(PipelineError::FrameTooShort {
            needed: 512,
            got: 10
        })
    );
    let bad = FrameGeometry { stride: 3, ..g };
    assert!(matches!(
        encode_frame(&[0; 512], &bad, &MARKER_CLASSES, &mut out),
        Err(PipelineError::BadGeometry { .. })
    ));
}

#[test]
fn unit_drops_count_as_dropped_runs() {
    let frame = scene(64, 32, 3);
    let g = FrameGeometry::packed(64, 32, PixelFormat::Rgb332);
    let mut out = vec![0u32; 4096];
    let s = encode_frame(&frame, &g, &MARKER_CLASSES, &mut out).unwrap();
    let mut d = BlobDetector::new();
    let det = blobs_from_runs(
        &out[..s.words],
        64,
        32,
        5,
        &PipelineConfig::default(),
        &mut d,
    )
    .unwrap();
    assert_eq!(det.dropped.runs, 5);
}
