//! The session store's capture blobs (`GLINTCAP` v1): whatever reads writes back the same.
#![no_main]

use glint_orchestrator::store::capture_file::{from_bytes, to_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(view) = from_bytes(data) {
        let again = to_bytes(&view).expect("a capture read back writes");
        let view_again = from_bytes(&again).expect("a written capture reads");
        assert_eq!(to_bytes(&view_again).expect("writes"), again);
    }
});
