//! Decoder settings: which LEDs, which frames, which estimator, how code values map to light.

use serde::{Deserialize, Serialize};

/// How many LEDs the capture carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum LedCount {
    /// Exactly this many (1..=8); a capture that shows another count is an error.
    Fixed(usize),
    /// Detect the number of modulated LEDs from the video.
    Auto,
}

/// The per-pixel amplitude estimator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Estimator {
    /// Fit each LED's received waveform once from the whole frame, then per-pixel least
    /// squares against it (matched filter): unbiased, handles exposure and rate mismatch.
    #[default]
    Waveform,
    /// The thesis' decoder (Eqs. 3.25–3.30): subspace projection and maximum, per block of n
    /// frames, averaged over blocks.
    Thesis,
}

/// Conversion of code values to linear light before decoding.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub enum Linearize {
    /// Code values are already linear in light.
    #[default]
    None,
    /// Undo the sRGB transfer curve.
    Srgb,
    /// Undo a power-law gamma: linear = fraction^gamma.
    Gamma(f32),
}

/// A rectangular region of interest in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roi {
    /// Left column.
    pub x: usize,
    /// Top row.
    pub y: usize,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// Everything `decode` needs besides the frames.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecodeConfig {
    /// Number of LEDs, or detect it.
    pub leds: LedCount,
    /// Number of frames to use (at least n = 2^(N+1)); `None` = every frame of the source.
    pub frames: Option<usize>,
    /// Frames to skip at the start.
    pub start: usize,
    /// The amplitude estimator.
    pub estimator: Estimator,
    /// Code-value linearisation.
    pub linearize: Linearize,
    /// Decode only this region.
    pub roi: Option<Roi>,
    /// Camera frame rate override in fps (phone containers may store the playback rate).
    pub fps: Option<f64>,
    /// Known chips per frame (chip rate / frame rate) instead of estimating it.
    pub rate_ratio: Option<f64>,
    /// Largest |chips per frame − 1| searched when estimating the rate ratio.
    pub max_rate_mismatch: f64,
    /// Known exposure as a fraction of the frame period instead of estimating it.
    pub exposure: Option<f64>,
    /// Known rolling-shutter line time in seconds (0 = global shutter) instead of fitting it.
    pub line_time_s: Option<f64>,
    /// Memory budget for the frames of one decoding window, in bytes.
    pub window_bytes: usize,
    /// A pixel whose brightest frame stays below this fraction of full scale is under-exposed.
    pub underexposed_below: f32,
    /// Fail when the capture's modulated LED count differs from a fixed `leds`.
    pub check_led_count: bool,
    /// What to do with a decode the verdict finds implausible.
    pub on_implausible: OnImplausible,
    /// How the timing fit finds its starting points.
    #[serde(default)]
    pub seeds: SeedMethod,
    /// The modulation depths the luminaire played: each LED image is divided by 1 − ℓ_i
    /// (its off chips' share of its on light) to its full-depth equivalent ([`super::depth`]).
    #[serde(default)]
    pub depths: super::depth::ModulationDepths,
}

/// How the timing fit finds its starting points.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SeedMethod {
    /// Each LED's rank-1 template read off the window's signal space (\[`super::template`\]):
    /// shifts in closed form, a few exposures.
    RankOne,
    /// Each LED's parametric template scored against the signal space on a grid of shifts
    /// and exposures (\[`super::seed`\]).
    #[default]
    Grid,
}

/// What [`crate::demod::decode`] does with a decode the quality verdict finds implausible.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum OnImplausible {
    /// Return an error saying what looks wrong and what to try.
    #[default]
    Refuse,
    /// Return the result with the verdict recorded as overridden.
    Keep,
}

impl Default for DecodeConfig {
    fn default() -> Self {
        Self {
            leds: LedCount::Fixed(4),
            frames: None,
            start: 0,
            estimator: Estimator::Waveform,
            linearize: Linearize::None,
            roi: None,
            fps: None,
            rate_ratio: None,
            max_rate_mismatch: 0.06,
            exposure: None,
            line_time_s: None,
            window_bytes: 128 << 20,
            underexposed_below: 0.02,
            check_led_count: true,
            on_implausible: OnImplausible::Refuse,
            seeds: SeedMethod::Grid,
            depths: super::depth::ModulationDepths::Full,
        }
    }
}

/// What the fit may vary.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitLimits {
    /// Largest |ρ − 1| searched when the rate ratio is estimated.
    pub max_rate_mismatch: f64,
    /// A known rate ratio ρ (chips per frame) instead of estimating it.
    pub rate_ratio: Option<f64>,
    /// A known exposure fraction instead of estimating it.
    pub exposure: Option<f64>,
    /// A known line delay λ (frame periods per row; 0 = global shutter) instead of fitting it.
    pub line_delay: Option<f64>,
    /// How the starting points are found.
    pub seeds: SeedMethod,
}

impl Default for FitLimits {
    fn default() -> Self {
        Self {
            max_rate_mismatch: 0.06,
            rate_ratio: None,
            exposure: None,
            line_delay: None,
            seeds: SeedMethod::Grid,
        }
    }
}
