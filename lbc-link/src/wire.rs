//! Message framing (seed 3.2): `<header> <data...> <checksum> <0xFF>`.
//!
//! [`Frame`] is a checked view over a complete message buffer; [`emit_frame`]
//! writes one. The checksum is a single byte: the XOR of the header and every
//! data byte, masked with 0x7F (Table 3-1; the "two bytes" in a note under
//! Table 3-2 contradicts every example and is not followed).

use crate::header::TERMINATOR;

/// Largest data field the deframer accepts (the longest STREAM needs 58 bytes).
pub const MAX_DATA_LEN: usize = 64;
/// Largest complete message: header, data, checksum and terminator.
pub const MAX_FRAME_LEN: usize = MAX_DATA_LEN + 3;

/// The checksum of a message: XOR of header and data, masked to 7 bits.
#[must_use]
pub fn checksum(header: u8, data: &[u8]) -> u8 {
    data.iter().fold(header, |acc, b| acc ^ b) & 0x7F
}

/// Length of a complete message with `data_len` data bytes.
#[must_use]
pub const fn frame_len(data_len: usize) -> usize {
    data_len + 3
}

/// Byte positions in a message; the checksum and terminator count from the end.
mod field {
    pub const HEADER: usize = 0;
    pub const DATA_START: usize = 1;
    /// Bytes after the data: checksum and terminator.
    pub const TRAILER: usize = 2;
}

/// Why a buffer is not a well-formed message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum FrameError {
    /// Fewer than three bytes (header, checksum, terminator).
    TooShort { len: usize },
    /// The first byte is not a header (`0x80..=0xFE`).
    BadHeader { byte: u8 },
    /// A data or checksum byte has bit 7 set.
    BadDataByte { index: usize, byte: u8 },
    /// The last byte is not the terminator 0xFF.
    MissingTerminator { byte: u8 },
    /// The checksum byte does not match the header and data.
    ChecksumMismatch { expected: u8, got: u8 },
}

/// A read-only or writable view over one complete message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wraps a buffer without checking it; accessors may then panic on short input.
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps a buffer after [`Frame::check`]; accessors cannot panic afterwards.
    pub fn new_checked(buffer: T) -> Result<Self, FrameError> {
        let frame = Self::new_unchecked(buffer);
        frame.check()?;
        Ok(frame)
    }

    /// Validates length, header, data bytes, checksum and terminator.
    pub fn check(&self) -> Result<(), FrameError> {
        let b = self.buffer.as_ref();
        if b.len() < field::DATA_START + field::TRAILER {
            return Err(FrameError::TooShort { len: b.len() });
        }
        let header = b[field::HEADER];
        if !(0x80..TERMINATOR).contains(&header) {
            return Err(FrameError::BadHeader { byte: header });
        }
        let last = b[b.len() - 1];
        if last != TERMINATOR {
            return Err(FrameError::MissingTerminator { byte: last });
        }
        if let Some((index, &byte)) = b[field::DATA_START..b.len() - 1]
            .iter()
            .enumerate()
            .find(|(_, x)| **x >= 0x80)
        {
            return Err(FrameError::BadDataByte {
                index: index + 1,
                byte,
            });
        }
        let expected = checksum(header, self.data());
        let got = self.checksum();
        if expected != got {
            return Err(FrameError::ChecksumMismatch { expected, got });
        }
        Ok(())
    }

    /// The header byte.
    pub fn header(&self) -> u8 {
        self.buffer.as_ref()[field::HEADER]
    }

    /// The data bytes between header and checksum.
    pub fn data(&self) -> &[u8] {
        let b = self.buffer.as_ref();
        &b[field::DATA_START..b.len() - field::TRAILER]
    }

    /// The checksum byte.
    pub fn checksum(&self) -> u8 {
        let b = self.buffer.as_ref();
        b[b.len() - field::TRAILER]
    }

    /// The whole message.
    pub fn as_bytes(&self) -> &[u8] {
        self.buffer.as_ref()
    }

    /// Releases the buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Frame<T> {
    /// Sets the header byte.
    pub fn set_header(&mut self, header: u8) {
        self.buffer.as_mut()[field::HEADER] = header;
    }

    /// The data bytes, writable.
    pub fn data_mut(&mut self) -> &mut [u8] {
        let b = self.buffer.as_mut();
        let end = b.len() - field::TRAILER;
        &mut b[field::DATA_START..end]
    }

    /// Computes and stores the checksum and writes the terminator.
    pub fn fill_checksum(&mut self) {
        let cs = checksum(self.header(), self.data());
        let b = self.buffer.as_mut();
        let n = b.len();
        b[n - 2] = cs;
        b[n - 1] = TERMINATOR;
    }
}

