//! Readers for public reference data sets: MATLAB v5 arrays ([`mat`]) and the DiLiGenT
//! photometric-stereo layout ([`diligent`]), normal maps with intrinsics ([`normal_maps`]).

pub mod diligent;
pub mod mat;
pub mod normal_maps;

use std::path::PathBuf;
use thiserror::Error;

/// Errors reading a data set.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// A file could not be read.
    #[error("cannot read {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file of the common formats (images, masks, arrays) could not be read.
    #[error(transparent)]
    Files(#[from] crate::io::FilesError),
    /// A file's content is not what the layout promises.
    #[error("{path}: {reason}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

impl DatasetError {
    /// A format error on `path`.
    pub(crate) fn format(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Self::Format {
            path: path.into(),
            reason: reason.into(),
        }
    }
}
