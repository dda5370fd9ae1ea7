use super::*;
use crate::mmio::testing::RamBus;
use core::cell::RefCell;
use core::ops::Range;
use vision::blobs::BlobDetector;
use vision::colour::{Rgb, MARKER_CLASSES, MARKER_PALETTE};
use vision::frame::PixelFormat;
use vision::run_window::{field, publish, status, WINDOW_LEN, WRITING};
use vision::runs::{blobs_from_runs, encode_frame};
use vision::{process_frame, FrameGeometry, PipelineConfig};

/// Word-aligned window memory (the unit's buffers are read as words in place).
struct Aligned {
    words: Vec<u32>,
    headers: RefCell<Vec<[u8; HEADER_LEN]>>,
}

impl Aligned {
    fn new(bytes: &[u8]) -> Self {
        Aligned {
            words: bytes
                .chunks(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            headers: RefCell::new(Vec::new()),
        }
    }
}

impl WindowMemory for Aligned {
    fn len(&self) -> usize {
        4 * self.words.len()
    }
    fn read_header(&self) -> [u8; HEADER_LEN] {
        let mut h = self.headers.borrow_mut();
        if !h.is_empty() {
            return h.remove(0);
        }
        let mut out = [0u8; HEADER_LEN];
        out.copy_from_slice(&bytemuck::cast_slice::<u32, u8>(&self.words)[..HEADER_LEN]);
        out
    }
    fn bytes(&self, range: Range<usize>) -> Option<&[u8]> {
        bytemuck::cast_slice::<u32, u8>(&self.words).get(range)
    }
}

fn regs_with(header: &Header) -> RamBus {
    let regs = RamBus::new(WINDOW_LEN);
    let mut h = [0u8; HEADER_LEN];
    header.emit(&mut h);
    regs.mem.lock().unwrap()[..HEADER_LEN].copy_from_slice(&h);
    regs
}

/// A frame with two drawn markers, and its window after publishing its runs (and an older
/// frame's before it).
fn scene() -> (Vec<u8>, FrameGeometry, Vec<u8>, Header) {
    let g = FrameGeometry::packed(160, 120, PixelFormat::Rgb332);
    let mut frame = vec![Rgb::new(120, 120, 110).to_rgb332(); g.frame_len()];
    for (c, x0, y0) in [(0usize, 10usize, 20usize), (2, 90, 60)] {
        for y in y0..y0 + 15 {
            for x in x0..x0 + 12 {
                frame[y * 160 + x] = MARKER_PALETTE[c].to_rgb332();
            }
        }
    }
    let mut window = vec![0u8; WINDOW_LEN];
    let mut h = Header::new(1024);
    h.emit(&mut window);
    let mut put = |off: usize, b: &[u8]| -> Result<(), ()> {
        window[off..off + b.len()].copy_from_slice(b);
        Ok(())
    };
    let mut runs = vec![0u32; 1024];
    publish(&mut h, &[], 0, (160, 120), &mut put).unwrap();
    let s = encode_frame(&frame, &g, &MARKER_CLASSES, &mut runs).unwrap();
    publish(&mut h, &runs[..s.words], 0, (160, 120), &mut put).unwrap();
    (frame, g, window, h)
}

#[test]
fn probe_needs_the_id_and_a_valid_layout() {
    let zero = RamBus::new(WINDOW_LEN);
    assert!(VisionUnit::probe(&zero, Aligned::new(&[0u8; WINDOW_LEN])).is_none());
    let (_, _, window, h) = scene();
    let regs = regs_with(&h);
    assert!(VisionUnit::probe(&regs, Aligned::new(&window)).is_some());
    // a wrong version is not this unit
    regs.write32(reg::VERSION, 0x0040_0002);
    assert!(VisionUnit::probe(&regs, Aligned::new(&window)).is_none());
}

#[test]
fn class_table_and_control_are_written_by_name() {
    let (_, _, window, h) = scene();
    let regs = regs_with(&h);
    let mut u = VisionUnit::probe(&regs, Aligned::new(&window)).unwrap();
    regs.write32(reg::CTRL, 3);
    u.load_classes(&MARKER_CLASSES);
    assert_eq!(u.ctrl(), Ctrl(0), "stopped while the table is written");
    {
        let m = regs.mem.lock().unwrap();
        for (c, &class) in MARKER_CLASSES.table().iter().enumerate() {
            assert_eq!(m[reg::LUT + c], class & 15, "code {c:#x}");
        }
    }
    u.start(true);
    assert!(u.ctrl().enable() && u.ctrl().irq_enable());
    u.start(false);
    assert!(u.ctrl().enable() && !u.ctrl().irq_enable());
    u.acknowledge();
    assert_eq!(regs.read32(reg::STATUS), status::FRAME);
    u.stop();
    assert_eq!(regs.read32(reg::CTRL), 0);
}

#[test]
fn newest_runs_once_in_place_give_the_pipelines_blobs() {
    let (frame, g, window, h) = scene();
    let regs = regs_with(&h);
    let mut u = VisionUnit::probe(&regs, Aligned::new(&window)).unwrap();
    assert!(u.has_new_runs());
    let mut det = BlobDetector::new();
    let cfg = PipelineConfig::default();
    let got = u
        .with_latest(|r| {
            let t = r.ticket;
            blobs_from_runs(r.words, t.width, t.height, t.dropped, &cfg, &mut det)
        })
        .unwrap()
        .unwrap();
    assert_eq!(got.0.sequence, 2);
    let mut det2 = BlobDetector::new();
    let want = process_frame(&frame, &g, &MARKER_CLASSES, &cfg, &mut det2).unwrap();
    assert_eq!(got.1, Ok(want));
    assert_eq!(want.blobs().len(), 2);
    assert_eq!(u.last_sequence(), 2);
    assert!(!u.has_new_runs());
    // the same frame is not handed out twice
    assert!(u.with_latest(|_| ()).unwrap().is_none());
    assert_eq!(u.stats().frames, 1);
}

#[test]
fn torn_and_mid_publish_reads_are_discarded() {
    let (_, _, window, h) = scene();
    let regs = regs_with(&h);
    let mem = Aligned::new(&window);
    let mut u = VisionUnit::probe(&regs, &mem).unwrap();
    let mut before = [0u8; HEADER_LEN];
    h.emit(&mut before);
    // the unit starts writing the ready buffer while it is read
    let mut torn = h;
    torn.buffer_seq[h.ready as usize] = WRITING;
    let mut after = [0u8; HEADER_LEN];
    torn.emit(&mut after);
    *mem.headers.borrow_mut() = vec![before, after];
    assert_eq!(
        u.with_latest(|r| r.words.len()),
        Err(UnitError::Header(HeaderError::Torn {
            expected: 2,
            found: WRITING
        }))
    );
    assert_eq!(u.stats().torn, 1);
    // mid-publish: sequence already new, the buffer not yet
    let mut mid = h;
    mid.sequence = 3;
    let mut b = [0u8; HEADER_LEN];
    mid.emit(&mut b);
    *mem.headers.borrow_mut() = vec![b];
    assert!(matches!(
        u.with_latest(|_| ()),
        Err(UnitError::Header(HeaderError::Inconsistent { .. }))
    ));
    assert_eq!(u.stats().inconsistent, 1);
    // then whole
    assert!(u.with_latest(|r| r.words.len()).unwrap().is_some());
}

#[test]
fn nothing_published_gives_none() {
    let h = Header::new(16);
    let mut window = vec![0u8; WINDOW_LEN];
    h.emit(&mut window);
    let regs = regs_with(&h);
    let mut u = VisionUnit::probe(&regs, Aligned::new(&window)).unwrap();
    assert!(!u.has_new_runs());
    assert_eq!(u.with_latest(|_| ()), Ok(None));
    assert_eq!(field::CTRL.start, reg::CTRL);
    assert_eq!(field::STATUS.start, reg::STATUS);
    assert_eq!(field::SEQUENCE.start, reg::SEQUENCE);
    assert_eq!(field::SIZE[1].start, reg::SIZE1);
}
