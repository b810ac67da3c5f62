//! The one file layer of `meb`: atomic output folders ([`folder`]), `.npy` arrays ([`npy`]),
//! large outputs written past the page cache ([`direct`]), the colour ramp ([`colour`]), PNG
//! previews ([`preview`]) and mask images ([`mask`]).
//!
//! Every command that writes files goes through this module, so every output folder is
//! replaced whole or not at all, every array is read with the same type and shape checks, and
//! every preview uses the same colours. It depends on nothing of the pipeline's stages
//! (only [`crate::stats`]), so any stage may use it.

pub mod colour;
pub mod direct;
pub mod folder;
pub mod mask;
pub mod npy;
pub mod preview;

pub use folder::{
    InterruptHook, OutputFolder, Replace, on_first_interrupt, remove_temporaries_on_signal,
};
pub use mask::{read_mask, write_mask};
pub use npy::{read_exact, read_float, write_npy, write_npy_synced};

use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors reading or writing files.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum FilesError {
    /// A file or folder could not be written.
    #[error("cannot write {path}")]
    Write {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file or folder could not be read.
    #[error("cannot read {path}")]
    Read {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file that must exist does not.
    #[error("{path} does not exist")]
    Missing {
        /// The file.
        path: PathBuf,
    },
    /// Data could not be encoded into a file format.
    #[error("cannot encode {path}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// An image file could not be decoded or encoded.
    #[error("{path}: not a readable or writable image")]
    Image {
        /// The file.
        path: PathBuf,
        /// The codec's error.
        source: image::ImageError,
    },
    /// A `.npy` file's header is malformed.
    #[error("{path} is not a .npy array file")]
    NpyHeader {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A `.npy` file's data cannot be parsed.
    #[error("{path}: the array data cannot be read")]
    NpyData {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A `.npy` file holds another element type than the one needed.
    #[error("{path} holds {found} values; {expected} expected")]
    NpyType {
        /// The file.
        path: PathBuf,
        /// The type found, e.g. "int32 ('<i4')".
        found: String,
        /// The type needed.
        expected: &'static str,
    },
    /// A `.npy` array has the wrong number of axes or sizes.
    #[error("{path} is {found}; expected {expected}")]
    NpyShape {
        /// The file.
        path: PathBuf,
        /// The shape found, e.g. "3-D, 4×5×2".
        found: String,
        /// The shape needed, e.g. "3-D, H×W×3".
        expected: String,
    },
    /// A `.npy` file ends before its array does.
    #[error("{path} ends before its array does (truncated file)")]
    NpyTruncated {
        /// The file.
        path: PathBuf,
    },
    /// A `.npy` file has bytes after its array.
    #[error("{path} has {extra} bytes after its array (not a single .npy array)")]
    NpyExtraBytes {
        /// The file.
        path: PathBuf,
        /// How many.
        extra: usize,
    },
    /// The output folder's path names no folder (e.g. `/`).
    #[error("{path} cannot be an output folder")]
    BadOutputPath {
        /// The path.
        path: PathBuf,
    },
    /// The output path is an existing file.
    #[error("output {path} is a file, not a folder")]
    OutputIsAFile {
        /// The path.
        path: PathBuf,
    },
    /// The output folder holds something that is not an earlier output of the same command.
    #[error(
        "output folder {path} is not empty and is not an earlier `meb {command}` output{}",
        found.as_ref().map(|c| format!(" (it holds a `meb {c}` output)")).unwrap_or_default()
    )]
    OutputNotEmpty {
        /// The folder.
        path: PathBuf,
        /// The command that wanted to write it.
        command: String,
        /// The command whose output it holds, when it is a `meb` output.
        found: Option<String>,
    },
}

impl FilesError {
    /// A write error on `path`.
    pub fn write(path: &Path, source: std::io::Error) -> Self {
        Self::Write {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A read error on `path`.
    pub fn read(path: &Path, source: std::io::Error) -> Self {
        Self::Read {
            path: path.to_path_buf(),
            source,
        }
    }
}
