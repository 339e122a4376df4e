//! The calibration files Glint reads: the camera response (`glint calibrate response`) and the
//! fitted material (`glint calibrate bsdf`). The first byte picks the file.
//!
//! The body is `glint_e2e::fuzz_cases::calibration_files`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::calibration_files(data));
