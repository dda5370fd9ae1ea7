//! Feeds arbitrary bytes to the radio deframer, to the raw frame parser, to a car endpoint
//! without a session, to one that joined a ground station's session (so commands, heartbeats
//! and session openings are verified against it) and to that ground station (Hellos). Every
//! frame that parses is emitted again and must parse to the same value, byte for byte; no
//! endpoint may panic whatever arrives.
#![no_main]

use libfuzzer_sys::fuzz_target;
use radio_mac::wire::{encode_frame, Frame, MAX_RAW};
use radio_mac::{CarConfig, CarId, CarMac, Deframer, GroundConfig, GroundStation, Key};

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
    // Whole endpoints, with a key so authenticated frames are checked.
    let Some(id) = CarId::new(5) else { return };
    let key = Key::new([0x42; 16]);
    let mut cfg = CarConfig::new(id);
    cfg.key = Some(key.clone());
    let mut fresh = CarMac::new(cfg.clone());
    // A car in session with a ground station: Hello and session opening exchanged first.
    let mut joined = CarMac::new(cfg);
    let mut ground = GroundStation::new(GroundConfig::new(key, 1));
    let mut buf = [0u8; 512];
    for now in [0u64, 60_000] {
        joined.poll(now);
        let n = joined.transmit(&mut buf);
        ground.push_rx(now, &buf[..n]);
        let n = ground.transmit(&mut buf);
        joined.push_rx(now, &buf[..n]);
    }
    assert!(
        joined.session().is_some(),
        "the car joins the ground station's session"
    );
    for (i, chunk) in data.chunks(7).enumerate() {
        let now = 100_000 + i as u64 * 1_000;
        for mac in [&mut fresh, &mut joined] {
            mac.push_rx(now, chunk);
            mac.poll(now);
            while let Some(ev) = mac.next_event() {
                if let radio_mac::Event::Request(inc) = ev {
                    let _ = mac.reply(inc.id, 0, &inc.payload);
                }
            }
            let _ = mac.transmit(&mut buf);
        }
        ground.push_rx(now, chunk);
        ground.poll(now);
        while ground.next_event().is_some() {}
        let _ = ground.transmit(&mut buf);
    }
});
