//! Untrusted bytes never break the emulated LBC: whatever arrives, it keeps answering.

mod common;

use common::Bench;
use lbc_emu::LbcConfig;
use lbc_link::{Command, Reply, VehicleId};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn any_bytes_then_a_command_gets_its_reply(
        chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 0..6)
    ) {
        let mut b = Bench::new(LbcConfig::default());
        for c in &chunks {
            let _ = b.raw_exchange(c, 3_000);
        }
        // Calibrations or EEPROM jobs the noise may have started finish within 2 s.
        let _ = b.raw_exchange(&[], 2_000_000);
        prop_assert_eq!(
            b.request(Command::ReadId),
            Ok(Reply::ReadId(VehicleId::new(7).unwrap()))
        );
    }
}
