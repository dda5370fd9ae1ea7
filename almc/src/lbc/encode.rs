//! `almc lbc encode`: build a command message from named fields.

use std::process::ExitCode;

use clap::Subcommand;
use lbc_link::{
    Command, EepromAddress, GpioPattern, LedPattern, Param, ParamValue, Position, RangeError,
    SteerVelocity, SteeringAngle, StreamFormat, UserRegister, Velocity, MAX_FRAME_LEN,
};

use super::hex::{parse_int, to_hex};
use super::text::range_error;

fn int(s: &str) -> Result<i64, String> {
    parse_int(s).map_err(|e| e.to_string())
}

/// Commands to encode; numbers may be decimal, `0x` hex or `0b` binary.
#[derive(Debug, Subcommand)]
pub enum EncodeCommand {
    /// STOP (0xC0): stop immediately.
    Stop,
    /// MOVE_XY (0xC1): move to X 0..=640, Y 0..=960 (tracking units, 2.5 mm).
    MoveXy {
        #[arg(value_parser = int)]
        x: i64,
        #[arg(value_parser = int)]
        y: i64,
    },
    /// MOVE_SV (0xC2): steer to S mrad (-523..=523, + = left), hold V mm/s.
    #[command(allow_negative_numbers = true)]
    MoveSv {
        #[arg(value_parser = int)]
        steering: i64,
        #[arg(value_parser = int)]
        velocity: i64,
    },
    /// CALB_ST (0xC8): calibrate steering.
    CalbSt,
    /// CALB_DM (0xC9): calibrate the drive motor.
    CalbDm,
    /// CALB_GS (0xCA): calibrate the gyroscopes.
    CalbGs,
    /// WRIT_EP (0xD0): write a 16-bit value to user register 0x20..=0x3F.
    WritEp {
        #[arg(value_parser = int)]
        address: i64,
        #[arg(value_parser = int)]
        value: i64,
    },
    /// READ_EP (0xD1): read EEPROM register 0x00..=0x3F.
    ReadEp {
        #[arg(value_parser = int)]
        address: i64,
    },
    /// WRIT_LED (0xD2): LED patterns, bits 6..4 rate/mode, bits 3..0 duty (Table 3-5).
    WritLed {
        #[arg(long, value_parser = int)]
        green: i64,
        #[arg(long, value_parser = int)]
        red: i64,
    },
    /// WRIT_GPO (0xD3): GPIO patterns, bits 6..4 frequency, bits 3..0 duty (Table 3-6).
    WritGpo {
        #[arg(long, value_parser = int)]
        gpio0: i64,
        #[arg(long, value_parser = int)]
        gpio1: i64,
    },
    /// INIT (0xE0).
    Init,
    /// CMEP (0xE1): commit control parameters to the EEPROM.
    Cmep,
    /// RSEP (0xE2): restore control parameters from the EEPROM.
    Rsep,
    /// DRDS (0xE3): disable servo and drive motor.
    Drds,
    /// DREN (0xE4): enable servo and drive motor.
    Dren,
    /// STDS (0xE5): stop streaming.
    Stds,
    /// STEN (0xE6): start streaming.
    Sten,
    /// READ_ID (0xE8).
    ReadId,
    /// READ_XY (0xE9).
    ReadXy,
    /// READ_SV (0xEA).
    ReadSv,
    /// READ_AY (0xEB).
    ReadAy,
    /// READ_PRY (0xEC).
    ReadPry,
    /// READ_BT (0xED).
    ReadBt,
    /// READ_RS (0xEE).
    ReadRs,
    /// READ_HD (0xEF).
    ReadHd,
    /// READ_SF (0xF0).
    ReadSf,
    /// UPD_SF (0xF1): set the 28-bit streaming format (no bit of 0x002060E0).
    UpdSf {
        #[arg(value_parser = int)]
        format: i64,
    },
    /// READ_PAR (0xF2): read control parameter 1..=12 (Table 3-3).
    ReadPar {
        #[arg(value_parser = int)]
        param: i64,
    },
    /// UPD_PAR (0xF3): set control parameter 1..=12 to a 14-bit value.
    #[command(allow_negative_numbers = true)]
    UpdPar {
        #[arg(value_parser = int)]
        param: i64,
        #[arg(value_parser = int)]
        value: i64,
    },
}

/// A field that failed its range check, named as on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldError {
    pub name: &'static str,
    pub error: RangeError,
}

fn check<T>(name: &'static str, r: Result<T, RangeError>) -> Result<T, FieldError> {
    r.map_err(|error| FieldError { name, error })
}

