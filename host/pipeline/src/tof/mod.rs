//! Hybrid time-of-flight + photometric stereo (thesis Ch. 6, docs/maths/tof.md#the-hybrid-scanner):
//! TCSPC histograms of a
//! SPAD camera → range map ([`range`]), chequerboard calibration between the SPAD and the
//! photometric-stereo camera ([`chequerboard`], [`calibration`]), per-object masks in the PS
//! camera's pixels ([`mask`]), range maps on disk ([`range_folder`]), and per-object
//! reconstruction placed at, and fused with, the absolute ToF range ([`hybrid`], its offset
//! and tilt from the ToF by [`rigid`]; the fusion is Nehab, Rusinkiewicz, Davis & Ramamoorthi,
//! "Efficiently combining positions and normals for precise 3D geometry", SIGGRAPH 2005, solved
//! by [`crate::integrate::fusion`]).
//!
//! The range is the distance along the ToF camera's optical axis ("axial depth"), in mm. The
//! emitter is taken to be co-located with the SPAD (the thesis' LED array sits beside it), so a
//! photon's time of flight is twice its radial distance over c.

pub mod calibration;
pub mod chequerboard;
pub mod histogram;
pub mod hybrid;
pub mod layer_smoothing;
pub mod mask;
pub mod range;
pub mod range_folder;
pub mod rigid;

pub use calibration::{BoardView, Calibration, CalibrationPlane};
pub use histogram::{Histograms, Reference};
pub use range::{RangeConfig, RangeMap, TimingMode, estimate_range};
pub use range_folder::{read_range_folder, write_range_folder};

use thiserror::Error;

/// Speed of light in mm per picosecond.
pub const LIGHT_MM_PER_PS: f64 = 0.299_792_458;

/// Errors of the time-of-flight stage.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum TofError {
    /// Histograms and reference disagree in length or shape.
    #[error("{what}: {detail}")]
    Shape {
        /// Which input.
        what: String,
        /// What does not match.
        detail: String,
    },
    /// Every histogram (or the reference) holds no photon.
    #[error("{0} holds no photon counts (all zero): nothing to correlate")]
    NoPhotons(String),
    /// Counts are negative, NaN or infinite.
    #[error("{what} has {count} negative or non-finite counts (first at index {first:?})")]
    BadCounts {
        /// Which input.
        what: String,
        /// How many.
        count: usize,
        /// Index of the first bad count.
        first: Vec<usize>,
    },
    /// No pixel yields a reliable range.
    #[error(
        "no pixel has a reliable range: {reason} (try more frames, a lower --min-photons, or check that the reference matches the histograms)"
    )]
    NoReliableRange {
        /// What held every pixel back.
        reason: String,
    },
    /// A setting is out of range.
    #[error("invalid setting `{field}`: {reason}")]
    Invalid {
        /// The setting.
        field: String,
        /// Why.
        reason: String,
    },
    /// The chequerboard was not found in an image.
    #[error("no {cols}x{rows} chequerboard found in the {image} image: {reason}")]
    BoardNotFound {
        /// Which image (ToF or camera).
        image: String,
        /// Inner corners per row.
        cols: usize,
        /// Inner corners per column.
        rows: usize,
        /// What went wrong.
        reason: String,
    },
    /// This build cannot find chequerboard corners (built without the `opencv` feature).
    #[error(
        "this meb was built without OpenCV, which finds the chequerboard corners: rebuild with `cargo build --release --features opencv` (after `bash scripts/setup.sh`, which installs libopencv-dev, clang and libclang-dev)"
    )]
    NoCornerDetector,
    /// A calibration does not fit the data it is applied to.
    #[error("calibration mismatch: {0}")]
    CalibrationMismatch(String),
    /// A calibration fit failed or is implausible.
    #[error("calibration failed: {0}")]
    Calibration(String),
    /// A range interval selects nothing.
    #[error("empty selection: {0}")]
    Empty(String),
    /// Reading or writing a file through the shared file layer failed.
    #[error(transparent)]
    Files(#[from] meb_core::io::FilesError),
    /// A file's content is not what is needed.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        reason: String,
    },
}
