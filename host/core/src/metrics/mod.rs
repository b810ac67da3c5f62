//! Accuracy figures against ground truth (docs/maths/accuracy.md#depth-error): depth RMSE after
//! removing the best
//! constant offset, NRMSE = RMSE / (max − min of the true depth), % of the surface reconstructed,
//! mean/median angular normal error, and per-pixel error maps. Ground truth is a depth map or a
//! mesh rendered to depth in the rig's camera ([`mesh`]).

pub mod angular;
pub mod depth;
pub mod mesh;

pub use angular::{AngularErrors, compare_normals, normals_from_depth, normals_from_depth_seen_by};
pub use depth::{DepthErrors, DepthScore, compare_depth, score_depth};
pub use mesh::{MeshDepth, load_mesh_triangles, render_mesh_depth};

use thiserror::Error;

/// Errors computing metrics.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MetricsError {
    /// Estimate and truth differ in size.
    #[error("estimate is {estimate:?} but ground truth is {truth:?} (rows, columns)")]
    SizeMismatch {
        /// Estimate shape.
        estimate: (usize, usize),
        /// Truth shape.
        truth: (usize, usize),
    },
    /// No pixel has both an estimate and a true value.
    #[error("no pixel has both an estimate and ground truth")]
    NoOverlap,
    /// A mesh file could not be read.
    #[error(transparent)]
    Mesh(#[from] crate::mesh::MeshError),
}
