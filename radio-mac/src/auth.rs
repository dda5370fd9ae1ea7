//! Authentication of ground-station commands: SipHash-2-4 keyed MAC and replay guard.
//!
//! The tag is SipHash-2-4 (64-bit output) under the testbed's 128-bit key, over the raw
//! frame from the header byte to the end of the payload, so the counter, destination, tag
//! and payload are all covered. The key is provisioned in the LBC EEPROM user registers
//! 0x38..=0x3F (eight 16-bit words, register 0x38 holds key bytes 0 and 1, low byte first)
//! and never sent on air.

use crate::wire::{EncodeError, Frame, Writer, AUTH_TAG_LEN, CRC_LEN};

/// First EEPROM user register holding the key.
pub const KEY_EEPROM_FIRST: u8 = 0x38;
/// Last EEPROM user register holding the key.
pub const KEY_EEPROM_LAST: u8 = 0x3F;

/// The testbed's 128-bit command key.
#[derive(Clone, PartialEq, Eq)]
pub struct Key([u8; 16]);

impl core::fmt::Debug for Key {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Key(..)")
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Key {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "Key(..)")
    }
}

impl Key {
    /// A key from 16 bytes.
    pub const fn new(bytes: [u8; 16]) -> Self {
        Self(bytes)
    }

    /// A key from EEPROM registers 0x38..=0x3F, in register order.
    pub fn from_eeprom_words(words: [u16; 8]) -> Self {
        let mut b = [0u8; 16];
        for (chunk, w) in b.chunks_exact_mut(2).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        Self(b)
    }

    /// The eight words to store in EEPROM registers 0x38..=0x3F.
    pub fn to_eeprom_words(&self) -> [u16; 8] {
        let mut w = [0u16; 8];
        for (i, c) in self.0.chunks_exact(2).enumerate() {
            w[i] = u16::from_le_bytes([c[0], c[1]]);
        }
        w
    }

    /// SipHash-2-4 of `data` under this key, little-endian.
    pub fn tag(&self, data: &[u8]) -> [u8; AUTH_TAG_LEN] {
        siphash24(&self.0, data).to_le_bytes()
    }
}

/// SipHash-2-4 (Aumasson and Bernstein) with a 64-bit output. Written with one round in a
/// loop rather than with the `siphasher` crate, whose eight unrolled rounds of 64-bit
/// arithmetic are about 1.1 KB more code on a 32-bit core.
fn siphash24(key: &[u8; 16], data: &[u8]) -> u64 {
    let k0 = le_u64(&key[..8]);
    let k1 = le_u64(&key[8..]);
    let mut v = [
        k0 ^ 0x736f_6d65_7073_6575,
        k1 ^ 0x646f_7261_6e64_6f6d,
        k0 ^ 0x6c79_6765_6e65_7261,
        k1 ^ 0x7465_6462_7974_6573,
    ];
    let mut blocks = data.chunks_exact(8);
    for block in &mut blocks {
        sip_compress(&mut v, le_u64(block));
    }
    // The last block: the bytes left over, and the message length (mod 256) in the top byte.
    let rest = blocks.remainder();
    let mut last = [0u8; 8];
    last[..rest.len()].copy_from_slice(rest);
    last[7] = data.len() as u8;
    sip_compress(&mut v, u64::from_le_bytes(last));
    v[2] ^= 0xff;
    sip_rounds(&mut v, 4);
    v[0] ^ v[1] ^ v[2] ^ v[3]
}

/// The little-endian word of 8 bytes.
fn le_u64(bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .rev()
        .fold(0, |word, &b| word << 8 | u64::from(b))
}

/// One message block through the two compression rounds.
fn sip_compress(v: &mut [u64; 4], m: u64) {
    v[3] ^= m;
    sip_rounds(v, 2);
    v[0] ^= m;
}

