//! What the CLI test files share: running the `glint` binary and reading what it said.

use std::process::{Command, Output};

/// Runs `glint` with `args` and waits for it.
#[allow(dead_code)] // Not every test file runs the CLI.
pub fn glint(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glint"))
        .args(args)
        .output()
        .expect("the glint binary runs")
}

/// Everything the run printed, stdout then stderr.
#[allow(dead_code)]
pub fn printed(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Starts `glint serve <args>` (give `--listen 127.0.0.1:0` for a free port) and waits for the
/// address it prints; killed when dropped.
#[allow(dead_code)] // Not every test file starts servers.
pub fn serve(args: &[&str]) -> glint_server::process::ServerProcess {
    glint_server::process::ServerProcess::spawn(env!("CARGO_BIN_EXE_glint").as_ref(), args)
        .expect("glint serve starts")
}
