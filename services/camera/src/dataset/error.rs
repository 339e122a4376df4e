//! The one error type of dataset IO. Every variant names the file it is about; JSON problems
//! also name the key, as a JSON pointer (RFC 6901) such as `/7/cam_R_w2c` (image 7, field
//! `cam_R_w2c`) or `/7/2/cam_t_m2c` (image 7, ground-truth instance 2).

use std::path::PathBuf;

use glint_geometry::io::{AtomicWriteError, MeshIoError};

/// Why a dataset file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or directory could not be read at all (missing, no permission, ...).
    #[error("cannot read {}", path.display())]
    Read {
        /// The file or directory.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// A directory could not be created.
    #[error("cannot create the directory {}", path.display())]
    CreateDirectory {
        /// The directory.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid JSON (syntax error, truncated, ...).
    #[error("{}: not valid JSON at line {line}, column {column}: {problem}", path.display())]
    Json {
        /// The JSON file.
        path: PathBuf,
        /// Line of the error, 1-based.
        line: usize,
        /// Column of the error, 1-based.
        column: usize,
        /// The parser's message.
        problem: String,
    },
    /// A JSON value is missing, has the wrong type or an unusable value.
    #[error("{}: key {key}: {problem}", path.display())]
    Field {
        /// The JSON file.
        path: PathBuf,
        /// JSON pointer to the value, e.g. `/7/cam_R_w2c`.
        key: String,
        /// What is wrong with the value.
        problem: String,
    },
    /// A line of a plain-text file (ROBI's `list.txt`, a camera `.yml`) is unusable.
    #[error("{}: line {line}: {problem}", path.display())]
    Line {
        /// The text file.
        path: PathBuf,
        /// The offending line, 1-based.
        line: usize,
        /// What is wrong with it.
        problem: String,
    },
    /// An image file could not be decoded.
    #[error("{}: cannot decode the image", path.display())]
    ImageDecode {
        /// The image file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: image::ImageError,
    },
    /// An image could not be encoded for writing.
    #[error("{}: cannot encode the image as PNG", path.display())]
    ImageEncode {
        /// The image file to be written.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: image::ImageError,
    },
    /// A record could not be encoded as JSON (a writer bug: Glint's records always encode).
    #[error("{}: cannot encode the record as JSON (a bug in Glint's writer)", path.display())]
    JsonEncode {
        /// The JSON file to be written.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: serde_json::Error,
    },
    /// An image decoded, but is not what the file must hold (bit depth, channels, size).
    #[error("{}: {problem}", path.display())]
    ImageContent {
        /// The image file.
        path: PathBuf,
        /// What is wrong with its content.
        problem: String,
    },
    /// A pixel cannot be stored in the file's format (depth beyond the 16-bit range, say).
    #[error("{}: pixel ({u}, {v}): {problem}", path.display())]
    Pixel {
        /// The image file to be written.
        path: PathBuf,
        /// Column of the pixel, px.
        u: u32,
        /// Row of the pixel, px.
        v: u32,
        /// Why its value cannot be stored.
        problem: String,
    },
    /// The caller asked for something the file at `path` cannot take or does not have.
    #[error("{}: {problem}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What was asked that it cannot take or does not have.
        problem: String,
    },
    /// An output file could not be written; the message names it.
    #[error(transparent)]
    Write(#[from] AtomicWriteError),
    /// A mesh file could not be read or written; the message names it. (Boxed: it is large,
    /// and rare.)
    #[error(transparent)]
    Mesh(Box<MeshIoError>),
}

impl From<MeshIoError> for DatasetError {
    fn from(error: MeshIoError) -> Self {
        Self::Mesh(Box::new(error))
    }
}

impl DatasetError {
    /// The file the error is about.
    pub fn path(&self) -> PathBuf {
        match self {
            Self::Read { path, .. }
            | Self::CreateDirectory { path, .. }
            | Self::Json { path, .. }
            | Self::Field { path, .. }
            | Self::Line { path, .. }
            | Self::ImageDecode { path, .. }
            | Self::ImageEncode { path, .. }
            | Self::JsonEncode { path, .. }
            | Self::ImageContent { path, .. }
            | Self::Pixel { path, .. }
            | Self::Invalid { path, .. } => path.clone(),
            Self::Write(error) => error.path.clone(),
            Self::Mesh(error) => PathBuf::from(mesh_error_file(error)),
        }
    }

    /// The JSON pointer of the offending value, for [`DatasetError::Field`].
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Field { key, .. } => Some(key),
            _ => None,
        }
    }
}

fn mesh_error_file(error: &MeshIoError) -> &str {
    match error {
        MeshIoError::Read { file, .. }
        | MeshIoError::UnknownFormat { file, .. }
        | MeshIoError::BadHeader { file, .. }
        | MeshIoError::Parse { file, .. }
        | MeshIoError::Truncated { file, .. }
        | MeshIoError::IndexOutOfRange { file, .. }
        | MeshIoError::InvalidMesh { file, .. } => file,
        MeshIoError::Write(error) => error.path.to_str().unwrap_or(""),
    }
}

/// `std::fs::create_dir_all` with an error that names the directory.
pub(crate) fn create_directory(path: &std::path::Path) -> Result<(), DatasetError> {
    std::fs::create_dir_all(path).map_err(|source| DatasetError::CreateDirectory {
        path: path.to_owned(),
        source,
    })
}

/// `std::fs::read` with an error that names the file.
pub(crate) fn read_file(path: &std::path::Path) -> Result<Vec<u8>, DatasetError> {
    std::fs::read(path).map_err(|source| DatasetError::Read {
        path: path.to_owned(),
        source,
    })
}
