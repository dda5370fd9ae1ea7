//! Feeds arbitrary bytes to the frame-grabber header parser; a header that parses must emit
//! bytes that parse to the same header.
#![no_main]

use libfuzzer_sys::fuzz_target;
use vision::frame::{HeaderRepr, HEADER_LEN};

fuzz_target!(|data: &[u8]| {
    if let Ok(header) = HeaderRepr::parse(data) {
        let mut out = [0u8; HEADER_LEN];
        header.emit(&mut out).expect("parsed headers emit");
        assert_eq!(HeaderRepr::parse(&out), Ok(header));
    }
});
