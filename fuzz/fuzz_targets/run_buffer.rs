//! Feeds arbitrary words to the run-buffer parser and the run-window header parser (the words
//! the vision unit, or the host for a QEMU car, leaves for the firmware). Whatever the words,
//! nothing panics; a buffer the parser accepts gives blobs, its rows are in order and inside the
//! frame, and every one of its words decodes and encodes back to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vision::blobs::BlobDetector;
use vision::run_window::{Header, HEADER_LEN};
use vision::runs::{blobs_from_runs, check, RowIter, RunWord};
use vision::PipelineConfig;

fuzz_target!(|data: &[u8]| {
    if let Ok(h) = Header::parse(data) {
        let mut out = [0u8; HEADER_LEN];
        h.emit(&mut out);
        assert_eq!(Header::parse(&out), Ok(h));
    }
    if data.len() < 5 {
        return;
    }
    let width = u16::from(data[0]) * 16 + 1;
    let height = u16::from(data[1]) * 16 + 1;
    let row_step = u16::from(data[2] % 4);
    let words: Vec<u32> = data[4..]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let checked = check(&words, width, height);
    let mut detector = BlobDetector::new();
    let config = PipelineConfig {
        row_step,
        ..PipelineConfig::default()
    };
    let blobs = blobs_from_runs(&words, width, height, 0, &config, &mut detector);
    assert_eq!(checked.is_ok(), blobs.is_ok());
    if checked.is_ok() {
        let mut last = None;
        for row in RowIter::new(&words, width, height) {
            let row = row.expect("a checked buffer parses");
            assert!(row.y < height && last.is_none_or(|l| row.y > l));
            last = Some(row.y);
        }
        for &w in &words {
            let d = RunWord::decode(w).expect("a checked buffer decodes");
            assert_eq!(d.encode(), Ok(w));
        }
    }
});
