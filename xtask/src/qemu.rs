//! `cargo xtask qemu`: boots the firmware in QEMU, attaches its UARTs to sockets and
//! prints the decoded defmt log until QEMU exits, the timeout passes or Ctrl-C.
//!
//! QEMU never outlives this command: the timeout and every return path stop it through
//! the harness (kill, reap, remove its socket directory); a terminal's Ctrl-C reaches QEMU
//! too (same process group), and it carries a parent-death signal, so it also dies when
//! this process is killed any other way.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use qemu_harness::{Error as HarnessError, Qemu, SocketSpec, UartAttach};

/// Options of `cargo xtask qemu`.
#[derive(Debug, clap::Args)]
pub struct QemuArgs {
    /// Firmware ELF to boot [default: build it for the qemu_virt board]
    #[arg(long, value_name = "PATH")]
    elf: Option<PathBuf>,
    /// Connect the LBC UART as a client to this socket (e.g. an emulated LBC server)
    #[arg(
        long,
        value_name = "unix:PATH|tcp:HOST:PORT",
        conflicts_with = "lbc_listen"
    )]
    lbc: Option<SocketSpec>,
    /// Serve the LBC UART on this Unix socket path instead
    #[arg(long, value_name = "PATH")]
    lbc_listen: Option<PathBuf>,
    /// Connect the radio UART as a client to this socket
    #[arg(
        long,
        value_name = "unix:PATH|tcp:HOST:PORT",
        conflicts_with = "radio_listen"
    )]
    radio: Option<SocketSpec>,
    /// Serve the radio UART on this Unix socket path instead
    #[arg(long, value_name = "PATH")]
    radio_listen: Option<PathBuf>,
    /// Stop QEMU after this many seconds
    #[arg(long, value_name = "SECS")]
    timeout: Option<u64>,
    /// Pass `-icount` to QEMU: a number N means `shift=N`, anything else goes verbatim
    /// (e.g. `shift=auto,sleep=off`)
    #[arg(long, value_name = "N|OPTIONS")]
    icount: Option<String>,
}

fn attach(connect: Option<SocketSpec>, listen: Option<PathBuf>) -> UartAttach {
    match (connect, listen) {
        (Some(spec), _) => UartAttach::Connect(spec),
        (None, Some(path)) => UartAttach::Listen(SocketSpec::Unix(path)),
        (None, None) => UartAttach::Null,
    }
}

/// The instant `secs` seconds from now; `None` (no deadline) when that lies beyond what the
/// clock can represent, so a huge `--timeout` cannot panic.
fn deadline_in(secs: u64) -> Option<Instant> {
    Instant::now().checked_add(Duration::from_secs(secs))
}

/// Runs `cargo xtask qemu`.
pub fn run(args: QemuArgs) -> anyhow::Result<()> {
    crate::install::ensure_qemu()?;
    let elf = match args.elf {
        Some(elf) => elf,
        None => crate::fw::build("qemu_virt", true).context("building the firmware")?,
    };
    let mut builder = Qemu::builder(&elf)
        .lbc(attach(args.lbc, args.lbc_listen))
        .radio(attach(args.radio, args.radio_listen));
    builder = match args.icount.as_deref().map(|v| (v, v.parse::<u8>())) {
        Some((_, Ok(shift))) => builder.icount(Some(shift)),
        Some((options, Err(_))) => builder.arg("-icount").arg(options),
        None => builder,
    };
    let mut qemu = builder
        .spawn()
        .with_context(|| format!("starting QEMU with {}", elf.display()))?;
    eprintln!("qemu: pid {} booting {}", qemu.pid(), elf.display());

    let deadline = args.timeout.and_then(deadline_in);
    let mut next = 0;
    loop {
        // Checked before every line, so a flood of log lines cannot starve the timeout.
        if deadline.is_some_and(|d| Instant::now() >= d) {
            eprintln!("qemu: timeout reached, stopping QEMU");
            qemu.kill()?;
            return Ok(());
        }
        match qemu
            .log()
            .wait_for_from(next, |_| true, Duration::from_millis(100))
        {
            Ok((index, line)) => {
                println!("{line}");
                next = index + 1;
            }
            Err(HarnessError::LogTimeout { .. }) => {
                if qemu.try_wait()?.is_some() {
                    break;
                }
            }
            Err(HarnessError::LogClosed { .. }) => break,
            Err(e) => return Err(e.into()),
        }
    }

    let status = qemu.wait_exit(Duration::from_secs(5))?;
    print_rest(&qemu, next);
    let malformed = qemu.log().malformed_frames();
    if malformed > 0 {
        eprintln!("qemu: {malformed} log frames could not be decoded");
    }
    if status.success() {
        eprintln!("qemu: exited normally");
        Ok(())
    } else {
        // QEMU's own notes about waiting for the harness's sockets are not news.
        let stderr = qemu.stderr_text();
        for line in stderr
            .lines()
            .filter(|l| !l.contains("QEMU waiting for connection"))
        {
            eprintln!("{line}");
        }
        anyhow::bail!("QEMU exited with {status}")
    }
}

fn print_rest(qemu: &Qemu, mut next: usize) {
    while let Ok((index, line)) = qemu.log().wait_for_from(next, |_| true, Duration::ZERO) {
        println!("{line}");
        next = index + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: QemuArgs,
    }

    #[test]
    fn sockets_and_options_parse() {
        let cli = Cli::try_parse_from([
            "qemu",
            "--elf",
            "fw.elf",
            "--lbc",
            "unix:/tmp/lbc.sock",
            "--radio-listen",
            "/tmp/radio.sock",
            "--timeout",
            "5",
            "--icount",
            "3",
        ])
        .expect("valid");
        let a = cli.args;
        assert_eq!(
            attach(a.lbc, a.lbc_listen),
            UartAttach::Connect(SocketSpec::Unix("/tmp/lbc.sock".into()))
        );
        assert_eq!(
            attach(a.radio, a.radio_listen),
            UartAttach::Listen(SocketSpec::Unix("/tmp/radio.sock".into()))
        );
        assert_eq!((a.timeout, a.icount.as_deref()), (Some(5), Some("3")));
    }

    #[test]
    fn huge_timeout_means_no_deadline_instead_of_a_panic() {
        let cli = Cli::try_parse_from(["qemu", "--timeout", &u64::MAX.to_string()]).expect("valid");
        assert_eq!(cli.args.timeout.and_then(deadline_in), None);
        assert!(deadline_in(5).is_some_and(|d| d > Instant::now()));
    }

    #[test]
    fn bad_socket_and_conflicts_are_rejected() {
        assert!(Cli::try_parse_from(["qemu", "--lbc", "/tmp/no-scheme"]).is_err());
        assert!(
            Cli::try_parse_from(["qemu", "--lbc", "tcp:h:1", "--lbc-listen", "/tmp/x"]).is_err()
        );
        let none = Cli::try_parse_from(["qemu"]).expect("defaults");
        assert_eq!(
            attach(none.args.lbc, none.args.lbc_listen),
            UartAttach::Null
        );
    }
}
