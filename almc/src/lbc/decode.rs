//! `almc lbc decode`: split bytes into messages and describe each one.

use std::process::ExitCode;

use lbc_link::{
    Command, CommandKind, Deframer, GpioPattern, HeaderClass, LbcMessage, LedPattern, Reply,
    StreamFormat, StreamSample, SystemValue,
};
use serde::Serialize;
use serde_json::Value;

use super::hex::{parse_bytes, parse_int, to_hex};
use super::text;
use super::DecodeArgs;

/// What a decoded message is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
enum Role {
    /// A command (the LBC would not send it: acks of this kind carry other data).
    Command,
    /// A positive acknowledgement with data.
    Ack,
    /// A command that its ack repeats byte for byte.
    CommandOrAck,
    /// A command's specific error.
    Error,
    UnknownCommand,
    ChecksumError,
    Stream,
}

/// One entry of the output.
#[derive(Debug, Serialize)]
struct Record {
    /// Offset of the first byte in the input.
    offset: usize,
    /// The bytes of this entry.
    bytes: String,
    #[serde(flatten)]
    body: Body,
}

#[derive(Debug, Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
enum Body {
    Message {
        symbol: String,
        role: Role,
        /// Named fields, flattened.
        fields: Vec<String>,
        /// The typed value.
        value: Value,
    },
    Error {
        message: String,
        detail: Value,
    },
}

fn value_of<T: Serialize>(v: &T) -> Value {
    serde_json::to_value(v).unwrap_or(Value::Null)
}

fn format_fields(format: StreamFormat) -> Vec<String> {
    let names: Vec<&str> = format.variables().map(|v| v.name()).collect();
    vec![
        format!("format=0x{:07x}", format.bits()),
        format!("variables=[{}]", names.join(", ")),
    ]
}

fn scalar_name(kind: CommandKind) -> &'static str {
    match kind {
        CommandKind::ReadId => "id",
        CommandKind::ReadAy => "adjusted_yaw_mrad",
        CommandKind::ReadHd => "heading_mrad",
        CommandKind::ReadRs => "range_adc",
        CommandKind::ReadEp => "address",
        CommandKind::ReadPar => "param",
        _ => "value",
    }
}

fn named_fields(kind: CommandKind, payload: Value) -> Vec<String> {
    let mut out = Vec::new();
    match payload {
        Value::Object(_) | Value::Null => text::flatten("", &payload, &mut out),
        scalar => text::flatten(scalar_name(kind), &scalar, &mut out),
    }
    out
}

fn duty_text(code: u8) -> String {
    match code & 0x0F {
        0 | 11..=15 => "off".into(),
        10 => "on".into(),
        d => format!("duty {d}/10"),
    }
}

fn led_text(p: LedPattern) -> String {
    let rate = p.rate();
    let mode = if rate.is_dim() { "dim" } else { "blink" };
    format!(
        "0x{:02x} ({mode} {} Hz, {})",
        p.bits(),
        rate.hz(),
        duty_text(p.bits())
    )
}

fn gpio_text(p: GpioPattern) -> String {
    format!(
        "0x{:02x} ({} Hz, {})",
        p.bits(),
        p.rate().hz(),
        duty_text(p.bits())
    )
}

fn command_fields(cmd: &Command) -> Vec<String> {
    match cmd {
        Command::UpdSf(f) => format_fields(*f),
        Command::WritLed { green, red } => vec![
            format!("green={}", led_text(*green)),
            format!("red={}", led_text(*red)),
        ],
        Command::WritGpo { gpio0, gpio1 } => vec![
            format!("gpio0={}", gpio_text(*gpio0)),
            format!("gpio1={}", gpio_text(*gpio1)),
        ],
        Command::WritEp { address, value } => vec![
            format!("address=0x{:02x}", address.get()),
            format!("value=0x{value:04x} ({value})"),
        ],
        Command::ReadEp(address) => vec![format!("address=0x{:02x}", address.get())],
        other => named_fields(other.kind(), text::untag(value_of(other))),
    }
}

fn reply_fields(reply: &Reply) -> Vec<String> {
    match reply {
        Reply::Echo(cmd) => command_fields(cmd),
        Reply::ReadSf(f) => format_fields(*f),
        Reply::ReadEpData { address, value } => vec![
            format!("address=0x{:02x}", address.get()),
            format!("value=0x{value:04x} ({value})"),
        ],
        other => named_fields(other.kind(), text::untag(value_of(other))),
    }
}

