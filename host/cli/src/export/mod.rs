//! Outputs of a reconstruction: `.npy` arrays, PNG previews (normal map,
//! albedo, colour-mapped depth, error map, shaded renders of the surface), surface meshes
//! (PLY, OBJ, STL) and the report (`report.json`, and `report.html`, one self-contained page with
//! the previews embedded as base64 PNGs), and `meb video`'s page (`video.html`: the 3-D frames
//! with a scrubber, and every window's verdict, motion, accuracy and timing), all written
//! through `meb_core::io`, the one file layer.

pub mod mesh;
pub mod render;
pub mod report;
pub mod video_report;
pub mod viewer;

use meb_core::io::FilesError;
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
