//! The PLY, OBJ and STL readers (`glint mesh`, `RegisterObject`'s and `Refine`'s mesh files,
//! BOP models): the first byte picks the format, the rest is the file.
//!
//! The body is `glint_e2e::fuzz_cases::mesh_files`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::mesh_files(data));
