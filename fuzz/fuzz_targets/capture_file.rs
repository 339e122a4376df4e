//! The session store's capture blobs (`GLINTCAP` v1): whatever reads writes back the same.
//!
//! The body is `glint_e2e::fuzz_cases::capture_file`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::capture_file(data));
