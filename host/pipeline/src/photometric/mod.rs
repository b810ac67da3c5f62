//! Photometric stereo: per-LED images → unit normals and albedo
//! (docs/maths/photometric-stereo.md#the-lambertian-model, thesis Eqs. 3.1–3.5).
//!
//! Lambertian model A_i(p) = ρ(p) · max(0, n(p)·L_i(p)). Per pixel the LEDs that light it are
//! chosen by a statistical test against each LED's noise ([`solve`], [`noise`]), G = L⁺A is
//! solved by weighted least squares over them, ρ = |G| and n = G/ρ. A pixel lit by exactly two
//! LEDs yields the circle its normal lies on, for the integrator to close; fewer is never
//! invented. Light vectors come from the distant model or, in the near field, from the current
//! depth estimate ([`lights`]). Unless a mask is supplied the object is found from the albedo and
//! the per-pixel signal-to-noise ratio, with its holes ([`mask`]).

pub mod highlights;
pub mod lights;
pub mod mask;
pub mod noise;
mod outcome;
pub mod solve;

pub use lights::Lights;
pub use mask::MaskConfig;
pub use noise::led_noise_gains;
pub use solve::{ModelMisfit, PhotometricResult, estimate_normals};

use thiserror::Error;

/// Settings of the per-pixel solve.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PhotometricConfig {
    /// Without a noise map: an LED counts as shadowed below this fraction of the pixel's
    /// brightest LED.
    pub shadow_fraction: f32,
    /// With a noise map: an LED counts as shadowed below this many of its noise σ.
    pub shadow_sigmas: f32,
    /// With a noise map and four or more lit LEDs: the Lambertian fit's χ² must stay below the
    /// quantile of this one-sided normal deviate (3.7 ≈ a false alarm in 10⁴ pixels).
    pub consistency_sigmas: f32,
    /// Relative model error ε added to each LED's noise in the consistency test (light-vector
    /// and gain errors of a few percent).
    pub model_error: f32,
    /// With a noise map and four or more lit LEDs: a lit LED that reads above the prediction of
    /// the others counts as a highlight when its half vector lies within this angle (degrees)
    /// of their normal ([`highlights`]).
    #[serde(default = "default_highlight_max_deg")]
    pub highlight_max_deg: f32,
    /// With a noise map and four or more lit LEDs: also reject a highlight's tail, a reading
    /// within the model error but above the noise of the others' prediction in an LED's lobe
    /// ([`highlights`]). Meant for a surface known to be glossy: a reconstruction turns it on
    /// once a pass finds one ([`highlights::looks_glossy`]), and a video's next window starts
    /// with it when the last one was glossy.
    #[serde(default)]
    pub reject_highlight_tails: bool,
    /// Fewest lit LEDs a pixel needs for a normal (3 for a unique solution).
    pub min_lit_leds: usize,
    /// Automatic object mask settings (used when no mask is given).
    pub mask: MaskConfig,
    /// Least noise gain of each LED image (empty: 1 for every LED, [`led_noise_gains`]): an
    /// image brought to full depth by a factor 1/(1 − ℓ_i) carries at least that many times
    /// the level noise. A reconstruction of a decoded capture sets it from the decode's
    /// image scales.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub noise_gain_floors: Vec<f64>,
}

impl Default for PhotometricConfig {
    fn default() -> Self {
        Self {
            shadow_fraction: 0.02,
            shadow_sigmas: 3.0,
            consistency_sigmas: 3.7,
            model_error: 0.03,
            highlight_max_deg: default_highlight_max_deg(),
            reject_highlight_tails: false,
            min_lit_leds: 3,
            mask: MaskConfig::default(),
            noise_gain_floors: Vec::new(),
        }
    }
}

/// The default [`PhotometricConfig::highlight_max_deg`] ([`highlights`]).
fn default_highlight_max_deg() -> f32 {
    30.0
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
    /// The light vectors cannot determine normals (fewer than three independent directions).
    #[error("singular light set-up: {0}")]
    SingularLights(String),
    /// Pixels are lit but the Lambertian model cannot explain them.
    #[error("no pixel could be solved: {0}")]
    Unsolvable(String),
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