fn message(symbol: &str, role: Role, fields: Vec<String>, value: Value) -> Body {
    Body::Message {
        symbol: symbol.to_owned(),
        role,
        fields,
        value,
    }
}

fn error(message: String, detail: Value) -> Body {
    Body::Error { message, detail }
}

fn stream_body(data: &lbc_link::StreamData, format: Option<StreamFormat>) -> Body {
    let Some(format) = format else {
        return message(
            "STREAM",
            Role::Stream,
            vec![
                format!("data=[{}]", to_hex(&data.0)),
                "note=pass --stream-format to decode".into(),
            ],
            value_of(data),
        );
    };
    match StreamSample::decode(format, &data.0) {
        Ok(sample) => {
            let mut fields = Vec::new();
            for var in format.variables() {
                match sample.get(var) {
                    Some(SystemValue::User { index, value }) => {
                        fields.push(format!("user{index}={}", value.get()));
                    }
                    Some(v) => {
                        let name = snake_case(&format!("{var:?}"));
                        text::flatten(&name, &text::untag(value_of(&v)), &mut fields);
                    }
                    None => {}
                }
            }
            message("STREAM", Role::Stream, fields, value_of(&sample))
        }
        Err(e) => error(text::stream_error(&e), value_of(&e)),
    }
}

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

fn describe(header: u8, data: &[u8], format: Option<StreamFormat>) -> Body {
    match HeaderClass::classify(header) {
        Some(HeaderClass::Command(kind)) => {
            let cmd = Command::decode(header, data);
            let reply = Reply::decode(kind, data);
            match (cmd, reply) {
                (Ok(c), Ok(Reply::Echo(e))) if c == e => message(
                    kind.symbol(),
                    Role::CommandOrAck,
                    command_fields(&c),
                    value_of(&c),
                ),
                (Ok(c), _) => message(
                    kind.symbol(),
                    Role::Command,
                    command_fields(&c),
                    value_of(&c),
                ),
                (Err(_), Ok(r)) => {
                    message(kind.symbol(), Role::Ack, reply_fields(&r), value_of(&r))
                }
                (Err(ce), Err(re)) => {
                    // Report the reading whose length fits, else the command's.
                    let e = if data.len() == kind.command_len() {
                        ce
                    } else {
                        re
                    };
                    error(text::decode_error(&e), value_of(&e))
                }
            }
        }
        _ => match LbcMessage::decode(header, data) {
            Ok(LbcMessage::Error(kind)) => message(
                &format!("{}_ERR", kind.symbol()),
                Role::Error,
                vec![format!("command={kind}")],
                value_of(&LbcMessage::Error(kind)),
            ),
            Ok(LbcMessage::ChecksumError) => {
                message("CSER", Role::ChecksumError, Vec::new(), Value::Null)
            }
            Ok(LbcMessage::UnknownCommand(echo)) => {
                let fields = match &echo {
                    Some(e) => vec![
                        format!("echo.header=0x{:02x}", e.header),
                        format!("echo.data=[{}]", to_hex(&e.data)),
                    ],
                    None => vec!["echo=none".into()],
                };
                message("UNKCMD", Role::UnknownCommand, fields, value_of(&echo))
            }
            Ok(LbcMessage::Stream(d)) => stream_body(&d, format),
            Ok(LbcMessage::Reply(r)) => {
                message(r.kind().symbol(), Role::Ack, reply_fields(&r), value_of(&r))
            }
            Err(e) => error(text::decode_error(&e), value_of(&e)),
        },
    }
}

fn decode_bytes(bytes: &[u8], format: Option<StreamFormat>) -> Vec<Record> {
    let mut records = Vec::new();
    let mut deframer = Deframer::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        let was_in_message = deframer.in_message();
        let result = deframer.push(b).map(|r| {
            r.map(|m| (m.header, m.data.to_vec()))
                .map_err(|e| (text::deframe_error(&e), value_of(&e)))
        });
        let message_start = if b >= 0x80 && b != 0xFF { i } else { start };
        if let Some(result) = result {
            // A truncation is reported when the next header arrives: the cut
            // message ends just before it.
            let (from, to) = match &result {
                Err(_) if b >= 0x80 && b != 0xFF && was_in_message => (start, i),
                Err(_) if !was_in_message => (i, i + 1),
                _ => (start, i + 1),
            };
            let body = match result {
                Ok((header, data)) => describe(header, &data, format),
                Err((message, detail)) => error(message, detail),
            };
            records.push(Record {
                offset: from,
                bytes: to_hex(&bytes[from..to]),
                body,
            });
        }
        start = message_start;
    }
    if deframer.in_message() {
        records.push(Record {
            offset: start,
            bytes: to_hex(&bytes[start..]),
            body: error(
                "message not terminated at end of input".into(),
                Value::String("Unterminated".into()),
            ),
        });
    }
    records
}

