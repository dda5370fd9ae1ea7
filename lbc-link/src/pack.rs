//! 7-bit data packing (seed 3.2.2).
//!
//! Message data is a bit stream: fields are written one after another, most
//! significant bit first, and the stream is cut into 7-bit words, each sent as a
//! byte with bit 7 clear. A final word holding `k < 7` bits is "prefixed with
//! zeros": its bits sit right-aligned in the byte (value `0..2^k`). The reader
//! therefore needs the total bit count, which every message type fixes.
//! Unused padding bits are ignored when reading (lenient, and harmless because
//! the length already fixes where the padding is).

/// Number of data bytes needed for `bits` bits of packed fields.
#[must_use]
pub const fn packed_len(bits: usize) -> usize {
    bits.div_ceil(7)
}

/// Errors from [`BitWriter`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PackError {
    /// The output buffer cannot hold the packed words.
    BufferTooSmall,
    /// A field is wider than 32 bits.
    WidthTooLarge { width: u8 },
    /// The value does not fit in the field width.
    ValueTooWide { value: u32, width: u8 },
}

/// Errors from [`BitReader`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UnpackError {
    /// The data has a different number of bytes than the bit count requires.
    LengthMismatch { expected: usize, got: usize },
    /// More bits were read than the stream holds.
    OutOfBits,
    /// A field is wider than 32 bits.
    WidthTooLarge { width: u8 },
}

const fn low_mask(bits: u32) -> u32 {
    if bits >= 32 {
        u32::MAX
    } else {
        (1u32 << bits) - 1
    }
}

/// Writes fields MSB first into 7-bit words.
#[derive(Debug)]
pub struct BitWriter<'a> {
    buf: &'a mut [u8],
    len: usize,
    acc: u64,
    pending: u32,
}

impl<'a> BitWriter<'a> {
    /// A writer filling `buf` from its start.
    pub fn new(buf: &'a mut [u8]) -> Self {
        Self {
            buf,
            len: 0,
            acc: 0,
            pending: 0,
        }
    }

    fn push_word(&mut self, word: u8) -> Result<(), PackError> {
        let slot = self
            .buf
            .get_mut(self.len)
            .ok_or(PackError::BufferTooSmall)?;
        *slot = word & 0x7F;
        self.len += 1;
        Ok(())
    }

    /// Appends the low `width` bits of `value`; `value` must fit in `width` bits.
    pub fn write(&mut self, value: u32, width: u8) -> Result<(), PackError> {
        if width > 32 {
            return Err(PackError::WidthTooLarge { width });
        }
        if value & !low_mask(u32::from(width)) != 0 {
            return Err(PackError::ValueTooWide { value, width });
        }
        self.acc = (self.acc << width) | u64::from(value);
        self.pending += u32::from(width);
        while self.pending >= 7 {
            let word = (self.acc >> (self.pending - 7)) as u8;
            self.push_word(word)?;
            self.pending -= 7;
        }
        self.acc &= u64::from(low_mask(self.pending));
        Ok(())
    }

    /// Appends a signed value as `width`-bit two's complement.
    pub fn write_signed(&mut self, value: i32, width: u8) -> Result<(), PackError> {
        let raw = to_twos(value, width).ok_or(PackError::ValueTooWide {
            value: value as u32,
            width,
        })?;
        self.write(raw, width)
    }

    /// Flushes a final partial word (right-aligned) and returns the bytes written.
    pub fn finish(mut self) -> Result<usize, PackError> {
        if self.pending > 0 {
            let word = self.acc as u8;
            self.push_word(word)?;
        }
        Ok(self.len)
    }
}

/// Reads fields MSB first from 7-bit words holding exactly `total_bits` bits.
#[derive(Debug, Clone)]
pub struct BitReader<'a> {
    data: &'a [u8],
    total_bits: usize,
    pos: usize,
}

impl<'a> BitReader<'a> {
    /// A reader over `data`, which must be exactly `packed_len(total_bits)` bytes.
    pub fn new(data: &'a [u8], total_bits: usize) -> Result<Self, UnpackError> {
        let expected = packed_len(total_bits);
        if data.len() != expected {
            return Err(UnpackError::LengthMismatch {
                expected,
                got: data.len(),
            });
        }
        Ok(Self {
            data,
            total_bits,
            pos: 0,
        })
    }

    /// Bits not read yet.
    #[must_use]
    pub fn remaining(&self) -> usize {
        self.total_bits - self.pos
    }

    /// Reads the next `width` bits as an unsigned value.
    pub fn read(&mut self, width: u8) -> Result<u32, UnpackError> {
        if width > 32 {
            return Err(UnpackError::WidthTooLarge { width });
        }
        let width = usize::from(width);
        if width > self.remaining() {
            return Err(UnpackError::OutOfBits);
        }
        let last = self.data.len().saturating_sub(1);
        let tail = self.total_bits % 7;
        let mut value: u32 = 0;
        let mut need = width;
        while need > 0 {
            let index = self.pos / 7;
            let offset = self.pos % 7;
            let byte = self
                .data
                .get(index)
                .copied()
                .ok_or(UnpackError::OutOfBits)?;
            let word_bits = if index == last && tail != 0 { tail } else { 7 };
            let word = u32::from(byte) & low_mask(word_bits as u32);
            let avail = word_bits - offset;
            let take = avail.min(need);
            let chunk = (word >> (avail - take)) & low_mask(take as u32);
            value = value.checked_shl(take as u32).unwrap_or(0) | chunk;
            need -= take;
            self.pos += take;
        }
        Ok(value)
    }

    /// Reads the next `width` bits as two's complement.
    pub fn read_signed(&mut self, width: u8) -> Result<i32, UnpackError> {
        let raw = self.read(width)?;
        Ok(sign_extend(raw, width))
    }
}

