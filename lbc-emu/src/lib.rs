//! An emulated ALMC lower board controller (LBC) with the car it drives.
//!
//! Researchers develop upper-board software against this instead of a car on the desk. The
//! emulator answers every command of the seed's Table 3-2 as the seed's chapters 2 and 3
//! describe, streams at 30 Hz, keeps its EEPROM in a file, and moves a modelled car with the
//! LBC's own tasks (velocity PID at 1 kHz, path generation at 50 Hz, ...).
//!
//! - [`Lbc`] is the sans-IO core: feed it bytes with [`Lbc::push_rx`], advance it with
//!   [`Lbc::step_until`], take what its UART sent with [`Lbc::pop_tx`]. Lockstep simulations
//!   (Verilator, the arena) drive it directly with simulated time.
//! - [`server`] runs it in real time behind a Unix or TCP socket (QEMU's UART connects there).
//! - [`cli`] is the `almc lbc-emu` / `lbc-emu` command line.
//!
//! ```
//! use lbc_emu::{Lbc, LbcConfig};
//! use lbc_link::{Command, Deframer, LbcMessage, Reply};
//!
//! let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 7);
//! let mut buf = [0u8; 8];
//! let n = Command::ReadId.emit(&mut buf).unwrap();
//! lbc.push_rx(0, &buf[..n]);
//! lbc.step_until(5_000);
//! let mut out = Vec::new();
//! lbc.drain_tx(5_000, &mut out);
//! let mut d = Deframer::new();
//! let msg = out.iter().find_map(|&b| d.push(b).map(|m| LbcMessage::parse(&m.unwrap()).unwrap()));
//! assert!(matches!(msg, Some(LbcMessage::Reply(Reply::ReadId(id))) if id.get() == 7));
//! ```
#![forbid(unsafe_code)]

pub mod cli;
pub mod control;
pub mod eeprom;
pub mod faults;
pub mod lbc;
pub mod scheduler;
pub mod server;
pub mod uart;
pub mod vehicle;

pub use eeprom::{EepromImage, EepromStore, FileStore, MemoryStore};
pub use faults::FaultConfig;
pub use lbc::{Lbc, LbcConfig, LbcStats, LogEntry, LogEvent, PoseSource, TrackingConfig};
pub use vehicle::{Pose, Vehicle, VehicleConfig};
