//! The dataset readers: Glint's rig, exposure-stack, reference-surface and camera files, the
//! BOP scene files (scene_camera, scene_gt, scene_gt_info, models_info) and ROBI's (object
//! poses, view list, camera yml). The first byte picks the file; the rest is written where the
//! reader looks for it (beside valid files for the others), and the reader runs on the folder.
//!
//! The body is `glint_e2e::fuzz_cases::dataset_files`, which `cargo test` also runs on this target's
//! kept corpus (`tests/tests/fuzz_corpus.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| glint_e2e::fuzz_cases::dataset_files(data));
