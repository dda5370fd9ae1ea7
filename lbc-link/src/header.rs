//! Header bytes and their classes (seed 3.3, Table 3-2).
//!
//! A header is any byte `0x80..=0xFE`. Bit 6 set marks a command and its positive
//! acknowledgement (they share the header); the same header with bit 6 clear is
//! that command's specific error. Headers whose bits 4..2 are `111` are general
//! errors (UNKCMD 0xBC, CSER 0xBD, reserved), except STREAM 0xFC, which Table 3-2
//! assigns to streaming. Bit 5 tells control (clear) from system (set) messages.

/// The terminator byte ending every message.
pub const TERMINATOR: u8 = 0xFF;
/// Bit that is set in command/ack headers and clear in their specific errors.
pub const COMMAND_BIT: u8 = 0x40;
/// Header of the UNKCMD general error.
pub const UNKCMD: u8 = 0xBC;
/// Header of the CSER (checksum error) general error.
pub const CSER: u8 = 0xBD;
/// Header of LBC data streaming messages.
pub const STREAM: u8 = 0xFC;

macro_rules! command_kinds {
    ($($(#[$doc:meta])* $name:ident = $hdr:literal, $sym:literal, $cmd_bits:literal, $ack_bits:literal;)*) => {
        /// Every command of Table 3-2; the discriminant is the header byte.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        #[cfg_attr(feature = "serde", derive(serde::Serialize))]
        #[repr(u8)]
        pub enum CommandKind {
            $($(#[$doc])* $name = $hdr,)*
        }

        impl CommandKind {
            /// All commands in header order.
            pub const ALL: &'static [CommandKind] = &[$(CommandKind::$name,)*];

            /// The command for a command/ack header (bit 6 set), if assigned.
            #[must_use]
            pub const fn from_header(header: u8) -> Option<Self> {
                match header {
                    $($hdr => Some(CommandKind::$name),)*
                    _ => None,
                }
            }

            /// The seed's symbol, e.g. `"READ_ID"`.
            #[must_use]
            pub const fn symbol(self) -> &'static str {
                match self {
                    $(CommandKind::$name => $sym,)*
                }
            }

            /// Data bits of the command message (Table 3-2, first number; see docs for fixes).
            #[must_use]
            pub const fn command_bits(self) -> usize {
                match self {
                    $(CommandKind::$name => $cmd_bits,)*
                }
            }

            /// Data bits of the canonical positive acknowledgement.
            #[must_use]
            pub const fn ack_bits(self) -> usize {
                match self {
                    $(CommandKind::$name => $ack_bits,)*
                }
            }
        }
    };
}

command_kinds! {
    /// Stop immediately.
    Stop = 0xC0, "STOP", 0, 0;
    /// Move to coordinate (X, Y).
    MoveXy = 0xC1, "MOVE_XY", 28, 28;
    /// Steer to angle S and hold velocity V.
    MoveSv = 0xC2, "MOVE_SV", 28, 28;
    /// Calibrate steering.
    CalbSt = 0xC8, "CALB_ST", 0, 28;
    /// Calibrate the drive motor.
    CalbDm = 0xC9, "CALB_DM", 0, 0;
    /// Calibrate the gyroscopes (ack: three 14-bit offsets).
    CalbGs = 0xCA, "CALB_GS", 0, 42;
    /// Write an EEPROM user register (7-bit address + 16-bit value = 23 bits).
    WritEp = 0xD0, "WRIT_EP", 23, 23;
    /// Read an EEPROM register (echo ack, then a 23-bit data message).
    ReadEp = 0xD1, "READ_EP", 7, 7;
    /// Set the green and red LED patterns.
    WritLed = 0xD2, "WRIT_LED", 14, 14;
    /// Set the GPIO0 and GPIO1 output patterns.
    WritGpo = 0xD3, "WRIT_GPO", 14, 14;
    /// Initialise motion control and sensing.
    Init = 0xE0, "INIT", 0, 0;
    /// Commit control parameters to the EEPROM.
    Cmep = 0xE1, "CMEP", 0, 0;
    /// Restore control parameters from the EEPROM.
    Rsep = 0xE2, "RSEP", 0, 0;
    /// Disable servo and drive motor.
    Drds = 0xE3, "DRDS", 0, 0;
    /// Enable servo and drive motor.
    Dren = 0xE4, "DREN", 0, 0;
    /// Disable data streaming.
    Stds = 0xE5, "STDS", 0, 0;
    /// Enable data streaming.
    Sten = 0xE6, "STEN", 0, 0;
    /// Read the vehicle ID.
    ReadId = 0xE8, "READ_ID", 0, 7;
    /// Read coordinate (X, Y).
    ReadXy = 0xE9, "READ_XY", 0, 28;
    /// Read steering angle and velocity.
    ReadSv = 0xEA, "READ_SV", 0, 28;
    /// Read adjusted yaw.
    ReadAy = 0xEB, "READ_AY", 0, 14;
    /// Read raw pitch, roll and yaw.
    ReadPry = 0xEC, "READ_PRY", 0, 42;
    /// Read battery-low and over-temperature indicators.
    ReadBt = 0xED, "READ_BT", 0, 2;
    /// Read the range sensor.
    ReadRs = 0xEE, "READ_RS", 0, 14;
    /// Read the tracking heading.
    ReadHd = 0xEF, "READ_HD", 0, 14;
    /// Read the streaming format.
    ReadSf = 0xF0, "READ_SF", 0, 28;
    /// Update the streaming format.
    UpdSf = 0xF1, "UPD_SF", 28, 28;
    /// Read a control parameter (7-bit number; ack adds the 14-bit value).
    ReadPar = 0xF2, "READ_PAR", 7, 21;
    /// Update a control parameter (7-bit number + 14-bit value).
    UpdPar = 0xF3, "UPD_PAR", 21, 21;
}

impl CommandKind {
    /// Header of the command and of its positive acknowledgement.
    #[must_use]
    pub const fn header(self) -> u8 {
        self as u8
    }

    /// Header of this command's specific error (bit 6 cleared).
    #[must_use]
    pub const fn error_header(self) -> u8 {
        self as u8 & !COMMAND_BIT
    }

    /// The command whose specific error uses `header`.
    #[must_use]
    pub const fn from_error_header(header: u8) -> Option<Self> {
        if header & 0xC0 != 0x80 {
            return None;
        }
        Self::from_header(header | COMMAND_BIT)
    }

    /// Control commands have bit 5 clear, system commands have it set.
    #[must_use]
    pub const fn is_control(self) -> bool {
        self as u8 & 0x20 == 0
    }

    /// Data bytes of the command message.
    #[must_use]
    pub const fn command_len(self) -> usize {
        crate::pack::packed_len(self.command_bits())
    }
}

impl core::fmt::Display for CommandKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.symbol())
    }
}

