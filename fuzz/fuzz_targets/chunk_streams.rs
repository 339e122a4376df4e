//! The reassembly of chunked arrays (captures, exposure stacks, refine views): a header list
//! and a chunk sequence, as any client may send them, must assemble or be refused — never
//! panic, never allocate past the stream limit. Input: a u16 length, that many bytes of an
//! `ExposureStackHeader` (its `arrays`), then length-delimited `BytesChunk`s.
//!
//! The body is `glint_e2e::fuzz_cases::chunk_streams`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::chunk_streams(data));
