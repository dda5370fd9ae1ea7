//! LBC side: turn received bytes into commands to execute or replies to send.
//!
//! [`CommandParser`] deframes and decodes what the UBC sends and says what to do:
//! execute a [`Command`] (and then emit its [`Reply`](crate::Reply) or
//! [`LbcMessage::Error`]), send a reply at once (CSER for a bad checksum, UNKCMD
//! for a message it cannot understand, the specific error for a command whose
//! fields are out of range), or stay silent (general errors, framing noise).

use crate::deframe::{DeframeError, Deframer, DeframerStats};
use crate::header::HeaderClass;
use crate::message::{Command, DecodeError, Echo, LbcMessage};
use crate::wire::RawMessage;

/// What the LBC should do about received bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Incoming {
    /// A valid command: execute it, then send its ack or specific error.
    Command(Command),
    /// Send this message now (CSER, UNKCMD or a specific error).
    Respond(LbcMessage),
    /// Nothing to send: a framing problem or a general-error message.
    Ignore(Ignored),
}

/// Why nothing is sent back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Ignored {
    /// Noise between messages, or a message cut short.
    Framing(DeframeError),
    /// A general-error or STREAM header: such messages get no reply (seed 3.3).
    NoReply { header: u8 },
}

/// The LBC's receive path.
#[derive(Debug, Clone, Default)]
pub struct CommandParser {
    deframer: Deframer,
}

impl CommandParser {
    /// A parser with an idle deframer.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            deframer: Deframer::new(),
        }
    }

    /// Framing counters.
    #[must_use]
    pub fn stats(&self) -> &DeframerStats {
        self.deframer.stats()
    }

    /// Feeds one byte; returns what to do when a message (or error) completes.
    pub fn push(&mut self, byte: u8) -> Option<Incoming> {
        Some(match self.deframer.push(byte)? {
            Ok(msg) => classify_command(&msg),
            Err(DeframeError::ChecksumMismatch { .. }) => {
                Incoming::Respond(LbcMessage::ChecksumError)
            }
            Err(DeframeError::MissingChecksum { header }) => {
                Incoming::Respond(LbcMessage::UnknownCommand(Some(Echo::of(&RawMessage {
                    header,
                    data: &[],
                }))))
            }
            Err(e) => Incoming::Ignore(Ignored::Framing(e)),
        })
    }
}

/// Decides how the LBC answers one well-framed message.
#[must_use]
pub fn classify_command(msg: &RawMessage<'_>) -> Incoming {
    match Command::parse(msg) {
        Ok(cmd) => Incoming::Command(cmd),
        Err(DecodeError::Field { header, .. }) => match HeaderClass::classify(header) {
            Some(HeaderClass::Command(kind)) => Incoming::Respond(LbcMessage::Error(kind)),
            _ => Incoming::Respond(LbcMessage::UnknownCommand(Some(Echo::of(msg)))),
        },
        Err(_) => {
            let silent = HeaderClass::classify(msg.header)
                .is_some_and(|c| c.is_general_error() || c == HeaderClass::Stream);
            if silent {
                Incoming::Ignore(Ignored::NoReply { header: msg.header })
            } else {
                Incoming::Respond(LbcMessage::UnknownCommand(Some(Echo::of(msg))))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::header::CommandKind;
    use std::vec::Vec;

    fn feed(bytes: &[u8]) -> Vec<Incoming> {
        let mut p = CommandParser::new();
        bytes.iter().filter_map(|&b| p.push(b)).collect()
    }

    #[test]
    fn valid_command_is_executed() {
        assert_eq!(
            feed(&[0xE8, 0x68, 0xFF]),
            [Incoming::Command(Command::ReadId)]
        );
    }

    #[test]
    fn bad_checksum_gets_cser() {
        assert_eq!(
            feed(&[0xE8, 0x69, 0xFF]),
            [Incoming::Respond(LbcMessage::ChecksumError)]
        );
    }

    #[test]
    fn out_of_range_coordinate_gets_the_specific_error() {
        // MOVE_XY with X = 700
        let data = [0x05, 0x3C, 0x00, 0x00];
        let cs = crate::checksum(0xC1, &data);
        let out = feed(&[0xC1, data[0], data[1], data[2], data[3], cs, 0xFF]);
        assert_eq!(
            out,
            [Incoming::Respond(LbcMessage::Error(CommandKind::MoveXy))]
        );
    }

    #[test]
    fn unknown_header_gets_unkcmd_with_echo() {
        let out = feed(&[0xC3, 0x01, 0x42, 0xFF]);
        let Incoming::Respond(LbcMessage::UnknownCommand(Some(echo))) = &out[0] else {
            panic!("{out:?}");
        };
        assert_eq!((echo.header, echo.data.as_slice()), (0xC3, &[0x01][..]));
        let mut buf = [0u8; 8];
        let n = LbcMessage::UnknownCommand(Some(echo.clone()))
            .emit(&mut buf)
            .unwrap();
        assert_eq!(
            &buf[..n],
            &[0xBC, 0x43, 0x01, (0xBC ^ 0x43 ^ 0x01) & 0x7F, 0xFF]
        );
    }

    #[test]
    fn wrong_length_gets_unkcmd() {
        let out = feed(&[0xE8, 0x01, 0x69, 0xFF]);
        assert!(matches!(
            out[0],
            Incoming::Respond(LbcMessage::UnknownCommand(Some(_)))
        ));
    }

    #[test]
    fn general_errors_and_noise_get_no_reply() {
        assert_eq!(
            feed(&[0xBD, 0x3D, 0xFF, 0x12]),
            [
                Incoming::Ignore(Ignored::NoReply { header: 0xBD }),
                Incoming::Ignore(Ignored::Framing(DeframeError::Garbage { byte: 0x12 }))
            ]
        );
    }
}