fn parse_format(text: &str) -> Result<StreamFormat, String> {
    let with_prefix = if text.starts_with("0x") || text.starts_with("0X") {
        text.to_owned()
    } else {
        format!("0x{text}")
    };
    let bits = parse_int(&with_prefix).map_err(|e| e.to_string())?;
    let bits = u32::try_from(bits).map_err(|_| format!("stream format {text} is not 28 bits"))?;
    StreamFormat::new(bits).map_err(|e| super::text::range_error(&e))
}

/// Runs `almc lbc decode`.
pub fn run(args: &DecodeArgs) -> ExitCode {
    let bytes = match parse_bytes(&args.bytes) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("almc lbc decode: {e}");
            return ExitCode::from(2);
        }
    };
    let format = match args.stream_format.as_deref().map(parse_format).transpose() {
        Ok(f) => f,
        Err(e) => {
            eprintln!("almc lbc decode: --stream-format: {e}");
            return ExitCode::from(2);
        }
    };
    let records = decode_bytes(&bytes, format);
    let failed = records.iter().any(|r| matches!(r.body, Body::Error { .. }));
    if args.json {
        let doc = serde_json::json!({ "ok": !failed, "messages": records });
        println!("{}", serde_json::to_string_pretty(&doc).unwrap_or_default());
    } else {
        for r in &records {
            match &r.body {
                Body::Message {
                    symbol,
                    role,
                    fields,
                    ..
                } => {
                    let role = match role {
                        Role::Command => "command",
                        Role::Ack => "ack",
                        Role::CommandOrAck => "command (or its ack)",
                        Role::Error => "error",
                        Role::UnknownCommand => "unknown-command report",
                        Role::ChecksumError => "checksum-error report",
                        Role::Stream => "stream",
                    };
                    println!("[{}] {}: {symbol} {role}", r.offset, r.bytes);
                    for f in fields {
                        println!("    {f}");
                    }
                }
                Body::Error { message, .. } => {
                    println!("[{}] {}: ERROR {message}", r.offset, r.bytes);
                }
            }
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn symbols(bytes: &[u8]) -> Vec<String> {
        decode_bytes(bytes, None)
            .into_iter()
            .map(|r| match r.body {
                Body::Message { symbol, .. } => format!("{}@{}", symbol, r.offset),
                Body::Error { .. } => format!("error@{}:{}", r.offset, r.bytes),
            })
            .collect()
    }

    #[test]
    fn offsets_and_spans() {
        assert_eq!(
            symbols(&[0x01, 0xE8, 0x68, 0xFF, 0xE9, 0x01, 0xC0, 0x40, 0xFF, 0xE8]),
            [
                "error@0:01",
                "READ_ID@1",
                "error@4:e9 01",
                "STOP@6",
                "error@9:e8"
            ]
        );
    }

    #[test]
    fn read_id_ack_has_named_field() {
        let r = decode_bytes(&[0xE8, 0x05, 0x6D, 0xFF], None);
        let Body::Message { role, fields, .. } = &r[0].body else {
            panic!("{r:?}")
        };
        assert_eq!(*role, Role::Ack);
        assert_eq!(fields, &["id=5"]);
    }

    #[test]
    fn move_xy_fields() {
        let r = decode_bytes(&[0xC1, 0x02, 0x40, 0x03, 0x60, 0x60, 0xFF], None);
        let Body::Message { role, fields, .. } = &r[0].body else {
            panic!("{r:?}")
        };
        assert_eq!(*role, Role::CommandOrAck);
        assert_eq!(fields, &["x=320", "y=480"]);
    }

    #[test]
    fn stream_format_parsing() {
        assert_eq!(parse_format("3").unwrap().bits(), 3);
        assert!(parse_format("e0").is_err());
        assert!(parse_format("10000000").is_err());
    }
}
