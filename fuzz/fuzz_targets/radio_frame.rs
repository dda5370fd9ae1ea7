//! Feeds arbitrary bytes to the radio deframer, to the raw frame parser and to a car
//! endpoint. Every frame that parses is emitted again and must parse to the same value,
//! byte for byte; the endpoint must never panic whatever arrives.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radio_mac::wire::{encode_frame, Frame, MAX_RAW};
use radio_mac::{CarConfig, CarId, CarMac, Deframer, Key};

fn reparse(frame: &Frame) {
    let mut raw = [0u8; MAX_RAW];
    let n = frame.emit_raw(&mut raw).expect("parsed frames re-emit");
    assert_eq!(Frame::parse(&raw[..n]).as_ref(), Ok(frame));
    let enc = encode_frame(frame).expect("parsed frames encode");
    let mut d = Deframer::new();
    let out: Vec<_> = enc.iter().filter_map(|b| d.push(*b)).collect();
    assert_eq!(out, vec![Ok(frame.clone())]);
}

fuzz_target!(|data: &[u8]| {
    // Raw frame parser.
    if let Ok(frame) = Frame::parse(data) {
        let mut raw = [0u8; MAX_RAW];
        let n = frame.emit_raw(&mut raw).expect("parsed frames re-emit");
        assert_eq!(&raw[..n], data, "parse is canonical");
        reparse(&frame);
    }
    // Stream deframer.
    let mut d = Deframer::new();
    for &b in data {
        if let Some(Ok(frame)) = d.push(b) {
            reparse(&frame);
        }
    }
    // Whole endpoint, with a key so authenticated commands are checked.
    let Some(id) = CarId::new(5) else { return };
    let mut cfg = CarConfig::new(id);
    cfg.key = Some(Key::new([0x42; 16]));
    let mut mac = CarMac::new(cfg);
    for (i, chunk) in data.chunks(7).enumerate() {
        let now = i as u64 * 1_000;
        mac.push_rx(now, chunk);
        mac.poll(now);
        while let Some(ev) = mac.next_event() {
            if let radio_mac::Event::Request(inc) = ev {
                let _ = mac.reply(inc.id, 0, &inc.payload);
            }
        }
        let mut buf = [0u8; 256];
        let _ = mac.transmit(&mut buf);
    }
});
