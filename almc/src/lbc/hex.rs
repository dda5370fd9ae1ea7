//! Parsing of byte lists (`e8 68 ff`, `0xE8,0x68,0xFF`, `e868ff`) and integers.

use std::fmt;

/// Why a byte list or number could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InputError {
    /// No bytes were given.
    NoBytes,
    /// A token is not hexadecimal.
    NotHex { token: String },
    /// A run of hex digits has an odd length, so it does not split into bytes.
    OddLength { token: String },
    /// A number could not be parsed.
    NotANumber { text: String },
}

impl fmt::Display for InputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            InputError::NoBytes => write!(f, "no bytes given"),
            InputError::NotHex { token } => write!(f, "`{token}` is not a hex byte"),
            InputError::OddLength { token } => {
                write!(f, "`{token}` has an odd number of hex digits")
            }
            InputError::NotANumber { text } => {
                write!(f, "`{text}` is not a number (decimal, 0x hex or 0b binary)")
            }
        }
    }
}

impl std::error::Error for InputError {}

fn hex_digits(token: &str) -> Result<Vec<u8>, InputError> {
    let digits = token
        .strip_prefix("0x")
        .or_else(|| token.strip_prefix("0X"))
        .unwrap_or(token);
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(InputError::NotHex {
            token: token.to_owned(),
        });
    }
    if digits.len() <= 2 {
        return u8::from_str_radix(digits, 16)
            .map(|b| vec![b])
            .map_err(|_| InputError::NotHex {
                token: token.to_owned(),
            });
    }
    if !digits.len().is_multiple_of(2) {
        return Err(InputError::OddLength {
            token: token.to_owned(),
        });
    }
    digits
        .as_bytes()
        .chunks(2)
        .map(|pair| {
            std::str::from_utf8(pair)
                .ok()
                .and_then(|s| u8::from_str_radix(s, 16).ok())
                .ok_or_else(|| InputError::NotHex {
                    token: token.to_owned(),
                })
        })
        .collect()
}

/// Reads bytes from arguments; tokens are separated by spaces or commas.
pub fn parse_bytes<S: AsRef<str>>(args: &[S]) -> Result<Vec<u8>, InputError> {
    let mut out = Vec::new();
    for arg in args {
        for token in arg
            .as_ref()
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
        {
            out.extend(hex_digits(token)?);
        }
    }
    if out.is_empty() {
        return Err(InputError::NoBytes);
    }
    Ok(out)
}

/// Reads a signed integer: decimal, `0x` hex or `0b` binary, optionally negative.
pub fn parse_int(text: &str) -> Result<i64, InputError> {
    let err = || InputError::NotANumber {
        text: text.to_owned(),
    };
    let (negative, body) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text.strip_prefix('+').unwrap_or(text)),
    };
    let body = body.replace('_', "");
    let (digits, radix) =
        if let Some(h) = body.strip_prefix("0x").or_else(|| body.strip_prefix("0X")) {
            (h, 16)
        } else if let Some(b) = body.strip_prefix("0b").or_else(|| body.strip_prefix("0B")) {
            (b, 2)
        } else {
            (body.as_str(), 10)
        };
    // One sign at most, in front: the integer parser would accept another one here.
    if digits.starts_with(['+', '-']) {
        return Err(err());
    }
    let value = i64::from_str_radix(digits, radix).map_err(|_| err())?;
    if negative {
        value.checked_neg().ok_or_else(err)
    } else {
        Ok(value)
    }
}

/// Bytes as lower-case hex separated by spaces.
pub fn to_hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_the_three_spellings() {
        let want = vec![0xE8, 0x68, 0xFF];
        assert_eq!(parse_bytes(&["e8", "68", "ff"]).unwrap(), want);
        assert_eq!(parse_bytes(&["0xE8,0x68,0xFF"]).unwrap(), want);
        assert_eq!(parse_bytes(&["e868ff"]).unwrap(), want);
        assert_eq!(parse_bytes(&["0xE8, 0x68", "ff"]).unwrap(), want);
    }

    #[test]
    fn rejects_bad_input() {
        assert_eq!(
            parse_bytes(&["e8", "zz"]),
            Err(InputError::NotHex { token: "zz".into() })
        );
        assert_eq!(
            parse_bytes(&["e86"]),
            Err(InputError::OddLength {
                token: "e86".into()
            })
        );
        assert_eq!(parse_bytes(&[","]), Err(InputError::NoBytes));
        assert_eq!(
            parse_bytes(&["0x"]),
            Err(InputError::NotHex { token: "0x".into() })
        );
    }

    #[test]
    fn integers() {
        assert_eq!(parse_int("320"), Ok(320));
        assert_eq!(parse_int("-523"), Ok(-523));
        assert_eq!(parse_int("0x35"), Ok(0x35));
        assert_eq!(parse_int("0b101"), Ok(5));
        assert!(parse_int("x1").is_err());
        assert!(parse_int("-").is_err());
    }

    #[test]
    fn a_second_sign_is_refused_and_cannot_overflow() {
        // These used to parse the body as i64::MIN and then negate it.
        for text in ["--9223372036854775808", "-0x-8000000000000000", "-0b-1"] {
            assert_eq!(
                parse_int(text),
                Err(InputError::NotANumber { text: text.into() })
            );
        }
        assert!(parse_int("--5").is_err());
        assert!(parse_int("0x-5").is_err());
        assert_eq!(parse_int("+5"), Ok(5));
        assert_eq!(parse_int("-9223372036854775807"), Ok(-i64::MAX));
    }
}
