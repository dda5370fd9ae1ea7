//! Byte transports between the ground station and its radio: a Unix socket or a TCP port
//! (the simulated hub, or a QEMU chardev), or a real serial radio module.
//!
//! Every transport reads with a short timeout so that one thread can both receive and run
//! the protocol timers.

use std::fmt;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::str::FromStr;
use std::time::Duration;

/// Baud rate of the radio module's UART (seed 1.5.2): 115200 8N1.
pub const DEFAULT_BAUD: u32 = 115_200;

/// How long one read waits for bytes before the protocol timers run again.
pub const READ_TIMEOUT: Duration = Duration::from_millis(1);

/// Where the ground station's radio is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TransportSpec {
    /// `unix:PATH`: connect to a Unix socket.
    Unix(PathBuf),
    /// `tcp:IP:PORT`: connect to a TCP port.
    Tcp(SocketAddr),
    /// `serial:DEVICE[@BAUD]`: a serial radio module, 8N1.
    Serial {
        /// Device path, e.g. `/dev/ttyUSB0`.
        device: String,
        /// Baud rate.
        baud: u32,
    },
}

/// Why a transport spec was rejected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SpecError {
    /// No `scheme:` prefix.
    MissingScheme {
        /// The spec given.
        spec: String,
    },
    /// A scheme other than `unix`, `tcp` or `serial`.
    UnknownScheme {
        /// The scheme given.
        scheme: String,
    },
    /// Nothing after the scheme.
    EmptyAddress,
    /// Not an `IP:PORT` socket address.
    BadSocketAddr {
        /// The text given.
        value: String,
    },
    /// The baud rate after `@` is not a positive number.
    BadBaud {
        /// The text given.
        value: String,
    },
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::MissingScheme { spec } => write!(
                f,
                "`{spec}` has no scheme (expected unix:PATH, tcp:IP:PORT or serial:DEVICE[@BAUD])"
            ),
            Self::UnknownScheme { scheme } => {
                write!(
                    f,
                    "unknown radio scheme `{scheme}` (expected unix, tcp or serial)"
                )
            }
            Self::EmptyAddress => write!(f, "empty path, address or device"),
            Self::BadSocketAddr { value } => {
                write!(
                    f,
                    "`{value}` is not an IP:PORT address (e.g. 127.0.0.1:7000)"
                )
            }
            Self::BadBaud { value } => write!(f, "`{value}` is not a baud rate"),
        }
    }
}

impl std::error::Error for SpecError {}

impl FromStr for TransportSpec {
    type Err = SpecError;

    fn from_str(s: &str) -> Result<Self, SpecError> {
        let (scheme, rest) = s
            .split_once(':')
            .ok_or_else(|| SpecError::MissingScheme { spec: s.into() })?;
        if rest.is_empty() {
            return Err(SpecError::EmptyAddress);
        }
        match scheme {
            "unix" => Ok(Self::Unix(rest.into())),
            "tcp" => rest
                .parse()
                .map(Self::Tcp)
                .map_err(|_| SpecError::BadSocketAddr { value: rest.into() }),
            "serial" => {
                let (device, baud) = match rest.rsplit_once('@') {
                    Some((d, b)) => {
                        let baud = b
                            .parse::<u32>()
                            .ok()
                            .filter(|b| *b > 0)
                            .ok_or_else(|| SpecError::BadBaud { value: b.into() })?;
                        (d, baud)
                    }
                    None => (rest, DEFAULT_BAUD),
                };
                if device.is_empty() {
                    return Err(SpecError::EmptyAddress);
                }
                Ok(Self::Serial {
                    device: device.into(),
                    baud,
                })
            }
            other => Err(SpecError::UnknownScheme {
                scheme: other.into(),
            }),
        }
    }
}

impl fmt::Display for TransportSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Unix(p) => write!(f, "unix:{}", p.display()),
            Self::Tcp(a) => write!(f, "tcp:{a}"),
            Self::Serial { device, baud } => write!(f, "serial:{device}@{baud}"),
        }
    }
}

/// The transport could not be opened.
#[derive(Debug)]
pub enum OpenError {
    /// Socket connect or setup failed.
    Io {
        /// What was opened.
        spec: TransportSpec,
        /// The cause.
        source: io::Error,
    },
    /// The serial device could not be opened or configured.
    Serial {
        /// What was opened.
        spec: TransportSpec,
        /// The cause.
        source: serialport::Error,
    },
}

impl fmt::Display for OpenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io { spec, source } => write!(f, "cannot open {spec}: {source}"),
            Self::Serial { spec, source } => write!(f, "cannot open {spec}: {source}"),
        }
    }
}

