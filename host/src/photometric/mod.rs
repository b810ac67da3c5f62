//! Photometric stereo: per-LED images → unit normals and albedo (SPEC §5, thesis Eqs. 3.1–3.5).
//!
//! Lambertian model A_i(p) = ρ(p) · max(0, n(p)·L_i(p)). Per pixel the LEDs that light it are
//! chosen ([`solve`]), G = L⁺A is solved by least squares over them, ρ = |G| and n = G/ρ. A pixel
//! lit by fewer than three LEDs is flagged, never invented. Light vectors come from the distant
//! model or, in the near field, from the current depth estimate ([`lights`]). Unless a mask is
//! supplied the object is found from the albedo and the per-pixel signal-to-noise ratio ([`mask`]).

pub mod lights;
pub mod mask;
pub mod solve;

pub use lights::Lights;
pub use mask::{MaskConfig, object_mask};
pub use solve::{PhotometricResult, estimate_normals, model_misfit};

use thiserror::Error;

/// Settings of the per-pixel solve.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotometricConfig {
    /// An LED counts as shadowed when its value is below this fraction of the pixel's brightest LED.
    pub shadow_fraction: f32,
    /// An LED counts as shadowed when its value is below this many noise σ (needs a noise map).
    pub shadow_sigmas: f32,
    /// Fewest lit LEDs a pixel needs for a normal (3 for a unique solution).
    pub min_lit_leds: usize,
    /// Automatic object mask settings (used when no mask is given).
    pub mask: MaskConfig,
}

impl Default for PhotometricConfig {
    fn default() -> Self {
        Self {
            shadow_fraction: 0.02,
            shadow_sigmas: 3.0,
            min_lit_leds: 3,
            mask: MaskConfig::default(),
        }
    }
}

/// Errors of photometric stereo.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PhotometricError {
    /// Photometric stereo needs at least three LEDs.
    #[error("photometric stereo needs at least 3 LEDs/lights, got {0}")]
    TooFewLeds(usize),
    /// The number of light vectors differs from the number of images.
    #[error("{images} images but {lights} light vectors")]
    LightCountMismatch {
        /// Number of images.
        images: usize,
        /// Number of light vectors.
        lights: usize,
    },
    /// Images (or mask, noise map, depth) of different sizes.
    #[error("{what} is {got_rows}x{got_cols}, expected {rows}x{cols} (rows x columns)")]
    SizeMismatch {
        /// Which input.
        what: String,
        /// Its size.
        got_rows: usize,
        /// Its size.
        got_cols: usize,
        /// The expected size.
        rows: usize,
        /// The expected size.
        cols: usize,
    },
    /// A light vector is zero or not finite.
    #[error("light vector {0} is zero or not finite")]
    BadLight(usize),
    /// The mask (given or found) holds no pixel that can be solved.
    #[error("empty mask: {0}")]
    EmptyMask(String),
}

/// Checks that `array` has `shape`; names it `what` in the error.
pub(crate) fn check_shape<T>(
    what: &str,
    array: &ndarray::Array2<T>,
    shape: (usize, usize),
) -> Result<(), PhotometricError> {
    let (got_rows, got_cols) = array.dim();
    if (got_rows, got_cols) != shape {
        return Err(PhotometricError::SizeMismatch {
            what: what.to_string(),
            got_rows,
            got_cols,
            rows: shape.0,
            cols: shape.1,
        });
    }
    Ok(())
}
