use super::*;
use vision::runs::encode_codes;

const T: CameraTiming = CameraTiming { h_blank: 3 };

/// A 6x3 frame: class 1 on code 1, class 2 on code 2.
fn frame() -> Vec<u8> {
    vec![
        0, 1, 1, 0, 2, 2, //
        1, 1, 1, 1, 1, 1, //
        0, 0, 0, 0, 0, 0,
    ]
}

fn lut_words(u: &mut VisionUnit, c: u64) {
    // entries 1 and 2 (word 0 holds codes 0..=3)
    u.write(c, 0x100, 0xf, 0x0002_0100);
}

fn expected() -> (Vec<u32>, u32) {
    let mut lut = [0u8; 256];
    lut[1] = 1;
    lut[2] = 2;
    let mut out = vec![0u32; CAPACITY];
    let s = encode_codes(&frame(), 6, &lut, &mut out);
    out.truncate(s.words);
    (out, u32::from(s.width) | u32::from(s.height) << 16)
}

#[test]
fn registers_after_reset() {
    let mut u = VisionUnit::new();
    let r: Vec<u32> = (0..18).map(|i| u.read(0, 4 * i)).collect();
    assert_eq!(
        r,
        [
            0x4E52_4C41,
            0x0040_0001,
            4096,
            0x4000,
            0x8000,
            0,
            1,
            WRITING,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0
        ]
    );
}

#[test]
fn a_frame_is_published_two_cycles_after_its_end_once_active() {
    let mut u = VisionUnit::new();
    lut_words(&mut u, 5);
    u.write(6, 0x40, 1, ctrl::ENABLE | ctrl::IRQ_ENABLE);
    // the first frame only activates the unit (its end comes while enabled)
    let (f1, e1) = u.queue(20, &frame(), 6, 3, T);
    assert_eq!((f1, e1), (20, 20 + 2 * 9 + 6 + 1));
    u.advance_to(e1 + 3);
    assert_eq!(u.read(e1 + 3, 0x14), 0);
    assert_eq!(u.read(e1 + 3, 0x44), status::ACTIVE);
    // the second is processed
    let (f2, e2) = u.queue(0, &frame(), 6, 3, T);
    assert_eq!(f2, e1 + 1);
    assert_eq!(u.read(e2 + 2, 0x14), 0, "not yet during eof + 2");
    assert!(!u.irq());
    assert_eq!(u.read(e2 + 3, 0x14), 1);
    u.advance_to(e2 + 3);
    assert!(u.irq());
    let (words, size) = expected();
    assert_eq!(u.read(e2 + 3, 0x18), 0, "ready");
    assert_eq!(u.read(e2 + 3, 0x1c), 1);
    assert_eq!(u.read(e2 + 3, 0x20), WRITING);
    assert_eq!(u.read(e2 + 3, 0x24), words.len() as u32);
    assert_eq!(u.read(e2 + 3, 0x28), 0);
    assert_eq!(u.read(e2 + 3, 0x34), size);
    for (i, &w) in words.iter().enumerate() {
        assert_eq!(u.read(e2 + 3, 0x4000 + 4 * i as u32), w);
        // the other buffer reads as zero
        assert_eq!(u.read(e2 + 3, 0x8000 + 4 * i as u32), 0);
    }
    // write 1 to clear; a publish at the same edge wins
    u.write(e2 + 5, 0x44, 1, status::FRAME);
    assert!(!u.irq());
    let (_, e3) = u.queue(0, &frame(), 6, 3, T);
    u.write(e3 + 2, 0x44, 1, status::FRAME);
    assert!(u.irq());
    assert_eq!(u.read(e3 + 3, 0x18), 1);
    assert_eq!(u.read(e3 + 3, 0x14), 2);
}

#[test]
fn clearing_enable_drops_the_frame_in_progress() {
    let mut u = VisionUnit::new();
    lut_words(&mut u, 0);
    u.write(1, 0x40, 1, ctrl::ENABLE);
    let (_, e1) = u.queue(10, &frame(), 6, 3, T);
    let (f2, e2) = u.queue(0, &frame(), 6, 3, T);
    // off and on again during frame 2: it is dropped; its end activates the unit again
    u.write(f2 + 3, 0x40, 1, 0);
    u.write(f2 + 5, 0x40, 1, ctrl::ENABLE);
    let (_, e3) = u.queue(0, &frame(), 6, 3, T);
    assert!(e1 < e2);
    assert_eq!(u.read(e3 + 2, 0x14), 0);
    assert_eq!(u.read(e3 + 3, 0x14), 1);
    // a clear in the frame's last cycle before publishing drops it, one in the publishing
    // cycle does not
    let (_, e4) = u.queue(0, &frame(), 6, 3, T);
    u.write(e4 + 1, 0x40, 1, 0);
    assert_eq!(u.read(e4 + 10, 0x14), 1);
    u.write(e4 + 11, 0x40, 1, ctrl::ENABLE);
    let (_, e5) = u.queue(0, &frame(), 6, 3, T);
    let (_, e6) = u.queue(0, &frame(), 6, 3, T);
    u.write(e6 + 2, 0x40, 1, 0);
    assert_eq!(u.read(e6 + 3, 0x14), 2);
    assert!(e5 < e6);
}

#[test]
fn the_class_table_is_written_only_while_disabled() {
    let mut u = VisionUnit::new();
    u.write(0, 0x100, 0b0010, 0x0000_0700);
    assert_eq!(u.lut[1], 7);
    u.write(1, 0x40, 1, ctrl::ENABLE);
    u.write(2, 0x100, 0b0010, 0x0000_0300);
    assert_eq!(u.lut[1], 7);
    // reads of the table are zero
    assert_eq!(u.read(3, 0x100), 0);
    u.write(4, 0x40, 1, 0);
    u.write(5, 0x1fc, 0b1000, 0xff00_0000);
    assert_eq!(u.lut[255], 15);
}
