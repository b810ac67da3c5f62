//! Synthetic MEB-FDMA captures with known ground truth: the test oracle of the pipeline.
//!
//! A [`Scene`] (analytic shapes, meshes, a ground plane, optional spin) is ray cast into a
//! height field ([`geometry`]), shaded per LED with the exact near-field light vector, attached
//! and cast shadows ([`lighting`], docs/maths/photometric-stereo.md#the-lambertian-model), and
//! every frame integrates each LED's carrier over
//! each row's exposure window ([`waveform`], docs/maths/demodulation.md#the-received-signal) before
//! sensor noise, tone curve and
//! quantisation ([`sensor`]). [`SimulatedCapture`] renders frames on demand as a
//! [`FrameSource`](meb_core::capture::FrameSource); [`output`] writes them and the truth to disk;
//! [`dataset`] builds the thesis' Ch. 7 data set
//! (docs/formats/simulated-folders.md#the-synthetic-data-set); [`exposure`] picks a gain that
//! does not clip, as an auto-exposed camera would.
//!
//! This crate depends on `meb-core` only: it cannot use the decoder or the reconstruction it is
//! the oracle of.

#![deny(missing_docs)]

pub mod board_view;
pub mod capture;
pub mod dataset;
pub mod exposure;
pub mod geometry;
pub mod lighting;
pub mod material;
pub mod mesh;
pub mod output;
pub mod rig_error;
pub mod room;
pub mod scene;
pub mod sensor;
pub mod tof;
pub mod waveform;

pub use capture::{GroundTruth, SimConfig, SimulatedCapture, TruthInfo};
pub use material::Material;
pub use meb_core::mesh::TriMesh;
pub use room::{LampWaveform, RoomEffects, RoomLamp};
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
    #[error(transparent)]
    Mesh(#[from] meb_core::mesh::MeshError),
    /// The rig is invalid.
    #[error(transparent)]
    Rig(#[from] meb_core::rig::RigError),
    /// The rig's LED count has no carrier set.
    #[error("rig: {0}")]
    Carriers(#[from] protocol::carriers::CarrierError),
    /// Writing the output failed.
    #[error(transparent)]
    Files(#[from] meb_core::io::FilesError),
    /// Rendering a frame failed.
    #[error(transparent)]
    Frames(#[from] meb_core::capture::CaptureError),
    /// The `ffmpeg` program could not be run.
    #[error("cannot run ffmpeg for MP4 output ({0}); install FFmpeg or write PNG or y4m frames")]
    Ffmpeg(String),
    /// Starting, feeding or waiting for `ffmpeg` failed in the operating system.
    #[error("cannot {what} ffmpeg for MP4 output; install FFmpeg or write PNG or y4m frames")]
    FfmpegIo {
        /// What was being done: "start", "feed frames to" or "wait for".
        what: &'static str,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

/// Largest camera side the simulator renders, pixels.
pub const MAX_CAMERA_SIDE: usize = 16_384;
/// Largest camera the simulator renders, pixels (2^26 ≈ 67 M, e.g. 8192 × 8192).
pub const MAX_CAMERA_PIXELS: usize = 1 << 26;

/// Upper estimate of the simulator's memory per camera pixel with `leds` LEDs, bytes: the
/// height field and ground truth (depth, normals, albedo, mask: ~40 B), per-LED true images
/// and shading (16 B each), one rendered frame and its accumulators (~56 B).
pub fn bytes_per_pixel(leds: usize) -> usize {
    96 + 16 * leds
}

/// Checks a `width` × `height` camera against [`MAX_CAMERA_SIDE`], [`MAX_CAMERA_PIXELS`] and
/// the memory the simulator would need ([`bytes_per_pixel`]) against the memory available,
/// before anything is allocated.
pub fn check_camera_size(width: usize, height: usize, leds: usize) -> Result<(), SimulateError> {
    let invalid = |reason: String| SimulateError::Invalid {
        field: "camera size".into(),
        reason,
    };
    if width > MAX_CAMERA_SIDE || height > MAX_CAMERA_SIDE {
        return Err(invalid(format!(
            "{width}×{height} pixels: each side may be at most {MAX_CAMERA_SIDE}"
        )));
    }
    let pixels = width * height; // ≤ 2^28, no overflow
    if pixels > MAX_CAMERA_PIXELS {
        return Err(invalid(format!(
            "{width}×{height} = {pixels} pixels: at most {MAX_CAMERA_PIXELS} are simulated"
        )));
    }
    let needed = pixels.saturating_mul(bytes_per_pixel(leds)) as u64;
    if let Some(available) = available_memory()
        && needed > available
    {
        return Err(invalid(format!(
            "{width}×{height} pixels need about {:.1} GB but {:.1} GB of memory is available",
            needed as f64 / 1e9,
            available as f64 / 1e9
        )));
    }
    Ok(())
}

/// Memory the system can still give out (`MemAvailable` of /proc/meminfo), when known.
fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn huge_cameras_are_refused_before_allocating() {
        for (w, h) in [
            (100_000, 100_000),
            (usize::MAX, usize::MAX),
            (16_384, 16_384),
        ] {
            let err = check_camera_size(w, h, 4).unwrap_err();
            assert!(err.to_string().contains("camera size"), "{err}");
        }
        check_camera_size(1280, 720, 4).unwrap();
    }
}
