//! Outputs of a reconstruction (ARCHITECTURE "export"): `.npy` arrays, PNG previews (normal map,
//! albedo, colour-mapped depth, error map, shaded renders of the surface), surface meshes
//! (PLY, OBJ, STL) and the report (`report.json`, and `report.html`, one self-contained page with
//! the previews embedded as base64 PNGs); and [`files`], the one file layer every command
//! writes through (atomic output folders, npy, colour ramp, previews, masks).

pub mod files;
pub mod mesh;
pub mod render;
pub mod report;
pub mod viewer;

pub use files::FilesError;

use thiserror::Error;

/// Errors writing outputs.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ExportError {
    /// A file could not be written.
    #[error(transparent)]
    Files(#[from] FilesError),
    /// Nothing to export (e.g. an empty depth map).
    #[error("nothing to export: {0}")]
    Empty(String),
}
