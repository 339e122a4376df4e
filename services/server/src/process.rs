//! A Glint server as a child process: `glint serve …` started from a binary, its address read
//! from the first line it prints (`listening on HOST:PORT`). For benchmarks and tests that need
//! real worker processes on loopback; killed when dropped.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

use crate::ServerError;

/// The line a server prints once it listens, before its address.
pub const LISTENING_PREFIX: &str = "listening on ";

/// A running server process and the address it listens on.
pub struct ServerProcess {
    /// The server's process; dropping the [`ServerProcess`] kills it.
    pub child: Child,
    /// HOST:PORT, as the server printed it.
    pub addr: String,
}

impl ServerProcess {
    /// Starts `program serve <args>` (give `--listen 127.0.0.1:0` for a free port) and waits
    /// for the address it prints; lines before it (a camera's scene) are skipped. Its log goes
    /// to the null device.
    pub fn spawn(program: &Path, args: &[&str]) -> Result<Self, ServerError> {
        let what = format!("{} serve {}", program.display(), args.join(" "));
        let failed = |problem: String| ServerError::Unhealthy {
            target: what.clone(),
            problem,
        };
        let mut child = Command::new(program)
            .arg("serve")
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| failed(format!("cannot start: {e}")))?;
        let Some(stdout) = child.stdout.take() else {
            return Err(failed("no standard output".into()));
        };
        let mut process = Self {
            child,
            addr: String::new(),
        };
        for line in BufReader::new(stdout).lines() {
            let line = line.map_err(|e| failed(format!("reading its output: {e}")))?;
            if let Some(addr) = line.trim().strip_prefix(LISTENING_PREFIX) {
                process.addr = addr.to_owned();
                return Ok(process);
            }
        }
        // Dropping `process` kills what is left of it.
        Err(failed(
            "it ended before printing the address it listens on".into(),
        ))
    }

    /// Kills the process (SIGKILL) and reaps it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        self.kill();
    }
}
