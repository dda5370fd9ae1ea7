//! Bytes to messages for the recording: radio frames (`radio_mac::Deframer`, one per node and
//! direction), LBC messages (`lbc_link::Deframer` and its message types, one per car and
//! direction) and firmware log lines (`qemu_harness::LineDecoder`). Each message is stamped
//! with the world time of the byte that completed it. Bad bytes become `error` messages;
//! nothing here panics on them.

use lbc_link::{Command, LbcMessage, StreamFormat, StreamSample};
use qemu_harness::{LineDecoder, LogLine};
use radio_mac::{Address, CarState, Frame};
use serde_json::{json, Value};
use std::fmt::Write;
use std::time::Instant;

/// World time, ns.
type Nanos = u64;

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 3);
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{b:02x}");
    }
    s
}

fn seconds(t: Nanos) -> f64 {
    t as f64 / 1e9
}

fn address(a: Address) -> String {
    match a {
        Address::Ground => "ground".into(),
        Address::Car(id) => format!("car{}", id.get()),
        Address::Broadcast => "broadcast".into(),
    }
}

/// The car whose state a frame carries, if it is a state broadcast.
pub fn state_of(frame: &Frame) -> Option<(u8, CarState)> {
    match frame {
        Frame::State { src, state, .. } => Some((src.get(), *state)),
        _ => None,
    }
}

/// A radio frame's fields as JSON (kind, addresses, and what it carries).
fn frame_json(frame: &Frame) -> Value {
    match frame {
        Frame::State { src, seq, state } => json!({
            "kind": "state", "src": format!("car{}", src.get()), "dst": "broadcast",
            "seq": seq, "x_units": state.x, "y_units": state.y,
            "heading_mrad": state.heading_mrad, "velocity_mm_s": state.velocity_mm_s,
            "role": format!("{:?}", state.mode.role), "phase": state.mode.phase,
        }),
        Frame::Heartbeat { src, beat } => json!({
            "kind": "heartbeat", "src": address(*src), "dst": "broadcast",
            "role": format!("{:?}", beat.mode.role), "phase": beat.mode.phase,
            "neighbours": beat.neighbours, "uptime_s": beat.uptime_s,
        }),
        Frame::Request {
            src,
            dst,
            seq,
            tag,
            payload,
        } => json!({
            "kind": "request", "src": address(*src), "dst": address(*dst), "seq": seq,
            "tag": tag, "payload": hex(payload),
        }),
        Frame::Reply {
            src,
            dst,
            seq,
            tag,
            payload,
        } => json!({
            "kind": "reply", "src": address(*src), "dst": address(*dst), "seq": seq,
            "tag": tag, "payload": hex(payload),
        }),
        Frame::Group {
            src,
            dst,
            group,
            gseq,
            msg,
        } => json!({
            "kind": "group", "src": address(*src), "dst": address(*dst), "group": group,
            "gseq": gseq, "msg": format!("{msg:?}"),
        }),
        Frame::AuthCommand {
            dst,
            counter,
            tag,
            payload,
            ..
        } => json!({
            "kind": "auth_command", "src": "ground", "dst": address(*dst),
            "counter": counter, "tag": tag, "payload": hex(payload),
        }),
        other => json!({
            "kind": snake_case(&format!("{:?}", other.kind())),
            "src": address(other.src()),
            "detail": format!("{other:?}"),
        }),
    }
}