impl std::error::Error for OpenError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            Self::Serial { source, .. } => Some(source),
        }
    }
}

/// An open byte stream to the radio.
pub trait Port: Read + Write + Send {}
impl<T: Read + Write + Send> Port for T {}

/// Open the transport; reads time out after [`READ_TIMEOUT`].
pub fn open(spec: &TransportSpec) -> Result<Box<dyn Port>, OpenError> {
    let io_err = |source| OpenError::Io {
        spec: spec.clone(),
        source,
    };
    let write_timeout = Some(Duration::from_secs(1));
    match spec {
        TransportSpec::Unix(path) => {
            let s = UnixStream::connect(path).map_err(io_err)?;
            s.set_read_timeout(Some(READ_TIMEOUT)).map_err(io_err)?;
            s.set_write_timeout(write_timeout).map_err(io_err)?;
            Ok(Box::new(s))
        }
        TransportSpec::Tcp(addr) => {
            let s = TcpStream::connect_timeout(addr, Duration::from_secs(2)).map_err(io_err)?;
            s.set_nodelay(true).map_err(io_err)?;
            s.set_read_timeout(Some(READ_TIMEOUT)).map_err(io_err)?;
            s.set_write_timeout(write_timeout).map_err(io_err)?;
            Ok(Box::new(s))
        }
        TransportSpec::Serial { device, baud } => {
            let port = serialport::new(device, *baud)
                .data_bits(serialport::DataBits::Eight)
                .parity(serialport::Parity::None)
                .stop_bits(serialport::StopBits::One)
                .flow_control(serialport::FlowControl::None)
                .timeout(READ_TIMEOUT)
                .open()
                .map_err(|source| OpenError::Serial {
                    spec: spec.clone(),
                    source,
                })?;
            Ok(Box::new(port))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse() {
        assert_eq!(
            "unix:/tmp/r.sock".parse(),
            Ok(TransportSpec::Unix("/tmp/r.sock".into()))
        );
        assert_eq!(
            "tcp:127.0.0.1:7000".parse(),
            Ok(TransportSpec::Tcp("127.0.0.1:7000".parse().unwrap()))
        );
        assert_eq!(
            "serial:/dev/ttyUSB0".parse(),
            Ok(TransportSpec::Serial {
                device: "/dev/ttyUSB0".into(),
                baud: 115_200
            })
        );
        assert_eq!(
            "serial:/dev/ttyS1@57600".parse(),
            Ok(TransportSpec::Serial {
                device: "/dev/ttyS1".into(),
                baud: 57_600
            })
        );
    }

    #[test]
    fn bad_specs_are_typed_errors() {
        let e = |s: &str| s.parse::<TransportSpec>().unwrap_err();
        assert_eq!(
            e("/dev/ttyUSB0"),
            SpecError::MissingScheme {
                spec: "/dev/ttyUSB0".into()
            }
        );
        assert_eq!(
            e("udp:1.2.3.4:5"),
            SpecError::UnknownScheme {
                scheme: "udp".into()
            }
        );
        assert_eq!(e("unix:"), SpecError::EmptyAddress);
        assert_eq!(e("serial:@9600"), SpecError::EmptyAddress);
        assert_eq!(
            e("tcp:localhost:1"),
            SpecError::BadSocketAddr {
                value: "localhost:1".into()
            }
        );
        assert_eq!(
            e("serial:/dev/x@fast"),
            SpecError::BadBaud {
                value: "fast".into()
            }
        );
        assert_eq!(
            e("serial:/dev/x@0"),
            SpecError::BadBaud { value: "0".into() }
        );
    }

    #[test]
    fn missing_devices_are_open_errors() {
        let spec: TransportSpec = "serial:/nonexistent/tty".parse().unwrap();
        assert!(matches!(open(&spec), Err(OpenError::Serial { .. })));
        let spec: TransportSpec = "unix:/nonexistent/radio.sock".parse().unwrap();
        assert!(matches!(open(&spec), Err(OpenError::Io { .. })));
    }

    proptest::proptest! {
        /// Whatever the text, parsing returns a value or an error; a parsed spec prints back
        /// to a spec that parses to the same value.
        #[test]
        fn parse_never_panics_and_display_round_trips(s in "\\PC{0,40}") {
            if let Ok(spec) = s.parse::<TransportSpec>() {
                proptest::prop_assert_eq!(spec.to_string().parse::<TransportSpec>(), Ok(spec));
            }
        }
    }
}