/// What a byte means on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum HeaderClass {
    /// A command, or its positive acknowledgement (same header).
    Command(CommandKind),
    /// The specific error of a command (bit 6 cleared).
    SpecificError(CommandKind),
    /// General error UNKCMD (0xBC).
    UnknownCommand,
    /// General error CSER (0xBD).
    ChecksumError,
    /// LBC streaming data (0xFC).
    Stream,
    /// General-error slot with no assigned meaning (bits 4..2 = `111`).
    Reserved(u8),
    /// A command or error slot marked NOT IN USE.
    NotInUse(u8),
}

impl HeaderClass {
    /// Classifies a header byte; `None` for data/checksum bytes and the terminator.
    #[must_use]
    pub const fn classify(byte: u8) -> Option<Self> {
        if byte < 0x80 || byte == TERMINATOR {
            return None;
        }
        Some(match byte {
            UNKCMD => HeaderClass::UnknownCommand,
            CSER => HeaderClass::ChecksumError,
            STREAM => HeaderClass::Stream,
            b if b & 0x1C == 0x1C => HeaderClass::Reserved(b),
            b => match CommandKind::from_header(b) {
                Some(kind) => HeaderClass::Command(kind),
                None => match CommandKind::from_error_header(b) {
                    Some(kind) => HeaderClass::SpecificError(kind),
                    None => HeaderClass::NotInUse(b),
                },
            },
        })
    }

    /// True for general errors (UNKCMD, CSER, reserved): these never get a reply.
    #[must_use]
    pub const fn is_general_error(self) -> bool {
        matches!(
            self,
            HeaderClass::UnknownCommand | HeaderClass::ChecksumError | HeaderClass::Reserved(_)
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classification_matches_table_3_2() {
        for b in 0u8..=0xFF {
            let class = HeaderClass::classify(b);
            let expected = match b {
                0x00..=0x7F | 0xFF => None,
                0xBC => Some(HeaderClass::UnknownCommand),
                0xBD => Some(HeaderClass::ChecksumError),
                0xFC => Some(HeaderClass::Stream),
                0x9C..=0x9F | 0xBE..=0xBF | 0xDC..=0xDF | 0xFD..=0xFE => {
                    Some(HeaderClass::Reserved(b))
                }
                0xC0..=0xC2 | 0xC8..=0xCA | 0xD0..=0xD3 | 0xE0..=0xE6 | 0xE8..=0xF3 => {
                    Some(HeaderClass::Command(CommandKind::from_header(b).unwrap()))
                }
                0x80..=0x82 | 0x88..=0x8A | 0x90..=0x93 | 0xA0..=0xA6 | 0xA8..=0xB3 => Some(
                    HeaderClass::SpecificError(CommandKind::from_header(b | 0x40).unwrap()),
                ),
                _ => Some(HeaderClass::NotInUse(b)),
            };
            assert_eq!(class, expected, "byte {b:#04x}");
        }
    }

    #[test]
    fn error_headers_clear_bit_6() {
        assert_eq!(CommandKind::Stop.error_header(), 0x80);
        assert_eq!(CommandKind::ReadAy.error_header(), 0xAB);
        assert_eq!(CommandKind::UpdSf.error_header(), 0xB1);
        assert_eq!(
            CommandKind::from_error_header(0x91),
            Some(CommandKind::ReadEp)
        );
        assert_eq!(CommandKind::from_error_header(0xD1), None);
    }

    #[test]
    fn control_and_system_split_on_bit_5() {
        assert!(CommandKind::WritGpo.is_control());
        assert!(!CommandKind::Init.is_control());
        assert_eq!(CommandKind::ALL.len(), 29);
        assert_eq!(
            CommandKind::ALL.iter().filter(|k| k.is_control()).count(),
            10
        );
    }
}