/// A message taken off the wire: header and data, checksum already verified.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawMessage<'a> {
    /// Header byte (`0x80..=0xFE`).
    pub header: u8,
    /// Data bytes (each `0x00..=0x7F`).
    pub data: &'a [u8],
}

impl<'a> RawMessage<'a> {
    /// The data field of a checked frame.
    pub fn from_frame<T: AsRef<[u8]>>(frame: &'a Frame<T>) -> Self {
        Self {
            header: frame.header(),
            data: frame.data(),
        }
    }
}

/// Errors when writing a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub enum EncodeError {
    /// The output buffer is too small for the message.
    BufferTooSmall { needed: usize },
    /// The stream sample lacks a variable that the format enables.
    MissingVariable { number: u8 },
    /// A packed field did not fit its width (a bug in a value type).
    FieldTooWide,
}

/// Writes `header`, the data produced by `fill` (7-bit packed), checksum and
/// terminator into `out`; returns the message length.
pub fn emit_frame<F>(header: u8, out: &mut [u8], fill: F) -> Result<usize, EncodeError>
where
    F: FnOnce(&mut crate::pack::BitWriter<'_>) -> Result<(), EncodeError>,
{
    let Some((head, body)) = out.split_first_mut() else {
        return Err(EncodeError::BufferTooSmall { needed: 3 });
    };
    let Some((area, _)) = body.split_last_chunk_mut::<{ field::TRAILER }>() else {
        return Err(EncodeError::BufferTooSmall { needed: 3 });
    };
    let data_len = {
        let mut w = crate::pack::BitWriter::new(area);
        fill(&mut w)?;
        w.finish().map_err(pack_error)?
    };
    let len = frame_len(data_len);
    *head = header;
    let cs = checksum(header, body.get(..data_len).unwrap_or_default());
    let trailer = body
        .get_mut(data_len..data_len + field::TRAILER)
        .ok_or(EncodeError::BufferTooSmall { needed: len })?;
    trailer.copy_from_slice(&[cs, TERMINATOR]);
    Ok(len)
}

/// Writes a message from already packed data bytes; returns its length.
pub fn emit_raw(header: u8, data: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let len = frame_len(data.len());
    let dst = out
        .get_mut(..len)
        .ok_or(EncodeError::BufferTooSmall { needed: len })?;
    dst[0] = header;
    dst[1..=data.len()].copy_from_slice(data);
    Frame::new_unchecked(dst).fill_checksum();
    Ok(len)
}

pub(crate) fn pack_error(e: crate::pack::PackError) -> EncodeError {
    match e {
        crate::pack::PackError::BufferTooSmall => EncodeError::BufferTooSmall {
            needed: MAX_FRAME_LEN,
        },
        _ => EncodeError::FieldTooWide,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_of_empty_message_is_header_masked() {
        assert_eq!(checksum(0xC0, &[]), 0x40);
        assert_eq!(checksum(0x80, &[]), 0x00);
        assert_eq!(checksum(0xB1, &[]), 0x31);
    }

    #[test]
    fn checked_view_accepts_a_seed_example() {
        let f = Frame::new_checked([0xE8u8, 0x68, 0xFF]).unwrap();
        assert_eq!(f.header(), 0xE8);
        assert!(f.data().is_empty());
    }

    #[test]
    fn checked_view_rejects_bad_input() {
        assert_eq!(
            Frame::new_checked([0xE8u8, 0xFF]).unwrap_err(),
            FrameError::TooShort { len: 2 }
        );
        assert_eq!(
            Frame::new_checked([0x18u8, 0x18, 0xFF]).unwrap_err(),
            FrameError::BadHeader { byte: 0x18 }
        );
        assert_eq!(
            Frame::new_checked([0xE8u8, 0x68, 0x00]).unwrap_err(),
            FrameError::MissingTerminator { byte: 0 }
        );
        assert_eq!(
            Frame::new_checked([0xE8u8, 0x80, 0x68, 0xFF]).unwrap_err(),
            FrameError::BadDataByte {
                index: 1,
                byte: 0x80
            }
        );
        assert_eq!(
            Frame::new_checked([0xB1u8, 0x30, 0xFF]).unwrap_err(),
            FrameError::ChecksumMismatch {
                expected: 0x31,
                got: 0x30
            }
        );
    }

    #[test]
    fn emit_raw_writes_checksum_and_terminator() {
        let mut out = [0u8; 8];
        let n = emit_raw(0xE8, &[0x05], &mut out).unwrap();
        assert_eq!(&out[..n], &[0xE8, 0x05, 0x6D, 0xFF]);
        assert_eq!(
            emit_raw(0xE8, &[0x05], &mut out[..3]),
            Err(EncodeError::BufferTooSmall { needed: 4 })
        );
    }
}
