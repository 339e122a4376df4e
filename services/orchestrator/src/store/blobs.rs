//! A content-addressed blob directory: each blob is a file named by the SHA-256 of its bytes
//! (lowercase hex) in a folder named by the name's first two digits. Blobs are written
//! atomically (`glint_geometry::io::write_file_atomically`: a temporary file, fsync, rename),
//! never changed, and verified against their name when read, so a damaged or truncated blob
//! is reported, never returned.

use std::path::{Path, PathBuf};

/// Why a blob could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum BlobError {
    /// The file system failed; a session store's calls report it as
    /// [`crate::stages::StageError::Internal`].
    #[error("{path}: {message}")]
    Io {
        /// The file or folder.
        path: String,
        /// The system's error.
        message: String,
    },
    /// No blob has the name; a session store's calls report data loss
    /// ([`crate::stages::StageError::DataLoss`]).
    #[error("blob {path} is missing")]
    Missing {
        /// Where it should be.
        path: String,
    },
    /// The blob's bytes do not hash to its name (damaged or truncated); a session store's
    /// calls report data loss ([`crate::stages::StageError::DataLoss`]).
    #[error("blob {path} is damaged: its bytes hash to {actual}, not to its name")]
    Damaged {
        /// The blob's file.
        path: String,
        /// The SHA-256 of its bytes, lowercase hex.
        actual: String,
    },
    /// The name given (shown) is not 64 lowercase hex digits.
    #[error("{0:?} is not a blob name (64 lowercase hex digits)")]
    BadName(String),
}

/// A blob directory.
#[derive(Clone, Debug)]
pub struct BlobDir {
    root: PathBuf,
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> BlobError {
    BlobError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

fn valid_name(name: &str) -> bool {
    name.len() == 64 && name.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

impl BlobDir {
    /// The blob directory at `root`, created if missing. Temporary files a crash left behind
    /// (`.<name>.<pid>-<n>.tmp`) are removed: they never became blobs.
    pub fn open(root: &Path) -> Result<Self, BlobError> {
        std::fs::create_dir_all(root).map_err(|e| io_error(root, e))?;
        for folder in std::fs::read_dir(root).map_err(|e| io_error(root, e))? {
            let folder = folder.map_err(|e| io_error(root, e))?.path();
            if !folder.is_dir() {
                continue;
            }
            for entry in std::fs::read_dir(&folder).map_err(|e| io_error(&folder, e))? {
                let path = entry.map_err(|e| io_error(&folder, e))?.path();
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                if name.starts_with('.') && name.ends_with(".tmp") {
                    std::fs::remove_file(&path).map_err(|e| io_error(&path, e))?;
                }
            }
        }
        Ok(Self {
            root: root.to_owned(),
        })
    }

    /// Where blob `name` lives.
    pub fn path(&self, name: &str) -> Result<PathBuf, BlobError> {
        if !valid_name(name) {
            return Err(BlobError::BadName(name.to_owned()));
        }
        Ok(self.root.join(&name[..2]).join(name))
    }

    /// Keeps `bytes` and returns their name. A blob that exists already is written again
    /// (atomically): a damaged copy is replaced rather than trusted.
    pub fn put(&self, bytes: &[u8]) -> Result<String, BlobError> {
        let name = glint_geometry::sha256_hex(bytes);
        let path = self.path(&name)?;
        if let Some(folder) = path.parent() {
            std::fs::create_dir_all(folder).map_err(|e| io_error(folder, e))?;
        }
        glint_geometry::io::write_file_atomically(&path, bytes).map_err(|e| io_error(&path, e))?;
        Ok(name)
    }

    /// Blob `name`'s bytes, verified against the name.
    pub fn get(&self, name: &str) -> Result<Vec<u8>, BlobError> {
        let path = self.path(name)?;
        let bytes = match std::fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(BlobError::Missing {
                    path: path.display().to_string(),
                });
            }
            Err(e) => return Err(io_error(&path, e)),
        };
        let actual = glint_geometry::sha256_hex(&bytes);
        if actual != name {
            return Err(BlobError::Damaged {
                path: path.display().to_string(),
                actual,
            });
        }
        Ok(bytes)
    }

    /// Whether blob `name` exists (its contents unchecked).
    pub fn contains(&self, name: &str) -> bool {
        self.path(name).is_ok_and(|p| p.is_file())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blob_reads_back_and_damage_or_loss_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobDir::open(dir.path()).unwrap();
        let name = blobs.put(b"a capture").unwrap();
        assert_eq!(name, glint_geometry::sha256_hex(b"a capture"));
        assert_eq!(blobs.get(&name).unwrap(), b"a capture");
        // Written twice, kept once.
        assert_eq!(blobs.put(b"a capture").unwrap(), name);

        let path = blobs.path(&name).unwrap();
        std::fs::write(&path, b"a cApture").unwrap();
        assert!(matches!(blobs.get(&name), Err(BlobError::Damaged { .. })));
        std::fs::remove_file(&path).unwrap();
        assert!(matches!(blobs.get(&name), Err(BlobError::Missing { .. })));
        assert!(matches!(blobs.get("../etc"), Err(BlobError::BadName(_))));

        // A crash's leftover temporary file goes at the next open.
        let leftover = path.parent().unwrap().join(format!(".{name}.1-0.tmp"));
        std::fs::write(&leftover, b"half").unwrap();
        BlobDir::open(dir.path()).unwrap();
        assert!(!leftover.exists());
    }
}
