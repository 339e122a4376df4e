//! What the CLI test files share: running the `glint` binary and reading what it said.

use std::process::{Command, Output};

/// Runs `glint` with `args` and waits for it.
pub fn glint(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glint"))
        .args(args)
        .output()
        .expect("the glint binary runs")
}

/// Everything the run printed, stdout then stderr.
pub fn printed(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}
