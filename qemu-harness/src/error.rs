//! The harness's error type: one variant per way a QEMU run can go wrong.

use std::io;
use std::path::PathBuf;
use std::process::ExitStatus;
use std::time::Duration;

/// Everything that can fail while locating, starting, talking to or stopping QEMU.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// `qemu-system-riscv32` is not installed.
    #[error(
        "qemu-system-riscv32 not found on PATH (install the Debian package qemu-system-misc, \
         or set UBC_QEMU to the binary)"
    )]
    QemuNotFound,
    /// The firmware ELF named by `UBC_FW_ELF` or by the build does not exist.
    #[error("firmware ELF {path} does not exist")]
    FirmwareMissing {
        /// The path that was looked for.
        path: PathBuf,
    },
    /// `cargo xtask fw ...` failed or printed no path.
    #[error("firmware build `{command}` failed ({status})")]
    FirmwareBuild {
        /// The build command.
        command: String,
        /// Exit status of the build, or a note that it printed nothing.
        status: String,
    },
    /// The ELF could not be read.
    #[error("cannot read firmware ELF {path}: {source}")]
    ReadElf {
        /// The ELF path.
        path: PathBuf,
        /// The I/O error.
        source: io::Error,
    },
    /// The ELF's `.defmt` table is unusable (wrong defmt version, bad symbols).
    #[error("defmt table in {path} is unusable: {reason}")]
    DefmtTable {
        /// The ELF path.
        path: PathBuf,
        /// What the decoder reported.
        reason: String,
    },
    /// Creating the temp dir, spawning QEMU or another process-level I/O step failed.
    #[error("{action}: {source}")]
    Io {
        /// What the harness was doing.
        action: &'static str,
        /// The I/O error.
        source: io::Error,
    },
    /// QEMU exited before the harness could connect to its sockets.
    #[error("QEMU exited during start-up ({status}); its stderr:\n{stderr}")]
    ExitedDuringStartup {
        /// QEMU's exit status.
        status: ExitStatus,
        /// What QEMU wrote to stderr.
        stderr: String,
    },
    /// A QEMU socket did not accept a connection within the connect timeout.
    #[error("could not connect to QEMU's {uart} socket {path} within {timeout:?}: {source}")]
    Connect {
        /// `lbc`, `radio` or `semihost` (the log console).
        uart: &'static str,
        /// The socket path.
        path: PathBuf,
        /// The configured bound.
        timeout: Duration,
        /// The last connection error.
        source: io::Error,
    },
    /// A UART read did not complete in time.
    #[error("{uart} uart: timed out after {timeout:?} with {got} of {wanted} bytes")]
    UartTimeout {
        /// `lbc` or `radio`.
        uart: &'static str,
        /// The bound that expired.
        timeout: Duration,
        /// Bytes received before it expired.
        got: usize,
        /// Bytes asked for.
        wanted: usize,
    },
    /// QEMU closed a UART socket (it exited) while bytes were still expected.
    #[error("{uart} uart: closed by QEMU after {got} of {wanted} bytes")]
    UartClosed {
        /// `lbc` or `radio`.
        uart: &'static str,
        /// Bytes received before it closed.
        got: usize,
        /// Bytes asked for.
        wanted: usize,
    },
    /// Any other socket error on a UART.
    #[error("{uart} uart: {source}")]
    Uart {
        /// `lbc` or `radio`.
        uart: &'static str,
        /// The I/O error.
        source: io::Error,
    },
    /// No log line matched within the timeout.
    #[error("no matching log line within {timeout:?} ({seen} lines seen, last: {last:?})")]
    LogTimeout {
        /// The bound that expired.
        timeout: Duration,
        /// Number of lines collected so far.
        seen: usize,
        /// The most recent line, if any.
        last: Option<String>,
    },
    /// QEMU's log stream ended (QEMU exited) before a matching line arrived.
    #[error("log ended before a matching line arrived ({seen} lines seen, last: {last:?})")]
    LogClosed {
        /// Number of lines collected.
        seen: usize,
        /// The most recent line, if any.
        last: Option<String>,
    },
    /// QEMU did not exit within the timeout.
    #[error("QEMU still running after {timeout:?}")]
    ExitTimeout {
        /// The bound that expired.
        timeout: Duration,
    },
}
