//! The testbed's 128-bit command key: from `--key HEX32`, the `ALMC_RADIO_KEY` environment
//! variable, or the documented testbed default, in that order.

use radio_mac::Key;
use std::fmt;

/// Environment variable holding the key as 32 hex digits.
pub const KEY_ENV: &str = "ALMC_RADIO_KEY";

/// The testbed default key, the ASCII text `ALMC-testbed-key` (the firmware's default too).
pub const DEFAULT_KEY: [u8; 16] = *b"ALMC-testbed-key";

/// Where the key in use came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeySource {
    /// `--key`.
    Flag,
    /// [`KEY_ENV`].
    Env,
    /// [`DEFAULT_KEY`].
    Default,
}

/// Why a key could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KeyError {
    /// Not 32 hex digits.
    BadLength {
        /// Digits given.
        digits: usize,
    },
    /// A character that is not a hex digit.
    NotHex {
        /// Its position (0-based).
        position: usize,
    },
    /// The environment variable is not valid text.
    EnvNotUnicode,
}

impl fmt::Display for KeyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadLength { digits } => {
                write!(f, "a radio key is 32 hex digits, got {digits}")
            }
            Self::NotHex { position } => {
                write!(
                    f,
                    "the radio key has a non-hex character at position {position}"
                )
            }
            Self::EnvNotUnicode => write!(f, "{KEY_ENV} is not valid text"),
        }
    }
}

impl std::error::Error for KeyError {}

/// Parse 32 hex digits (an optional `0x` prefix is allowed).
pub fn parse_key(text: &str) -> Result<Key, KeyError> {
    let digits = text.trim();
    let digits = digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
        .unwrap_or(digits);
    if let Some(position) = digits.chars().position(|c| !c.is_ascii_hexdigit()) {
        return Err(KeyError::NotHex { position });
    }
    if digits.len() != 32 {
        return Err(KeyError::BadLength {
            digits: digits.len(),
        });
    }
    let mut bytes = [0u8; 16];
    for (i, b) in bytes.iter_mut().enumerate() {
        let pair = digits.get(2 * i..2 * i + 2).unwrap_or("00");
        *b = u8::from_str_radix(pair, 16).map_err(|_| KeyError::NotHex { position: 2 * i })?;
    }
    Ok(Key::new(bytes))
}

/// The key from `flag`, else [`KEY_ENV`], else [`DEFAULT_KEY`].
pub fn resolve_key(flag: Option<&str>) -> Result<(Key, KeySource), KeyError> {
    if let Some(f) = flag {
        return parse_key(f).map(|k| (k, KeySource::Flag));
    }
    match std::env::var(KEY_ENV) {
        Ok(v) => parse_key(&v).map(|k| (k, KeySource::Env)),
        Err(std::env::VarError::NotUnicode(_)) => Err(KeyError::EnvNotUnicode),
        Err(std::env::VarError::NotPresent) => Ok((Key::new(DEFAULT_KEY), KeySource::Default)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_key_in_hex() {
        let k = parse_key("414c4d432d746573746265642d6b6579").unwrap();
        assert_eq!(k, Key::new(DEFAULT_KEY));
        assert_eq!(parse_key("0x414C4D432D746573746265642D6B6579"), Ok(k));
    }

    #[test]
    fn bad_keys() {
        assert_eq!(parse_key("abcd"), Err(KeyError::BadLength { digits: 4 }));
        assert_eq!(
            parse_key("414c4d432d746573746265642d6b65zz"),
            Err(KeyError::NotHex { position: 30 })
        );
        assert_eq!(parse_key("é"), Err(KeyError::NotHex { position: 0 }));
        assert_eq!(
            resolve_key(Some("00112233445566778899aabbccddeeff")).map(|(_, s)| s),
            Ok(KeySource::Flag)
        );
    }

    proptest::proptest! {
        #[test]
        fn any_16_bytes_round_trip(bytes in proptest::array::uniform16(0u8..)) {
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            proptest::prop_assert_eq!(parse_key(&hex), Ok(Key::new(bytes)));
        }

        #[test]
        fn never_panics(s in "\\PC{0,40}") {
            let _ = parse_key(&s);
        }
    }
}
