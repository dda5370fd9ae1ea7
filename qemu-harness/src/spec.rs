//! Socket addresses given on a command line (`unix:PATH` or `tcp:HOST:PORT`) and the
//! way each UART of the emulated board is attached to the host.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// A stream socket on the host: a Unix-domain socket path or a TCP endpoint.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum SocketSpec {
    /// `unix:PATH`
    Unix(PathBuf),
    /// `tcp:HOST:PORT`; an IPv6 host may be written in brackets (`tcp:[::1]:5555`).
    Tcp {
        /// Host name or address, without brackets.
        host: String,
        /// TCP port.
        port: u16,
    },
}

/// Why a socket specification could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SocketSpecError {
    /// The text has no `unix:` or `tcp:` prefix.
    #[error("socket address needs a scheme: unix:PATH or tcp:HOST:PORT")]
    MissingScheme,
    /// The prefix before the first `:` is neither `unix` nor `tcp`.
    #[error("unknown socket scheme `{0}` (expected unix or tcp)")]
    UnknownScheme(String),
    /// `unix:` with nothing after it.
    #[error("unix socket path is empty")]
    EmptyPath,
    /// `tcp:` with no host before the port.
    #[error("tcp socket host is empty")]
    EmptyHost,
    /// `tcp:HOST` with no `:PORT`.
    #[error("tcp socket address has no port")]
    MissingPort,
    /// The port is not a number in 1..=65535.
    #[error("tcp port `{0}` is not a number in 1..=65535")]
    InvalidPort(String),
}

impl FromStr for SocketSpec {
    type Err = SocketSpecError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (scheme, rest) = s.split_once(':').ok_or(SocketSpecError::MissingScheme)?;
        match scheme {
            "unix" => {
                if rest.is_empty() {
                    Err(SocketSpecError::EmptyPath)
                } else {
                    Ok(SocketSpec::Unix(PathBuf::from(rest)))
                }
            }
            "tcp" => {
                let (host, port) = rest.rsplit_once(':').ok_or(SocketSpecError::MissingPort)?;
                let host = host
                    .strip_prefix('[')
                    .and_then(|h| h.strip_suffix(']'))
                    .unwrap_or(host);
                if host.is_empty() {
                    return Err(SocketSpecError::EmptyHost);
                }
                let port = match port.parse::<u16>() {
                    Ok(p) if p != 0 => p,
                    _ => return Err(SocketSpecError::InvalidPort(port.to_owned())),
                };
                Ok(SocketSpec::Tcp {
                    host: host.to_owned(),
                    port,
                })
            }
            other => Err(SocketSpecError::UnknownScheme(other.to_owned())),
        }
    }
}

impl fmt::Display for SocketSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SocketSpec::Unix(path) => write!(f, "unix:{}", path.display()),
            SocketSpec::Tcp { host, port } if host.contains(':') => {
                write!(f, "tcp:[{host}]:{port}")
            }
            SocketSpec::Tcp { host, port } => write!(f, "tcp:{host}:{port}"),
        }
    }
}

/// How one UART of the emulated board reaches the host.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum UartAttach {
    /// QEMU listens on a socket in the harness's private directory and the harness
    /// connects to it, giving the caller a [`Uart`](crate::Uart) handle. QEMU waits for
    /// that connection before the firmware starts, so no byte is lost.
    #[default]
    Harness,
    /// QEMU connects as a client to a socket someone else is serving (an emulated LBC).
    Connect(SocketSpec),
    /// QEMU serves the socket for an outside peer and boots without waiting for it.
    Listen(SocketSpec),
    /// Nothing is attached; the firmware's output on this UART is discarded.
    Null,
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn parses_unix_and_tcp() {
        assert_eq!(
            "unix:/tmp/lbc.sock".parse(),
            Ok(SocketSpec::Unix("/tmp/lbc.sock".into()))
        );
        assert_eq!(
            "unix:rel/a:b".parse(),
            Ok(SocketSpec::Unix("rel/a:b".into()))
        );
        assert_eq!(
            "tcp:127.0.0.1:5555".parse(),
            Ok(SocketSpec::Tcp {
                host: "127.0.0.1".into(),
                port: 5555
            })
        );
        assert_eq!(
            "tcp:[::1]:80".parse(),
            Ok(SocketSpec::Tcp {
                host: "::1".into(),
                port: 80
            })
        );
    }

    #[test]
    fn rejects_bad_specs_with_reasons() {
        let cases: [(&str, SocketSpecError); 8] = [
            ("/tmp/x.sock", SocketSpecError::MissingScheme),
            (
                "udp:1.2.3.4:5",
                SocketSpecError::UnknownScheme("udp".into()),
            ),
            ("unix:", SocketSpecError::EmptyPath),
            ("tcp:localhost", SocketSpecError::MissingPort),
            ("tcp::5555", SocketSpecError::EmptyHost),
            ("tcp:[]:5555", SocketSpecError::EmptyHost),
            ("tcp:localhost:0", SocketSpecError::InvalidPort("0".into())),
            (
                "tcp:localhost:70000",
                SocketSpecError::InvalidPort("70000".into()),
            ),
        ];
        for (text, err) in cases {
            assert_eq!(text.parse::<SocketSpec>(), Err(err), "{text}");
        }
    }

    fn spec_strategy() -> impl Strategy<Value = SocketSpec> {
        prop_oneof![
            "[a-zA-Z0-9_./:,-]{1,40}".prop_map(|p| SocketSpec::Unix(p.into())),
            ("[a-z0-9.-]{1,20}", 1u16..).prop_map(|(host, port)| SocketSpec::Tcp { host, port }),
            ("[0-9a-f:]{2,20}", 1u16..)
                .prop_filter("ipv6-like", |(h, _)| h.contains(':'))
                .prop_map(|(host, port)| SocketSpec::Tcp { host, port }),
        ]
    }

    proptest! {
        #[test]
        fn display_then_parse_round_trips(spec in spec_strategy()) {
            let text = spec.to_string();
            prop_assert_eq!(text.parse::<SocketSpec>(), Ok(spec));
        }

        #[test]
        fn parse_never_panics(text in "\\PC{0,60}") {
            let _ = text.parse::<SocketSpec>();
        }
    }
}
