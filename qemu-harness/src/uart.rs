//! Host end of an emulated UART: a Unix stream socket served by QEMU, with bounded
//! reads and writes so a silent firmware turns into an error instead of a hang.

use std::io::{self, Read, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

use crate::Error;

/// Default bound on a single blocking write.
pub const DEFAULT_WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// A connected UART socket. Cloning the handle ([`Uart::try_clone`]) gives a second
/// handle to the same link, so one thread can write while another reads.
#[derive(Debug)]
pub struct Uart {
    name: &'static str,
    stream: UnixStream,
}

impl Uart {
    pub(crate) fn new(name: &'static str, stream: UnixStream) -> Result<Self, Error> {
        stream
            .set_write_timeout(Some(DEFAULT_WRITE_TIMEOUT))
            .map_err(|source| Error::Uart { uart: name, source })?;
        Ok(Uart { name, stream })
    }

    pub(crate) fn into_stream(self) -> UnixStream {
        self.stream
    }

    /// `lbc` or `radio`.
    pub fn name(&self) -> &'static str {
        self.name
    }

    fn err(&self, source: io::Error) -> Error {
        Error::Uart {
            uart: self.name,
            source,
        }
    }

    /// Another handle to the same link.
    pub fn try_clone(&self) -> Result<Uart, Error> {
        let stream = self.stream.try_clone().map_err(|e| self.err(e))?;
        Ok(Uart {
            name: self.name,
            stream,
        })
    }

    /// Bound on each blocking write (`None` blocks forever).
    pub fn set_write_timeout(&self, timeout: Option<Duration>) -> Result<(), Error> {
        self.stream
            .set_write_timeout(timeout)
            .map_err(|e| self.err(e))
    }

    /// Sends all of `data`; fails if the firmware stops taking bytes for longer than
    /// the write timeout.
    pub fn write_all(&mut self, data: &[u8]) -> Result<(), Error> {
        Write::write_all(&mut self.stream, data).map_err(|e| self.err(e))
    }

    /// Fills `buf` completely or fails once `timeout` has passed in total.
    pub fn read_exact_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<(), Error> {
        let deadline = crate::deadline_after(timeout);
        let mut got = 0;
        while got < buf.len() {
            let now = Instant::now();
            let timed_out = Error::UartTimeout {
                uart: self.name,
                timeout,
                got,
                wanted: buf.len(),
            };
            if now >= deadline {
                return Err(timed_out);
            }
            self.stream
                .set_read_timeout(Some(deadline - now))
                .map_err(|e| self.err(e))?;
            match self.stream.read(&mut buf[got..]) {
                Ok(0) => {
                    return Err(Error::UartClosed {
                        uart: self.name,
                        got,
                        wanted: buf.len(),
                    })
                }
                Ok(n) => got += n,
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    return Err(timed_out)
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.err(e)),
            }
        }
        Ok(())
    }

    /// Waits up to `timeout` for data and reads what is there (at least one byte, at most
    /// `buf.len()`).
    pub fn read_some_timeout(&mut self, buf: &mut [u8], timeout: Duration) -> Result<usize, Error> {
        let timed_out = Error::UartTimeout {
            uart: self.name,
            timeout,
            got: 0,
            wanted: buf.len(),
        };
        if buf.is_empty() {
            return Ok(0);
        }
        if timeout.is_zero() {
            return Err(timed_out);
        }
        self.stream
            .set_read_timeout(Some(timeout))
            .map_err(|e| self.err(e))?;
        loop {
            return match self.stream.read(buf) {
                Ok(0) => Err(Error::UartClosed {
                    uart: self.name,
                    got: 0,
                    wanted: buf.len(),
                }),
                Ok(n) => Ok(n),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    Err(timed_out)
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => Err(self.err(e)),
            };
        }
    }

    /// Reads whatever is available right now without waiting; an empty vector means
    /// nothing was pending (or the link is closed).
    pub fn drain(&mut self) -> Result<Vec<u8>, Error> {
        self.stream.set_nonblocking(true).map_err(|e| self.err(e))?;
        let mut out = Vec::new();
        let mut chunk = [0u8; 4096];
        let result = loop {
            match self.stream.read(&mut chunk) {
                Ok(0) => break Ok(()),
                Ok(n) => out.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => break Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => break Err(self.err(e)),
            }
        };
        self.stream
            .set_nonblocking(false)
            .map_err(|e| self.err(e))?;
        result.map(|()| out)
    }
}

/// Plain blocking reads; the timeout set by the last `read_exact_timeout` stays in force.
impl Read for Uart {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.stream.read(buf)
    }
}

impl Write for Uart {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.stream.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.stream.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pair() -> (Uart, UnixStream) {
        let (a, b) = UnixStream::pair().expect("socketpair");
        (Uart::new("lbc", a).expect("uart"), b)
    }

    #[test]
    fn read_exact_times_out_with_partial_count() {
        let (mut uart, mut peer) = pair();
        peer.write_all(b"abc").expect("write");
        let mut buf = [0u8; 5];
        let err = uart
            .read_exact_timeout(&mut buf, Duration::from_millis(50))
            .expect_err("only 3 of 5 bytes were sent");
        assert!(
            matches!(
                err,
                Error::UartTimeout {
                    uart: "lbc",
                    got: 3,
                    wanted: 5,
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn read_exact_reports_close() {
        let (mut uart, mut peer) = pair();
        peer.write_all(b"x").expect("write");
        drop(peer);
        let mut buf = [0u8; 2];
        let err = uart
            .read_exact_timeout(&mut buf, Duration::from_secs(1))
            .expect_err("peer closed");
        assert!(
            matches!(
                err,
                Error::UartClosed {
                    got: 1,
                    wanted: 2,
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn read_some_returns_what_is_there_or_times_out() {
        let (mut uart, mut peer) = pair();
        let mut buf = [0u8; 8];
        let err = uart
            .read_some_timeout(&mut buf, Duration::from_millis(20))
            .expect_err("nothing sent");
        assert!(
            matches!(
                err,
                Error::UartTimeout {
                    got: 0,
                    wanted: 8,
                    ..
                }
            ),
            "{err:?}"
        );
        peer.write_all(b"abc").expect("write");
        let n = uart
            .read_some_timeout(&mut buf, Duration::from_secs(1))
            .expect("data");
        assert_eq!(&buf[..n], b"abc");
        drop(peer);
        let err = uart
            .read_some_timeout(&mut buf, Duration::from_secs(1))
            .expect_err("closed");
        assert!(matches!(err, Error::UartClosed { .. }), "{err:?}");
    }

    #[test]
    fn drain_returns_pending_bytes_without_blocking() {
        let (mut uart, mut peer) = pair();
        assert!(uart.drain().expect("drain").is_empty());
        peer.write_all(b"hello").expect("write");
        // Socket pairs deliver synchronously, so the bytes are already queued.
        assert_eq!(uart.drain().expect("drain"), b"hello");
        uart.write_all(b"back").expect("write");
        let mut buf = [0u8; 4];
        peer.read_exact(&mut buf).expect("read");
        assert_eq!(&buf, b"back");
    }
}
