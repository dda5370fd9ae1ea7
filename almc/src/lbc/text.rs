//! Human-readable descriptions of protocol values and errors.

use lbc_link::{DecodeError, DeframeError, Field, HeaderClass, RangeError, StreamError};
use serde_json::Value;

/// Range and unit of a field, for error messages.
pub fn field_range(field: Field) -> &'static str {
    match field {
        Field::X => "X must be 0..=640 tracking units (2.5 mm)",
        Field::Y => "Y must be 0..=960 tracking units (2.5 mm)",
        Field::SteeringAngle => "steering must be -523..=523 mrad",
        Field::Velocity => "velocity must be -8192..=8191 mm/s",
        Field::Heading => "heading/yaw must be 0..=6283 mrad",
        Field::VehicleId => "vehicle ID must be 0..=127",
        Field::EepromAddress => "EEPROM address must be 0x00..=0x3F",
        Field::UserRegister => "WRIT_EP address must be a user register 0x20..=0x3F",
        Field::EepromValue => "EEPROM value must be 0..=65535 (16 bits)",
        Field::ParamNumber => "parameter number must be 1..=12",
        Field::ParamValue => {
            "parameter value must be 0..=16383 (unsigned) or -8192..=8191 (servo offset/gain)"
        }
        Field::StreamFormat => {
            "stream format must be 28 bits with no NOT-IN-USE bit (mask 0x002060E0)"
        }
        Field::Pattern => "LED/GPIO pattern must be 7 bits (0x00..=0x7F)",
        Field::Duty => "duty must be 0..=10 tenths",
        Field::Unsigned14 => "value must be 0..=16383",
        Field::Signed14 => "value must be -8192..=8191",
        Field::Signed28 => "value must fit in 28 bits, signed",
        Field::ChipTemperature => "chip temperature must be 0..=127",
        _ => "value out of range",
    }
}

/// A range error as a sentence.
pub fn range_error(e: &RangeError) -> String {
    format!("{} is out of range: {}", e.value, field_range(e.field))
}

fn header_name(header: u8) -> String {
    match HeaderClass::classify(header) {
        Some(HeaderClass::Command(k)) => format!("{k} (0x{header:02x})"),
        Some(HeaderClass::SpecificError(k)) => format!("{k} error (0x{header:02x})"),
        Some(HeaderClass::UnknownCommand) => "UNKCMD (0xbc)".into(),
        Some(HeaderClass::ChecksumError) => "CSER (0xbd)".into(),
        Some(HeaderClass::Stream) => "STREAM (0xfc)".into(),
        _ => format!("0x{header:02x}"),
    }
}

/// A framing error as a sentence.
pub fn deframe_error(e: &DeframeError) -> String {
    match *e {
        DeframeError::Garbage { byte } => format!("data byte 0x{byte:02x} outside any message"),
        DeframeError::StrayTerminator => "terminator 0xff outside any message".into(),
        DeframeError::Truncated { header, received } => format!(
            "message {} cut off by a new header after {received} byte(s)",
            header_name(header)
        ),
        DeframeError::Oversize { header } => format!(
            "message {} longer than {} data bytes",
            header_name(header),
            lbc_link::MAX_DATA_LEN
        ),
        DeframeError::MissingChecksum { header } => {
            format!("message {} has no checksum byte", header_name(header))
        }
        DeframeError::ChecksumMismatch {
            header,
            expected,
            got,
        } => format!(
            "bad checksum in message {}: expected 0x{expected:02x}, got 0x{got:02x}",
            header_name(header)
        ),
    }
}

/// A decode error as a sentence.
pub fn decode_error(e: &DecodeError) -> String {
    match e {
        DecodeError::NotAHeader { byte } => format!("0x{byte:02x} is not a header"),
        DecodeError::Unassigned { header } => {
            format!("header 0x{header:02x} is reserved or not in use")
        }
        DecodeError::WrongClass { class } => format!("unexpected message class {class:?}"),
        DecodeError::Length {
            header,
            expected,
            got,
        } => format!(
            "{} needs {expected} data byte(s), got {got}",
            header_name(*header)
        ),
        DecodeError::Field { header, error } => {
            format!("{}: {}", header_name(*header), range_error(error))
        }
        DecodeError::BadEcho { byte } => {
            format!("UNKCMD echo starts with 0x{byte:02x}, which is not a header")
        }
        DecodeError::BadDataByte { index, byte } => {
            format!("data byte {index} is 0x{byte:02x} (bit 7 set)")
        }
    }
}

/// A STREAM decode error as a sentence.
pub fn stream_error(e: &StreamError) -> String {
    match e {
        StreamError::Length { expected, got } => {
            format!("STREAM data is {got} byte(s) but the format needs {expected}")
        }
        StreamError::Field(r) => format!("STREAM {}", range_error(r)),
        StreamError::UnknownFormat => "no stream format given (use --stream-format)".into(),
    }
}

/// Flattens a JSON value into `key=value` pairs (nested keys joined with dots,
/// absent values left out).
pub fn flatten(prefix: &str, v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Null => {}
        Value::Object(map) => {
            for (k, v) in map {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        Value::Array(items) => {
            for (i, v) in items.iter().enumerate() {
                flatten(&format!("{prefix}[{}]", i + 1), v, out);
            }
        }
        Value::String(s) => out.push(format!("{prefix}={s}")),
        other => out.push(format!("{prefix}={other}")),
    }
}

/// Strips serde's enum tag (`{"MoveXy": {...}}` -> `{...}`).
pub fn untag(v: Value) -> Value {
    match v {
        Value::Object(map) if map.len() == 1 => {
            let (_, inner) = map.into_iter().next().unwrap_or_default();
            inner
        }
        Value::String(_) => Value::Null,
        other => other,
    }
}
