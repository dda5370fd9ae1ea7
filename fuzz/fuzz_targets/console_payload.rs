//! Feeds arbitrary radio payloads to the car program's console decoders (requests, among them
//! the group command with any registered law and the program start; replies; notices).
//! Whatever decodes must encode again and decode to the same value.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ubc_app::program::console::{Notice, Reply, Request, MAX_PAYLOAD};

fuzz_target!(|data: &[u8]| {
    let Some((&tag, payload)) = data.split_first() else {
        return;
    };
    let mut out = [0u8; MAX_PAYLOAD];
    if let Ok(request) = Request::decode(tag, payload) {
        let n = request.encode(&mut out).expect("decoded requests encode");
        assert_eq!(Request::decode(tag, &out[..n]), Ok(request));
    }
    if let Ok(reply) = Reply::decode(tag, payload) {
        let n = reply.encode(&mut out).expect("decoded replies encode");
        assert_eq!(Reply::decode(tag, &out[..n]), Ok(reply));
    }
    if let Ok(notice) = Notice::decode(payload) {
        let n = notice.encode(&mut out).expect("decoded notices encode");
        assert_eq!(Notice::decode(&out[..n]), Ok(notice));
    }
});
