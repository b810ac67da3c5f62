//! The decode report written as `decode.json`.

use super::config::Estimator;
use serde::{Deserialize, Serialize};

/// What the decoder measured about one LED.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LedReport {
    /// LED number, 1-based as in the thesis.
    pub led: usize,
    /// Received shift Δ_i of the carrier at frame 0, in chips (integer + fractional part).
    pub phase_chips: f64,
    /// Mean on-level over the decoded pixels (fraction of full scale).
    pub mean_level: f64,
    /// Signal-to-noise ratio of the LED image, 20·log10(mean level / RMS noise of A_i), dB.
    pub snr_db: f64,
}

/// Summary of one decode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecodeReport {
    /// The estimator used.
    pub estimator: Estimator,
    /// Number of LEDs decoded.
    pub leds: usize,
    /// Number of modulated LEDs seen in the video (when it could be checked).
    pub detected_leds: Option<usize>,
    /// Frames that went into the images.
    pub frames_used: usize,
    /// Decoding windows (a long clip is decoded in windows and averaged).
    pub windows: usize,
    /// Image width and height.
    pub width: usize,
    /// Image height.
    pub height: usize,
    /// Estimated chips per camera frame (chip rate / frame rate), mean over windows.
    pub rate_ratio: f64,
    /// Camera frame rate used for `chip_rate_hz`.
    pub fps: f64,
    /// Chip rate implied by the rate ratio, Hz.
    pub chip_rate_hz: f64,
    /// Estimated exposure as a fraction of the frame period.
    pub exposure: f64,
    /// RMS residual of the waveform fit to the mean signal (fraction of full scale).
    pub fit_residual: f64,
    /// Median per-frame pixel noise σ (fraction of full scale).
    pub median_noise: f64,
    /// Number of saturated pixels.
    pub saturated_pixels: usize,
    /// Number of under-exposed pixels.
    pub underexposed_pixels: usize,
    /// Per-LED results.
    pub per_led: Vec<LedReport>,
}