/// `GroundBeat` as `ground_beat`.
fn snake_case(camel: &str) -> String {
    let mut out = String::new();
    for (i, c) in camel.chars().enumerate() {
        if c.is_ascii_uppercase() {
            if i > 0 {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

/// One direction of one radio node's UART.
#[derive(Debug, Default)]
pub struct RadioStream {
    deframer: radio_mac::Deframer,
    bytes: Vec<u8>,
}

impl RadioStream {
    /// Feeds one byte at world time `t`; a frame (or a bad one) when a delimiter ends it:
    /// its JSON (with `t_s`, `node`, `dir`, `bytes`), and the frame itself when valid.
    pub fn push(
        &mut self,
        t: Nanos,
        b: u8,
        node: &str,
        dir: &str,
    ) -> Option<(Value, Option<Frame>)> {
        if b != 0 {
            // Bytes beyond the longest frame are garbage the deframer skips; keep the hex short.
            if self.bytes.len() < 2 * radio_mac::wire::MAX_ENCODED {
                self.bytes.push(b);
            }
        }
        let result = self.deframer.push(b);
        if b == 0 && result.is_none() {
            self.bytes.clear();
        }
        let result = result?;
        let mut v = match &result {
            Ok(f) => frame_json(f),
            Err(e) => json!({ "kind": "error", "error": format!("{e:?}") }),
        };
        v["t_s"] = json!(seconds(t));
        v["node"] = json!(node);
        v["dir"] = json!(dir);
        v["bytes"] = json!(hex(&self.bytes));
        self.bytes.clear();
        Some((v, result.ok()))
    }
}

/// One direction of one car's LBC link.
#[derive(Debug, Default)]
pub struct LbcStream {
    deframer: lbc_link::Deframer,
    bytes: Vec<u8>,
}

fn serde_value<T: serde::Serialize>(v: &T) -> Value {
    serde_json::to_value(v).unwrap_or(Value::Null)
}

impl LbcStream {
    /// Feeds one byte at world time `t`; a message (or a bad one) when one ends, as JSON.
    /// `format` is the stream format the car last set (updated by `UPD_SF` commands seen on
    /// the `to_lbc` stream), used to decode `STREAM` messages.
    pub fn push(
        &mut self,
        t: Nanos,
        b: u8,
        to_lbc: bool,
        format: &mut Option<StreamFormat>,
    ) -> Option<Value> {
        if (0x80..0xFF).contains(&b) {
            self.bytes.clear();
        }
        if self.bytes.len() <= lbc_link::MAX_FRAME_LEN {
            self.bytes.push(b);
        }
        let result = self.deframer.push(b)?.map(|m| (m.header, m.data.to_vec()));
        let mut v = match result {
            Err(e) => json!({ "error": format!("{e:?}") }),
            Ok((header, data)) if to_lbc => match Command::decode(header, &data) {
                Ok(c) => {
                    if let Command::UpdSf(f) = c {
                        *format = Some(f);
                    }
                    json!({ "symbol": c.kind().symbol(), "message": serde_value(&c) })
                }
                Err(e) => json!({ "error": format!("{e:?}") }),
            },
            Ok((header, data)) => match LbcMessage::decode(header, &data) {
                Ok(m) => {
                    let mut v = json!({ "symbol": symbol(&m), "message": serde_value(&m) });
                    if let (LbcMessage::Stream(d), Some(f)) = (&m, *format) {
                        match StreamSample::decode(f, &d.0) {
                            Ok(s) => v["sample"] = serde_value(&s),
                            Err(e) => v["error"] = json!(format!("{e:?}")),
                        }
                    }
                    v
                }
                Err(e) => json!({ "error": format!("{e:?}") }),
            },
        };
        v["t_s"] = json!(seconds(t));
        v["dir"] = json!(if to_lbc { "to_lbc" } else { "from_lbc" });
        v["bytes"] = json!(hex(&self.bytes));
        self.bytes.clear();
        Some(v)
    }
}

fn symbol(m: &LbcMessage) -> String {
    match m {
        LbcMessage::Reply(r) => r.kind().symbol().into(),
        LbcMessage::Error(k) => format!("{}_ERR", k.symbol()),
        LbcMessage::UnknownCommand(_) => "UNKCMD".into(),
        LbcMessage::ChecksumError => "CSER".into(),
        LbcMessage::Stream(_) => "STREAM".into(),
    }
}

/// One car's console: its log bytes become lines, each stamped with the world time of the
/// byte that ended its frame (a defmt frame's 0x00, a text line's newline).
pub struct ConsoleStream<'f> {
    decoder: LineDecoder<'f>,
    pending: Vec<u8>,
    lines: Vec<LogLine>,
}

impl std::fmt::Debug for ConsoleStream<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ConsoleStream")
            .field("pending", &self.pending.len())
            .finish_non_exhaustive()
    }
}

impl<'f> ConsoleStream<'f> {
    /// A console decoded with `format`.
    pub fn new(format: &'f qemu_harness::LogFormat) -> Self {
        ConsoleStream {
            decoder: LineDecoder::new(format),
            pending: Vec::new(),
            lines: Vec::new(),
        }
    }

    /// Feeds console bytes with their world times; calls `out` with every line completed.
    pub fn push(&mut self, bytes: &[(Nanos, u8)], out: &mut dyn FnMut(Nanos, &LogLine)) {
        let Some(&(last, _)) = bytes.last() else {
            return;
        };
        let mut emit = |dec: &mut LineDecoder<'f>, pending: &mut Vec<u8>, t: Nanos| {
            self.lines.clear();
            dec.push(pending, Instant::now(), &mut self.lines);
            pending.clear();
            for l in &self.lines {
                out(t, l);
            }
        };
        for &(t, b) in bytes {
            self.pending.push(b);
            if b == 0 || b == b'\n' {
                emit(&mut self.decoder, &mut self.pending, t);
            }
        }
        if !self.pending.is_empty() {
            emit(&mut self.decoder, &mut self.pending, last);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use radio_mac::{CarId, Mode};

    #[test]
    fn a_state_frame_is_decoded_and_garbage_is_an_error() {
        let frame = Frame::State {
            src: CarId::new(3).unwrap(),
            seq: 9,
            state: CarState {
                x: 100,
                y: 200,
                heading_mrad: 1571,
                velocity_mm_s: -20,
                mode: Mode::default(),
            },
        };
        let wire = radio_mac::wire::encode_frame(&frame).unwrap();
        let mut s = RadioStream::default();
        let mut got = Vec::new();
        for (i, &b) in wire.iter().enumerate() {
            if let Some(r) = s.push(i as u64 * 1000, b, "ground", "received") {
                got.push(r);
            }
        }
        assert_eq!(got.len(), 1);
        let (v, f) = &got[0];
        assert_eq!(v["kind"], "state");
        assert_eq!(v["src"], "car3");
        assert_eq!(v["x_units"], 100);
        assert_eq!(state_of(f.as_ref().unwrap()).unwrap().0, 3);
        let garbage = [0x13, 0x37, 0x42, 0x00];
        let r: Vec<_> = garbage
            .iter()
            .filter_map(|&b| s.push(0, b, "ground", "received"))
            .collect();
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].0["kind"], "error");
        assert!(r[0].1.is_none());
    }

    #[test]
    fn lbc_commands_set_the_stream_format_and_bad_bytes_are_errors() {
        let mut format = None;
        let mut s = LbcStream::default();
        // READ_ID: e8 68 ff.
        let got: Vec<Value> = [0xE8, 0x68, 0xFF]
            .iter()
            .filter_map(|&b| s.push(5_000, b, true, &mut format))
            .collect();
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0]["symbol"], "READ_ID");
        assert_eq!(got[0]["bytes"], "e8 68 ff");
        assert_eq!(got[0]["dir"], "to_lbc");
        let bad: Vec<Value> = [0xE8, 0x11, 0xFF]
            .iter()
            .filter_map(|&b| s.push(6_000, b, false, &mut format))
            .collect();
        assert!(bad.iter().all(|v| v.get("error").is_some()), "{bad:?}");
    }
}
