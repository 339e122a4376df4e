//! Every RPC request's proto → core conversion, as the servers run it before any work: the
//! first byte picks the message, the rest is its protobuf encoding. Decoding may fail (that is
//! tonic's job to answer); a message that decodes must be converted or refused, never panic.
//!
//! The body is `glint_e2e::fuzz_cases::rpc_requests`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::rpc_requests(data));
