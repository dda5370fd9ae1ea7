//! The `lbc-emu` command line, shared by the `lbc-emu` binary and `almc lbc-emu`.
//!
//! `--listen unix:PATH | tcp:127.0.0.1:PORT [--eeprom FILE] [--id N] [--faults SPEC] [--seed N]
//! [--log]`. SIGINT and SIGTERM stop the server cleanly (the socket file is removed; the EEPROM
//! file is always consistent because every commit is atomic).

use std::fmt;
use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::eeprom::{reg, EepromFileError, EepromImage, EepromStore, FileStore, MemoryStore};
use crate::faults::FaultConfig;
use crate::lbc::{Lbc, LbcConfig};
use crate::server::{ListenAddr, Server, ServerEvent};

/// Arguments of `almc lbc-emu`.
#[derive(Debug, Clone, clap::Args)]
#[command(about = "Run an emulated lower board (LBC) behind a socket")]
pub struct LbcEmuArgs {
    /// Where the UBC side connects: unix:PATH or tcp:127.0.0.1:PORT.
    #[arg(long, value_name = "unix:PATH|tcp:127.0.0.1:PORT")]
    pub listen: ListenAddr,
    /// EEPROM file (created with factory defaults if missing); in memory when absent.
    #[arg(long, value_name = "FILE")]
    pub eeprom: Option<PathBuf>,
    /// Car ID (0..=127) written to EEPROM register 0x00.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(0..=127))]
    pub id: Option<u8>,
    /// Link faults, e.g. drop=0.01,corrupt=0.001,delay-ms=5,suppress=0.0,reset-every-s=0.
    #[arg(long, value_name = "SPEC", default_value = "")]
    pub faults: FaultConfig,
    /// Seed of sensor noise and faults.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub seed: u64,
    /// Print every command and reply.
    #[arg(long)]
    pub log: bool,
    /// Pause inside each EEPROM file commit, ms (test hook).
    #[arg(long, hide = true, value_name = "MS")]
    pub eeprom_write_pause_ms: Option<u64>,
}

/// Why `lbc-emu` stopped with an error.
#[derive(Debug)]
#[non_exhaustive]
pub enum CliError {
    /// The EEPROM file could not be loaded or written.
    Eeprom {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        error: EepromFileError,
    },
    /// The socket could not be bound or served.
    Socket {
        /// The address.
        addr: ListenAddr,
        /// What went wrong.
        error: io::Error,
    },
    /// The signal handler could not be installed.
    Signal(ctrlc::Error),
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Eeprom { path, error } => write!(f, "EEPROM file {}: {error}", path.display()),
            Self::Socket { addr, error } => write!(f, "socket {addr}: {error}"),
            Self::Signal(e) => write!(f, "cannot install the signal handler: {e}"),
        }
    }
}

impl std::error::Error for CliError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Eeprom { error, .. } => Some(error),
            Self::Socket { error, .. } => Some(error),
            Self::Signal(e) => Some(e),
        }
    }
}

/// Runs the emulator until SIGINT/SIGTERM.
pub fn run(args: LbcEmuArgs) -> Result<(), CliError> {
    let (image, store): (EepromImage, Box<dyn EepromStore>) = match &args.eeprom {
        Some(path) => {
            let eeprom_err = |error| CliError::Eeprom {
                path: path.clone(),
                error,
            };
            let (mut store, mut image) =
                FileStore::open(path, &EepromImage::factory(args.id.unwrap_or(1)))
                    .map_err(eeprom_err)?;
            store.set_write_pause(args.eeprom_write_pause_ms.map(Duration::from_millis));
            if let Some(id) = args.id {
                if image.car_id() != id || image.get(reg::CID) != Some(u16::from(id)) {
                    image.set(reg::CID, u16::from(id));
                    store.commit(&image).map_err(eeprom_err)?;
                }
            }
            (image, Box::new(store))
        }
        None => (
            EepromImage::factory(args.id.unwrap_or(1)),
            Box::new(MemoryStore::default()),
        ),
    };
    let cfg = LbcConfig {
        faults: args.faults,
        seed: args.seed,
        log: args.log,
        ..LbcConfig::default()
    };
    let mut lbc = Lbc::new(cfg, image, store);

    let server = Server::bind(&args.listen).map_err(|error| CliError::Socket {
        addr: args.listen.clone(),
        error,
    })?;
    let stop = Arc::new(AtomicBool::new(false));
    let s = Arc::clone(&stop);
    ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)).map_err(CliError::Signal)?;

    eprintln!(
        "lbc-emu: car {} listening on {}{}{}",
        image.car_id(),
        server.local_addr(),
        match &args.eeprom {
            Some(p) => format!(", EEPROM {}", p.display()),
            None => ", EEPROM in memory".to_owned(),
        },
        if args.faults.is_active() {
            format!(", faults {}", args.faults)
        } else {
            String::new()
        }
    );
    let log = args.log;
    let mut on_log = |e: &crate::lbc::LogEntry| {
        if log {
            eprintln!("{:>12.6} {}", e.t_us as f64 / 1e6, e.event);
        }
    };
    let mut on_event = |e: ServerEvent| eprintln!("lbc-emu: {e:?}");
    server
        .run(&mut lbc, &stop, &mut on_log, &mut on_event)
        .map_err(|error| CliError::Socket {
            addr: args.listen.clone(),
            error,
        })?;
    let s = lbc.stats();
    eprintln!(
        "lbc-emu: stopped after {:.1} s: {} commands, {} replies, {} errors, {} CSER, {} UNKCMD, {} STREAM",
        lbc.now_us() as f64 / 1e6,
        s.commands,
        s.replies,
        s.errors,
        s.cser,
        s.unkcmd,
        s.stream_frames
    );
    Ok(())
}
