//! Synthetic MEB-FDMA captures with known ground truth: the test oracle of the pipeline.
//!
//! A [`Scene`] (analytic shapes, meshes, a ground plane, optional spin) is ray cast into a
//! height field ([`geometry`]), shaded per LED with the exact near-field light vector, attached
//! and cast shadows ([`lighting`], SPEC §5), and every frame integrates each LED's carrier over
//! each row's exposure window ([`waveform`], SPEC §2–§3) before sensor noise, tone curve and
//! quantisation ([`sensor`]). [`SimulatedCapture`] renders frames on demand as a
//! [`FrameSource`](crate::capture::FrameSource); [`output`] writes them and the truth to disk;
//! [`dataset`] builds the thesis' Ch. 7 data set (SPEC §10).
//!
//! This module never uses `demod`, `photometric` or `integrate` code.

pub mod capture;
pub mod dataset;
pub mod geometry;
pub mod lighting;
pub mod mesh;
pub mod output;
pub mod scene;
pub mod sensor;
pub mod tof;
pub mod waveform;

pub use capture::{GroundTruth, SimConfig, SimulatedCapture, TruthInfo};
pub use mesh::TriMesh;
pub use scene::{GroundPlane, Scene, SceneObject, Shape, Spin};
pub use sensor::{NoiseModel, ToneCurve};
pub use waveform::{CarrierWaveform, LedWaveform};

use thiserror::Error;

/// Errors of the simulator.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum SimulateError {
    /// A configuration value is out of range; names the option.
    #[error("invalid simulation setting `{field}`: {reason}")]
    Invalid {
        /// The setting, e.g. `frames`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A mesh file cannot be used.
    #[error("mesh {path}: {reason}")]
    Mesh {
        /// The file.
        path: String,
        /// What is wrong.
        reason: String,
    },
    /// Writing the output failed.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The file or directory.
        path: std::path::PathBuf,
        /// The underlying error.
        reason: String,
    },
    /// The output directory exists and is not empty.
    #[error("output {0} already exists and is not empty (choose another --out or pass --force)")]
    OutputExists(std::path::PathBuf),
    /// The `ffmpeg` program could not be run.
    #[error("cannot run ffmpeg for MP4 output ({0}); install FFmpeg or use --format png/y4m")]
    Ffmpeg(String),
}
