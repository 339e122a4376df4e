//! What the CLI test files share: running the `glint` binary and reading what it said.

use std::ffi::OsStr;
use std::process::{Command, Output};

/// Runs `glint` with `args` and waits for it.
#[allow(dead_code)] // Not every test file runs the CLI.
pub fn glint(args: impl IntoIterator<Item = impl AsRef<OsStr>>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_glint"))
        .args(args)
        .output()
        .expect("the glint binary runs")
}

/// The arguments a command line reads as: the words of `line`, each word `{}` replaced by the
/// next of `values` whole (a path may hold spaces). Panics unless every value has its `{}`.
#[allow(dead_code)]
pub fn argv(line: &str, values: &[&str]) -> Vec<String> {
    let mut values = values.iter();
    let args: Vec<String> = line
        .split_whitespace()
        .map(|word| match word {
            "{}" => values.next().expect("a value for every {}").to_string(),
            _ => word.to_owned(),
        })
        .collect();
    assert!(values.next().is_none(), "more values than {{}} in {line:?}");
    args
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
pub fn serve(args: Vec<String>) -> glint_server::process::ServerProcess {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    glint_server::process::ServerProcess::spawn(env!("CARGO_BIN_EXE_glint").as_ref(), &args)
        .expect("glint serve starts")
}
