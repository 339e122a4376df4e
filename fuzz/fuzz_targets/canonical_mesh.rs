//! The session store's mesh blob (`TriMesh::from_canonical_bytes`): whatever it accepts
//! round-trips to the same bytes.
//!
//! The body is `glint_e2e::fuzz_cases::canonical_mesh`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::canonical_mesh(data));
