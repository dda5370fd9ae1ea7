//! Feeds arbitrary bytes to the maneuver parameter decoder; whatever decodes must encode to
//! bytes that decode to the same parameters.
#![no_main]

use libfuzzer_sys::fuzz_target;
use maneuvers::ManeuverParams;

fuzz_target!(|data: &[u8]| {
    if let Ok(params) = ManeuverParams::decode(data) {
        let bytes = params.encode().expect("decoded parameters encode");
        assert_eq!(ManeuverParams::decode(&bytes), Ok(params));
    }
});
