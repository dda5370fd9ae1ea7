//! Feeds arbitrary bytes to the group command body decoder (law ID, options, the law's
//! parameters from the registration list); whatever decodes must encode to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use maneuvers::params::MAX_LEN;
use maneuvers::ManeuverParams;

fuzz_target!(|data: &[u8]| {
    if let Ok(params) = ManeuverParams::decode(data) {
        let mut out = [0u8; MAX_LEN];
        let n = params.encode(&mut out).expect("decoded parameters encode");
        assert_eq!(&out[..n], data);
        assert_eq!(ManeuverParams::decode(&out[..n]), Ok(params));
        // Every decoded law can be started.
        let mut c = maneuvers::Controller::new(maneuvers::ControllerConfig::default());
        c.start(params);
        assert_eq!(c.law().map_or(0, maneuvers::AnyLaw::id), params.law());
    }
});