/// Interprets the low `width` bits of `raw` as two's complement.
#[must_use]
pub const fn sign_extend(raw: u32, width: u8) -> i32 {
    if width == 0 {
        return 0;
    }
    if width >= 32 {
        return raw as i32;
    }
    let shift = 32 - width as u32;
    ((raw << shift) as i32) >> shift
}

/// Encodes `value` as `width`-bit two's complement, or `None` if it does not fit.
#[must_use]
pub const fn to_twos(value: i32, width: u8) -> Option<u32> {
    if width == 0 || width > 32 {
        return None;
    }
    if width == 32 {
        return Some(value as u32);
    }
    let min = -(1i64 << (width - 1));
    let max = (1i64 << (width - 1)) - 1;
    let v = value as i64;
    if v < min || v > max {
        return None;
    }
    Some((value as u32) & low_mask(width as u32))
}

/// Packs `(value, width)` fields into `out`; returns the number of data bytes.
pub fn pack(fields: &[(u32, u8)], out: &mut [u8]) -> Result<usize, PackError> {
    let mut w = BitWriter::new(out);
    for &(value, width) in fields {
        w.write(value, width)?;
    }
    w.finish()
}

/// Unpacks fields of the given widths; `data` must hold exactly their sum.
pub fn unpack<const N: usize>(data: &[u8], widths: &[u8; N]) -> Result<[u32; N], UnpackError> {
    let mut out = [0u32; N];
    unpack_into(data, widths, &mut out)?;
    Ok(out)
}

/// [`unpack`] into `out` (one value per width), for any number of fields.
pub fn unpack_into(data: &[u8], widths: &[u8], out: &mut [u32]) -> Result<(), UnpackError> {
    let total: usize = widths.iter().map(|&w| usize::from(w)).sum();
    let mut r = BitReader::new(data, total)?;
    for (slot, &width) in out.iter_mut().zip(widths) {
        *slot = r.read(width)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn two_14_bit_fields_fill_four_words() {
        // X = 320 = 0b00000101000000, Y = 480 = 0b00000111100000
        let mut buf = [0u8; 4];
        let n = pack(&[(320, 14), (480, 14)], &mut buf).unwrap();
        assert_eq!(n, 4);
        assert_eq!(buf, [0x02, 0x40, 0x03, 0x60]);
        assert_eq!(unpack(&buf, &[14, 14]).unwrap(), [320, 480]);
    }

    #[test]
    fn final_partial_word_is_right_aligned() {
        // 7-bit address 0x21 then 16-bit 0xBEEF: 23 bits, last word carries 2 bits.
        let mut buf = [0u8; 4];
        let n = pack(&[(0x21, 7), (0xBEEF, 16)], &mut buf).unwrap();
        assert_eq!(n, 4);
        // 1011111 0111011 11 -> 0x5F, 0x3B, 0b11
        assert_eq!(buf, [0x21, 0x5F, 0x3B, 0x03]);
        assert_eq!(unpack(&buf, &[7, 16]).unwrap(), [0x21, 0xBEEF]);
    }

    #[test]
    fn two_single_bits_share_one_word() {
        let mut buf = [0u8; 1];
        pack(&[(1, 1), (0, 1)], &mut buf).unwrap();
        assert_eq!(buf, [0b10]);
    }

    #[test]
    fn padding_bits_are_ignored() {
        assert_eq!(unpack(&[0x7E], &[1, 1]).unwrap(), [1, 0]);
    }

    #[test]
    fn wrong_length_is_an_error() {
        assert_eq!(
            unpack(&[0, 0, 0], &[14, 14]),
            Err(UnpackError::LengthMismatch {
                expected: 4,
                got: 3
            })
        );
    }

    #[test]
    fn value_wider_than_field_is_rejected() {
        let mut buf = [0u8; 4];
        assert_eq!(
            pack(&[(1 << 14, 14)], &mut buf),
            Err(PackError::ValueTooWide {
                value: 1 << 14,
                width: 14
            })
        );
    }

    #[test]
    fn small_buffer_is_rejected() {
        let mut buf = [0u8; 1];
        assert_eq!(pack(&[(0, 14)], &mut buf), Err(PackError::BufferTooSmall));
    }

    #[test]
    fn signed_14_bit() {
        assert_eq!(to_twos(-1, 14), Some(0x3FFF));
        assert_eq!(to_twos(-8192, 14), Some(0x2000));
        assert_eq!(to_twos(8192, 14), None);
        assert_eq!(sign_extend(0x3FFF, 14), -1);
        assert_eq!(sign_extend(0x1FFF, 14), 8191);
    }

    proptest! {
        #[test]
        fn pack_unpack_round_trip(fields in proptest::collection::vec((any::<u32>(), 1u8..=32), 0..12)) {
            let fields: std::vec::Vec<(u32, u8)> = fields
                .into_iter()
                .map(|(v, w)| (v & low_mask(u32::from(w)), w))
                .collect();
            let total: usize = fields.iter().map(|f| usize::from(f.1)).sum();
            let mut buf = [0u8; 64];
            let n = pack(&fields, &mut buf).unwrap();
            prop_assert_eq!(n, packed_len(total));
            prop_assert!(buf[..n].iter().all(|b| *b < 0x80));
            let mut r = BitReader::new(&buf[..n], total).unwrap();
            for (v, w) in &fields {
                prop_assert_eq!(r.read(*w).unwrap(), *v);
            }
            prop_assert_eq!(r.remaining(), 0);
        }

        #[test]
        fn signed_round_trip(v in -8192i32..=8191) {
            prop_assert_eq!(sign_extend(to_twos(v, 14).unwrap(), 14), v);
        }
    }
}