// Out of line: one copy of the round, not one per use (204 bytes).
#[cfg_attr(target_arch = "riscv32", inline(never))]
fn sip_rounds(v: &mut [u64; 4], rounds: u32) {
    for _ in 0..rounds {
        v[0] = v[0].wrapping_add(v[1]);
        v[1] = v[1].rotate_left(13) ^ v[0];
        v[0] = v[0].rotate_left(32);
        v[2] = v[2].wrapping_add(v[3]);
        v[3] = v[3].rotate_left(16) ^ v[2];
        v[0] = v[0].wrapping_add(v[3]);
        v[3] = v[3].rotate_left(21) ^ v[0];
        v[2] = v[2].wrapping_add(v[1]);
        v[1] = v[1].rotate_left(17) ^ v[2];
        v[2] = v[2].rotate_left(32);
    }
}

/// Tag of an authenticated frame (its own `mac` field is ignored): SipHash-2-4 over the raw
/// frame from the header to the field before the tag; for an [`Frame::AuthCommand`] the
/// ground station's session `epoch` (u32, little-endian) follows, so that a command is bound
/// to one session without carrying the epoch on air. `None` for kinds without a tag.
pub fn frame_tag(
    key: &Key,
    epoch: u32,
    frame: &Frame,
) -> Result<Option<[u8; AUTH_TAG_LEN]>, EncodeError> {
    let bound = match frame {
        Frame::AuthCommand { .. } => true,
        Frame::GroundBeat { .. } | Frame::Hello { .. } | Frame::SessionOpen { .. } => false,
        _ => return Ok(None),
    };
    let mut w = Writer::new();
    frame.emit_into(&mut w)?;
    let (raw, n) = (&mut w.buf, w.pos);
    let mut end = n.saturating_sub(AUTH_TAG_LEN + CRC_LEN);
    if bound {
        raw.get_mut(end..end + 4)
            .ok_or(EncodeError::BufferTooSmall)?
            .copy_from_slice(&epoch.to_le_bytes());
        end += 4;
    }
    let covered = raw.get(..end).ok_or(EncodeError::BufferTooSmall)?;
    Ok(Some(key.tag(covered)))
}

/// Set the `mac` field of an authenticated frame (`epoch`: see [`frame_tag`]).
pub fn sign(key: &Key, epoch: u32, frame: &mut Frame) -> Result<(), EncodeError> {
    if let Some(t) = frame_tag(key, epoch, frame)? {
        if let Frame::AuthCommand { mac, .. }
        | Frame::GroundBeat { mac, .. }
        | Frame::Hello { mac, .. }
        | Frame::SessionOpen { mac, .. } = frame
        {
            *mac = t;
        }
    }
    Ok(())
}

/// Check the `mac` field of an authenticated frame in constant time (`epoch`: see
/// [`frame_tag`]).
pub fn verify(key: &Key, epoch: u32, frame: &Frame) -> bool {
    let mac = match frame {
        Frame::AuthCommand { mac, .. }
        | Frame::GroundBeat { mac, .. }
        | Frame::Hello { mac, .. }
        | Frame::SessionOpen { mac, .. } => mac,
        _ => return false,
    };
    match frame_tag(key, epoch, frame) {
        Ok(Some(t)) => {
            t.iter()
                .zip(mac.iter())
                .fold(0u8, |acc, (a, b)| acc | (a ^ b))
                == 0
        }
        _ => false,
    }
}

/// Verdict of the replay guard on a counter whose MAC was valid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Freshness {
    /// Higher than any accepted counter: execute.
    Fresh,
    /// Equal to the last accepted counter: a retransmission; answer again, do not execute.
    Repeat,
    /// Lower than the last accepted counter: a replay; reject.
    Replay,
}

/// Highest accepted command counter. Persist [`ReplayGuard::last`] (e.g. in EEPROM) to keep
/// replay protection across restarts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReplayGuard {
    last: Option<u32>,
}

impl ReplayGuard {
    /// A guard that accepts any first counter.
    pub const fn new() -> Self {
        Self { last: None }
    }

    /// A guard restored from a persisted counter.
    pub const fn restore(last: u32) -> Self {
        Self { last: Some(last) }
    }

    /// Highest accepted counter.
    pub const fn last(&self) -> Option<u32> {
        self.last
    }

    /// Classify `counter` without accepting it.
    pub fn check(&self, counter: u32) -> Freshness {
        match self.last {
            None => Freshness::Fresh,
            Some(l) if counter > l => Freshness::Fresh,
            Some(l) if counter == l => Freshness::Repeat,
            Some(_) => Freshness::Replay,
        }
    }

