//! Feeds arbitrary bytes to the LBC-link deframer and both decoders; every
//! decoded message is emitted again and must decode to the same value.
#![no_main]

use lbc_link::client::{Client, Instant};
use lbc_link::lbc::CommandParser;
use lbc_link::{Command, Deframer, LbcMessage, StreamFormat, MAX_FRAME_LEN};
use libfuzzer_sys::fuzz_target;

fn redecode_command(cmd: &Command) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = cmd.emit(&mut buf).expect("commands always fit");
    let mut d = Deframer::new();
    let mut seen = 0;
    for &b in &buf[..n] {
        if let Some(r) = d.push(b) {
            let m = r.expect("emitted command deframes");
            assert_eq!(Command::decode(m.header, m.data).as_ref(), Ok(cmd));
            seen += 1;
        }
    }
    assert_eq!(seen, 1);
}

fn redecode_lbc(msg: &LbcMessage) {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = msg.emit(&mut buf).expect("decoded messages fit");
    let mut d = Deframer::new();
    let mut seen = 0;
    for &b in &buf[..n] {
        if let Some(r) = d.push(b) {
            let m = r.expect("emitted message deframes");
            assert_eq!(LbcMessage::decode(m.header, m.data).as_ref(), Ok(msg));
            seen += 1;
        }
    }
    assert_eq!(seen, 1);
}

fuzz_target!(|data: &[u8]| {
    // The first four bytes choose the streaming format (always a valid one).
    let mut word = [0u8; 4];
    for (w, d) in word.iter_mut().zip(data) {
        *w = *d;
    }
    let format = StreamFormat::new(u32::from_le_bytes(word) & StreamFormat::ALL.bits())
        .unwrap_or(StreamFormat::ALL);
    let mut deframer = Deframer::new();
    for &byte in data {
        if let Some(Ok(msg)) = deframer.push(byte) {
            if let Ok(cmd) = Command::decode(msg.header, msg.data) {
                redecode_command(&cmd);
            }
            if let Ok(reply) = LbcMessage::decode(msg.header, msg.data) {
                if let LbcMessage::Stream(s) = &reply {
                    if let Ok(sample) = s.decode(format) {
                        let mut buf = [0u8; MAX_FRAME_LEN];
                        let n = sample.emit(format, &mut buf).expect("full sample");
                        assert_eq!(
                            LbcMessage::decode(buf[0], &buf[1..n - 2])
                                .ok()
                                .and_then(|m| match m {
                                    LbcMessage::Stream(s) => s.decode(format).ok(),
                                    _ => None,
                                }),
                            Some(sample)
                        );
                    }
                }
                redecode_lbc(&reply);
            }
        }
    }

    // The same bytes through both state machines: must not panic.
    let mut parser = CommandParser::new();
    for &byte in data {
        let _ = parser.push(byte);
    }
    let mut client = Client::default();
    let _ = client.send(Instant::from_millis(0), Command::ReadSf);
    client.poll(Instant::from_millis(1), data, |_| {});
    client.poll(Instant::from_millis(10_000), &[], |_| {});
});
