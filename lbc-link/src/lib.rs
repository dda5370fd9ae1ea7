//! The UBC<->LBC link of the ALMC micro-car (seed chapter 3), for both ends.
//!
//! Layers, bottom up:
//! - [`pack`]: 7-bit packing of arbitrary field widths.
//! - [`wire`]: message framing, checksum, a checked [`Frame`] view.
//! - [`deframe`]: a byte-at-a-time [`Deframer`] that resynchronises on headers.
//! - [`header`], [`fields`], [`stream`], [`message`]: typed headers, fields,
//!   streaming formats and messages ([`Command`], [`Reply`], [`LbcMessage`]).
//! - [`client`]: the UBC's sans-IO [`Client`]; [`lbc`]: the LBC's [`CommandParser`].
//!
//! No heap, no `unsafe`, no `std` outside tests. Wire details and the readings
//! chosen where the seed is ambiguous are in `docs/lbc-protocol.md`.
//!
//! Features: `defmt` derives `defmt::Format` (firmware logs), `serde` derives
//! `serde::Serialize` (host tools). Neither is on by default.
//!
//! UBC side: queue commands, feed bytes and time, forward events.
//!
//! ```
//! use lbc_link::client::{Client, Event, Instant};
//! use lbc_link::{Command, Position, Reply};
//!
//! let mut client = Client::default();
//! let target = Position::new(320, 480).unwrap();
//! client.send(Instant::from_millis(0), Command::MoveXy(target)).unwrap();
//!
//! let mut tx = [0u8; 16];
//! let n = client.transmit(&mut tx); // write these to the LBC UART
//! assert_eq!(&tx[..n], &[0xC1, 0x02, 0x40, 0x03, 0x60, 0x60, 0xFF]);
//!
//! // The LBC acknowledges by repeating the message.
//! let rx = &tx[..n];
//! client.poll(Instant::from_millis(3), rx, |event| match event {
//!     Event::Done { reply, .. } => assert_eq!(reply, Reply::Echo(Command::MoveXy(target))),
//!     other => panic!("{other:?}"),
//! });
//! ```
//!
//! LBC side: parse commands, answer with replies, errors and STREAM messages.
//!
//! ```
//! use lbc_link::lbc::{CommandParser, Incoming};
//! use lbc_link::{Command, LbcMessage, Reply, VehicleId};
//!
//! let mut parser = CommandParser::new();
//! let mut out = [0u8; lbc_link::MAX_FRAME_LEN];
//! for &byte in &[0xE8, 0x68, 0xFF] {
//!     match parser.push(byte) {
//!         Some(Incoming::Command(Command::ReadId)) => {
//!             let n = Reply::ReadId(VehicleId::new(7).unwrap()).emit(&mut out).unwrap();
//!             assert_eq!(&out[..n], &[0xE8, 0x07, 0x6F, 0xFF]);
//!         }
//!         Some(Incoming::Respond(msg)) => {
//!             let _n = msg.emit(&mut out).unwrap(); // CSER, UNKCMD or a specific error
//!         }
//!         Some(_) | None => {}
//!     }
//! }
//! let n = LbcMessage::ChecksumError.emit(&mut out).unwrap();
//! assert_eq!(&out[..n], &[0xBD, 0x3D, 0xFF]);
//! ```
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

pub mod client;
pub mod deframe;
pub mod fields;
pub mod header;
pub mod lbc;
pub mod message;
pub mod pack;
pub mod stream;
pub mod wire;

pub use client::{Client, Event, Instant};
pub use deframe::{DeframeError, Deframer, DeframerStats};
pub use fields::*;
pub use header::{CommandKind, HeaderClass};
pub use lbc::{CommandParser, Incoming};
pub use message::{Command, DecodeError, Echo, LbcMessage, Reply, StreamData};
pub use stream::{
    decode_all, StreamError, StreamFormat, StreamSample, SystemValue, SystemVariable,
};
pub use wire::{checksum, EncodeError, Frame, FrameError, RawMessage, MAX_DATA_LEN, MAX_FRAME_LEN};
