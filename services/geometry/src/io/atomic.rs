//! Crash-safe output files: every file Glint writes goes through [`write_atomically`].
//!
//! The contents go to a temporary file in the destination's directory, which is flushed to
//! disk and then renamed over the destination. A rename within one directory is atomic, so a
//! reader (or a rerun after a crash) sees either the old file or the complete new one, never a
//! half-written one; on any failure the temporary file is removed.

use std::ffi::OsString;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Why an output file could not be written. The destination is unchanged.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {step}", path.display())]
pub struct AtomicWriteError {
    /// The destination file.
    pub path: PathBuf,
    /// What went wrong, in words.
    pub step: String,
    /// The I/O error behind the failure.
    #[source]
    pub source: io::Error,
}

/// Writes the file at `path` with whatever `write_contents` writes, atomically (see the module
/// doc). The writer handed to `write_contents` is buffered. The directory must exist: a missing
/// directory is more often a typo than a wish to create it.
pub fn write_atomically<F>(path: &Path, write_contents: F) -> Result<(), AtomicWriteError>
where
    F: FnOnce(&mut dyn Write) -> io::Result<()>,
{
    let failed = |step: String| {
        move |source: io::Error| AtomicWriteError {
            path: path.to_owned(),
            step,
            source,
        }
    };
    let Some(file_name) = path.file_name() else {
        return Err(failed("the path does not name a file".to_owned())(
            io::Error::from(io::ErrorKind::InvalidInput),
        ));
    };
    let directory = match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent,
        _ => Path::new("."),
    };
    match fs::metadata(directory) {
        Ok(metadata) if metadata.is_dir() => {}
        Ok(_) => {
            return Err(failed(format!(
                "{} is not a directory",
                directory.display()
            ))(io::Error::from(
                io::ErrorKind::NotADirectory,
            )));
        }
        Err(e) => {
            return Err(failed(format!(
                "directory {} does not exist",
                directory.display()
            ))(e));
        }
    }

    let (temporary, file) = create_temporary_file(directory, file_name).map_err(failed(
        format!("cannot create a temporary file in {}", directory.display()),
    ))?;
    let mut writer = BufWriter::new(file);
    write_contents(&mut writer).map_err(failed("writing the contents failed".to_owned()))?;
    let file = writer
        .into_inner()
        .map_err(|e| failed("writing the contents failed".to_owned())(e.into_error()))?;
    // Without the fsync, a crash soon after the rename can leave an empty file behind the new
    // name on some file systems (ext4 with delayed allocation, for one).
    file.sync_all()
        .map_err(failed("flushing the contents to disk failed".to_owned()))?;
    drop(file);
    fs::rename(temporary.path(), path).map_err(failed(format!(
        "cannot rename the temporary file {} onto it",
        temporary.path().display()
    )))?;
    temporary.keep();
    sync_directory(directory);
    Ok(())
}

/// Writes `bytes` to `path` atomically: [`write_atomically`] for contents already in memory.
pub fn write_file_atomically(path: &Path, bytes: &[u8]) -> Result<(), AtomicWriteError> {
    write_atomically(path, |w| w.write_all(bytes))
}

/// Distinguishes the temporary files of concurrent writes from one process.
static TEMPORARY_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Tries this many names before giving up on creating a temporary file.
const TEMPORARY_NAME_ATTEMPTS: u32 = 64;

/// Creates `.<file name>.<pid>-<n>.tmp` beside the destination: hidden, unique to this process
/// and write, and in the same directory so that the final rename cannot cross file systems.
fn create_temporary_file(
    directory: &Path,
    file_name: &std::ffi::OsStr,
) -> io::Result<(TemporaryFile, File)> {
    let mut last_error = io::Error::from(io::ErrorKind::AlreadyExists);
    for _ in 0..TEMPORARY_NAME_ATTEMPTS {
        let n = TEMPORARY_COUNTER.fetch_add(1, Ordering::Relaxed);
        let mut name = OsString::from(".");
        name.push(file_name);
        name.push(format!(".{}-{n}.tmp", std::process::id()));
        let path = directory.join(name);
        match OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(file) => return Ok((TemporaryFile { path: Some(path) }, file)),
            // A leftover from a crashed run with a recycled pid: try the next name.
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last_error = e,
            Err(e) => return Err(e),
        }
    }
    Err(last_error)
}

/// A temporary file that is deleted when dropped, unless [`TemporaryFile::keep`] is called
/// (after it was renamed into place). Dropping also runs while a panicking `write_contents`
/// unwinds, so a panic leaves nothing behind either.
struct TemporaryFile {
    path: Option<PathBuf>,
}

impl TemporaryFile {
    fn path(&self) -> &Path {
        self.path.as_deref().unwrap_or(Path::new(""))
    }

    fn keep(mut self) {
        self.path = None;
    }
}

impl Drop for TemporaryFile {
    fn drop(&mut self) {
        if let Some(path) = self.path.take() {
            // Nothing useful can be done if this fails: the original error is what matters.
            let _ = fs::remove_file(path);
        }
    }
}

/// Makes the rename itself durable. Best effort: some file systems refuse to fsync a directory,
/// and the new contents are already safe on disk either way.
fn sync_directory(directory: &Path) {
    #[cfg(unix)]
    if let Ok(dir) = File::open(directory) {
        let _ = dir.sync_all();
    }
    #[cfg(not(unix))]
    let _ = directory;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_successful_write_leaves_only_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.txt");
        write_file_atomically(&path, b"first").unwrap();
        write_atomically(&path, |w| w.write_all(b"second, longer")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second, longer");
        assert_eq!(entries(dir.path()), vec!["out.txt"]);
    }

    #[test]
    fn a_missing_directory_is_a_clear_error_and_creates_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no-such-dir");
        let path = missing.join("out.ply");
        let err = write_file_atomically(&path, b"data").unwrap_err();
        assert_eq!(err.source.kind(), io::ErrorKind::NotFound);
        let message = err.to_string();
        assert!(message.contains("out.ply"), "{message}");
        assert!(
            message.contains("no-such-dir") && message.contains("does not exist"),
            "{message}"
        );
        assert!(!missing.exists());
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("keep.txt");
        fs::write(&path, b"old").unwrap();
        let err = write_atomically(&path, |w| {
            w.write_all(b"half of the new cont")?;
            Err(io::Error::other("the encoder gave up"))
        })
        .unwrap_err();
        assert!(err.to_string().contains("keep.txt"));
        assert_eq!(err.source.to_string(), "the encoder gave up");
        assert_eq!(fs::read(&path).unwrap(), b"old");
        assert_eq!(entries(dir.path()), vec!["keep.txt"]);
    }

    #[test]
    fn a_panicking_writer_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("panic.txt");
        let result = std::panic::catch_unwind(|| {
            let _ = write_atomically(&path, |_| panic!("writer bug"));
        });
        assert!(result.is_err());
        assert!(entries(dir.path()).is_empty());
    }

    #[test]
    fn a_directory_in_the_way_is_an_error_and_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("taken");
        fs::create_dir(&path).unwrap();
        fs::write(path.join("inside"), b"x").unwrap();
        assert!(write_file_atomically(&path, b"data").is_err());
        assert_eq!(entries(dir.path()), vec!["taken"]);
        assert!(write_file_atomically(Path::new("/"), b"data").is_err());
    }
}