    /// Record `counter` as executed.
    pub fn accept(&mut self, counter: u32) {
        self.last = Some(counter);
    }

    /// A guard that accepts counters from `min` on (everything below is a replay).
    pub const fn from_min(min: u32) -> Self {
        match min.checked_sub(1) {
            Some(last) => Self::restore(last),
            None => Self::new(),
        }
    }

    /// The stricter of two guards (the higher last counter).
    pub fn max(self, other: Self) -> Self {
        if other.last > self.last {
            other
        } else {
            self
        }
    }
}

/// A car's session with its ground station: the station's epoch and the counters accepted in
/// it. A car has none after a restart until the ground station answers its
/// [`Frame::Hello`], so nothing recorded before the restart is accepted after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Session {
    /// The ground station's epoch (part of every command's MAC, sent in its heartbeats).
    pub epoch: u32,
    /// Command counters.
    pub commands: ReplayGuard,
    /// Heartbeat counters.
    pub beats: ReplayGuard,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::addr::{Address, CarId};
    use crate::wire::Payload;

    /// SipHash-2-4 reference vector (64-bit output, key 00..0f, empty message): 0x726fdb47dd0e0e31.
    #[test]
    fn siphash_reference_vector() {
        let mut k = [0u8; 16];
        for (i, b) in k.iter_mut().enumerate() {
            *b = i as u8;
        }
        let key = Key::new(k);
        assert_eq!(u64::from_le_bytes(key.tag(&[])), 0x726f_db47_dd0e_0e31);
        let mut msg = [0u8; 15];
        for (i, b) in msg.iter_mut().enumerate() {
            *b = i as u8;
        }
        assert_eq!(u64::from_le_bytes(key.tag(&msg)), 0xa129_ca61_49be_45e5);
    }

    proptest::proptest! {
        #[test]
        fn siphash_matches_the_reference_crate(
            key in proptest::prelude::any::<[u8; 16]>(),
            data in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..80),
        ) {
            use core::hash::Hasher;
            let mut h = siphasher::sip::SipHasher24::new_with_key(&key);
            h.write(&data);
            proptest::prop_assert_eq!(Key::new(key).tag(&data), h.finish().to_le_bytes());
        }

        #[test]
        fn eeprom_words_encode_decode(bytes in proptest::prelude::any::<[u8; 16]>()) {
            let key = Key::new(bytes);
            proptest::prop_assert_eq!(Key::from_eeprom_words(key.to_eeprom_words()), key);
        }
    }

    #[test]
    fn eeprom_words_round_trip() {
        let key = Key::new(*b"0123456789abcdef");
        let w = key.to_eeprom_words();
        assert_eq!(w[0], u16::from_le_bytes(*b"01"));
        assert_eq!(Key::from_eeprom_words(w), key);
    }

    fn cmd(counter: u32) -> Frame {
        Frame::AuthCommand {
            dst: Address::Car(CarId::new(4).unwrap()),
            counter,
            tag: 1,
            payload: Payload::from_slice(&[9, 9]).unwrap(),
            mac: [0; 8],
        }
    }

    #[test]
    fn sign_verify_and_tamper() {
        let key = Key::new([7; 16]);
        let mut f = cmd(10);
        sign(&key, 3, &mut f).unwrap();
        assert!(verify(&key, 3, &f));
        assert!(!verify(&key, 4, &f), "bound to the session epoch");
        assert!(!verify(&Key::new([8; 16]), 3, &f));
        if let Frame::AuthCommand {
            counter, payload, ..
        } = &mut f
        {
            *counter = 11;
            assert!(!verify(&key, 3, &cmd(11)));
            *counter = 10;
            payload[0] = 8;
        }
        assert!(!verify(&key, 3, &f));
    }

    #[test]
    fn replay_guard() {
        let mut g = ReplayGuard::new();
        assert_eq!(g.check(5), Freshness::Fresh);
        g.accept(5);
        assert_eq!(g.check(5), Freshness::Repeat);
        assert_eq!(g.check(4), Freshness::Replay);
        assert_eq!(g.check(6), Freshness::Fresh);
        assert_eq!(ReplayGuard::restore(9).check(9), Freshness::Repeat);
    }
}
