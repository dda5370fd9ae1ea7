//! Feeds arbitrary text to the `key=value` parser of every registered law (the command line's
//! `group start LAW key=value ...`, the experiment files): whatever parses must encode to a
//! group command body that decodes to the same parameters.
#![no_main]

use libfuzzer_sys::fuzz_target;
use maneuvers::params::MAX_LEN;
use maneuvers::{ManeuverParams, LAWS};

fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let law = &LAWS[usize::from(pick) % LAWS.len()];
    let args: Vec<&str> = text.split_whitespace().collect();
    match law.parse(&args) {
        Ok(params) => {
            assert_eq!(params.law(), law.id);
            let mut out = [0u8; MAX_LEN];
            let n = params.encode(&mut out).expect("parsed parameters encode");
            assert_eq!(ManeuverParams::decode(&out[..n]), Ok(params));
        }
        Err(e) => assert!(!e.to_string().is_empty()),
    }
});
