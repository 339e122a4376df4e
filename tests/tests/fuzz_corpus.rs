//! Every input the fuzzers keep (`fuzz/corpus/TARGET/`: the seeds of `fuzz/make_seeds.py` and
//! the minimised corpus of the last runs, crashes found among them) through its target's body,
//! on every `cargo test`: what fuzzing explored stays free of panics without a nightly
//! toolchain.

use std::path::Path;

use glint_e2e::fuzz_cases::TARGETS;

#[test]
fn every_kept_fuzz_input_runs_without_a_panic() {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz/corpus");
    for (name, body) in TARGETS {
        let dir = corpus.join(name);
        let mut inputs: Vec<_> = std::fs::read_dir(&dir)
            .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
            .map(|entry| entry.unwrap().path())
            .collect();
        inputs.sort();
        assert!(!inputs.is_empty(), "{}: no inputs kept", dir.display());
        for input in inputs {
            let data = std::fs::read(&input).unwrap();
            let outcome = std::panic::catch_unwind(|| body(&data));
            assert!(outcome.is_ok(), "{name}: {} panicked", input.display());
        }
    }
}
