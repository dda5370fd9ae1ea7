//! Detection of a fixed byte sequence in a stream that arrives in arbitrary pieces, such as
//! the test mode's panic request.

use heapless::HistoryBuf;

/// Longest sequence a [`SequenceDetector`] can watch for.
pub const MAX_SEQUENCE: usize = 16;

/// Watches a byte stream for `sequence`, remembering the last bytes across calls.
#[derive(Debug)]
pub struct SequenceDetector {
    sequence: &'static [u8],
    recent: HistoryBuf<u8, MAX_SEQUENCE>,
}

impl SequenceDetector {
    /// A detector for `sequence` (at most [`MAX_SEQUENCE`] bytes; longer ones never match).
    pub fn new(sequence: &'static [u8]) -> Self {
        Self {
            sequence,
            recent: HistoryBuf::new(),
        }
    }

    /// Feeds one byte; true when it completes the sequence.
    pub fn push(&mut self, byte: u8) -> bool {
        self.recent.write(byte);
        let n = self.sequence.len();
        if n == 0 || n > MAX_SEQUENCE || self.recent.len() < n {
            return false;
        }
        self.recent
            .oldest_ordered()
            .skip(self.recent.len() - n)
            .eq(self.sequence.iter())
    }

    /// Feeds `bytes`; returns the index of the byte that completes the sequence, if any.
    /// Bytes after that index are not consumed.
    pub fn find(&mut self, bytes: &[u8]) -> Option<usize> {
        bytes.iter().position(|&b| self.push(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const MAGIC: &[u8] = b"!ubc-panic!";

    #[test]
    fn finds_sequence_in_one_piece() {
        let mut d = SequenceDetector::new(MAGIC);
        assert_eq!(d.find(b"before!ubc-panic!after"), Some(16));
    }

    #[test]
    fn finds_sequence_split_across_pieces() {
        let mut d = SequenceDetector::new(MAGIC);
        assert_eq!(d.find(b"xx!ubc-"), None);
        assert_eq!(d.find(b"pan"), None);
        assert_eq!(d.find(b"ic!"), Some(2));
    }

    #[test]
    fn overlapping_start_still_matches() {
        let mut d = SequenceDetector::new(MAGIC);
        assert_eq!(d.find(b"!!ubc-panic!"), Some(11));
        let mut d = SequenceDetector::new(MAGIC);
        assert_eq!(d.find(b"!ubc-panic!ubc-panic!"), Some(10));
    }

    #[test]
    fn near_misses_do_not_match() {
        let mut d = SequenceDetector::new(MAGIC);
        assert_eq!(d.find(b"!ubc-panic?!ubc-panix!ubc_panic!UBC-PANIC!x"), None);
        assert_eq!(
            d.find(b"ubc-panic!"),
            None,
            "the missing '!' must not be remembered"
        );
    }

    #[test]
    fn degenerate_sequences_never_match() {
        let mut d = SequenceDetector::new(b"");
        assert_eq!(d.find(b"anything"), None);
        let mut d = SequenceDetector::new(&[0u8; MAX_SEQUENCE + 1]);
        assert_eq!(d.find(&[0u8; 64]), None);
    }

    proptest! {
        #[test]
        fn matches_exactly_where_the_stream_first_ends_with_it(
            stream in prop::collection::vec(prop::sample::select(b"!ubc-panix".to_vec()), 0..400),
            cut in 0usize..400,
        ) {
            let first = (MAGIC.len()..=stream.len())
                .find(|&end| &stream[end - MAGIC.len()..end] == MAGIC)
                .map(|end| end - 1);
            let cut = cut.min(stream.len());
            let mut d = SequenceDetector::new(MAGIC);
            let got = match d.find(&stream[..cut]) {
                Some(i) => Some(i),
                None => d.find(&stream[cut..]).map(|i| i + cut),
            };
            prop_assert_eq!(got, first);
        }
    }
}
