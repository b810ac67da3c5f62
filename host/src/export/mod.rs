//! Outputs of a reconstruction (ARCHITECTURE "export"): `.npy` arrays, PNG previews (normal map,
//! albedo, colour-mapped depth, error map, shaded renders of the surface), surface meshes
//! (PLY, OBJ, STL) and the report (`report.json`, and `report.html`, one self-contained page with
//! the previews embedded as base64 PNGs). Every file is written to a temporary name and renamed,
//! so a failed run never leaves a half-written file behind under its final name.

pub mod images;
pub mod mesh;
pub mod render;
pub mod report;

use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors writing outputs.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ExportError {
    /// A file could not be written.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// Nothing to export (e.g. an empty depth map).
    #[error("nothing to export: {0}")]
    Empty(String),
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let err = |e: std::io::Error| ExportError::Write {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, bytes).map_err(err)?;
    std::fs::rename(&tmp, path).map_err(err)
}

/// Serialises an array as `.npy` and writes it atomically.
pub fn write_npy<A, D>(path: &Path, array: &ndarray::Array<A, D>) -> Result<(), ExportError>
where
    A: ndarray_npy::WritableElement,
    D: ndarray::Dimension,
{
    use ndarray_npy::WriteNpyExt;
    let mut bytes = Vec::new();
    array
        .write_npy(&mut bytes)
        .map_err(|e| ExportError::Write {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
    write_atomic(path, &bytes)
}