impl EncodeCommand {
    /// The typed command, with range checks.
    pub fn to_command(&self) -> Result<Command, FieldError> {
        use lbc_link::Field as F;
        use EncodeCommand as E;
        Ok(match *self {
            E::Stop => Command::Stop,
            E::MoveXy { x, y } => Command::MoveXy(Position {
                x: check("x", lbc_link::XCoord::try_from_i64(x))?,
                y: check("y", lbc_link::YCoord::try_from_i64(y))?,
            }),
            E::MoveSv { steering, velocity } => Command::MoveSv(SteerVelocity {
                steering: check("steering", SteeringAngle::try_from_i64(steering))?,
                velocity: check("velocity", Velocity::try_from_i64(velocity))?,
            }),
            E::CalbSt => Command::CalbSt,
            E::CalbDm => Command::CalbDm,
            E::CalbGs => Command::CalbGs,
            E::WritEp { address, value } => Command::WritEp {
                address: check("address", UserRegister::try_from_i64(address))?,
                value: u16::try_from(value).map_err(|_| FieldError {
                    name: "value",
                    error: RangeError {
                        field: F::EepromValue,
                        value,
                    },
                })?,
            },
            E::ReadEp { address } => {
                Command::ReadEp(check("address", EepromAddress::try_from_i64(address))?)
            }
            E::WritLed { green, red } => Command::WritLed {
                green: pattern("green", green, LedPattern::from_bits)?,
                red: pattern("red", red, LedPattern::from_bits)?,
            },
            E::WritGpo { gpio0, gpio1 } => Command::WritGpo {
                gpio0: pattern("gpio0", gpio0, GpioPattern::from_bits)?,
                gpio1: pattern("gpio1", gpio1, GpioPattern::from_bits)?,
            },
            E::Init => Command::Init,
            E::Cmep => Command::Cmep,
            E::Rsep => Command::Rsep,
            E::Drds => Command::Drds,
            E::Dren => Command::Dren,
            E::Stds => Command::Stds,
            E::Sten => Command::Sten,
            E::ReadId => Command::ReadId,
            E::ReadXy => Command::ReadXy,
            E::ReadSv => Command::ReadSv,
            E::ReadAy => Command::ReadAy,
            E::ReadPry => Command::ReadPry,
            E::ReadBt => Command::ReadBt,
            E::ReadRs => Command::ReadRs,
            E::ReadHd => Command::ReadHd,
            E::ReadSf => Command::ReadSf,
            E::UpdSf { format } => {
                let bad = FieldError {
                    name: "format",
                    error: RangeError {
                        field: F::StreamFormat,
                        value: format,
                    },
                };
                let bits = u32::try_from(format).map_err(|_| bad.clone())?;
                Command::UpdSf(StreamFormat::new(bits).map_err(|_| bad)?)
            }
            E::ReadPar { param } => Command::ReadPar(param_number(param)?),
            E::UpdPar { param, value } => {
                let p = param_number(param)?;
                let v = i16::try_from(value).map_err(|_| FieldError {
                    name: "value",
                    error: RangeError {
                        field: F::ParamValue,
                        value,
                    },
                })?;
                Command::UpdPar(check("value", ParamValue::new(p, v))?)
            }
        })
    }
}

fn pattern<T>(
    name: &'static str,
    v: i64,
    make: fn(u8) -> Result<T, RangeError>,
) -> Result<T, FieldError> {
    let bad = || FieldError {
        name,
        error: RangeError {
            field: lbc_link::Field::Pattern,
            value: v,
        },
    };
    let byte = u8::try_from(v).map_err(|_| bad())?;
    make(byte).map_err(|_| bad())
}

fn param_number(n: i64) -> Result<Param, FieldError> {
    let bad = || FieldError {
        name: "param",
        error: RangeError {
            field: lbc_link::Field::ParamNumber,
            value: n,
        },
    };
    let n = u8::try_from(n).map_err(|_| bad())?;
    Param::from_number(n).map_err(|_| bad())
}

/// Runs `almc lbc encode`.
pub fn run(cmd: &EncodeCommand) -> ExitCode {
    let command = match cmd.to_command() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("almc lbc encode: {}: {}", e.name, range_error(&e.error));
            return ExitCode::from(2);
        }
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    match command.emit(&mut buf) {
        Ok(n) => {
            println!("{}", to_hex(&buf[..n]));
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("almc lbc encode: cannot encode: {e:?}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn range_errors_name_the_argument() {
        let e = EncodeCommand::MoveXy { x: 700, y: 0 }
            .to_command()
            .unwrap_err();
        assert_eq!(e.name, "x");
        assert_eq!(e.error.value, 700);
        let e = EncodeCommand::UpdSf { format: 0xE0 }
            .to_command()
            .unwrap_err();
        assert_eq!(e.name, "format");
        let e = EncodeCommand::WritEp {
            address: 0x05,
            value: 1,
        }
        .to_command()
        .unwrap_err();
        assert_eq!(e.name, "address");
    }
}
