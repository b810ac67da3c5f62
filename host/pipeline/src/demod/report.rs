//! The decode report written as `decode.json`.

use super::config::Estimator;
use super::depth::ModulationReport;
use super::nuisance::RoomReport;
use super::quality::{LedQuality, Verdict};
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
    /// How well the fitted waveform explains this LED (first window, but the gain uncertainty
    /// of the average over the windows; the verdict covers all).
    #[serde(default)]
    pub quality: LedQuality,
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
    /// Estimated exposure as a fraction of the frame period (at a rate ratio of exactly 1 any
    /// exposure up to one frame gives the same waveforms, so it is not identifiable there).
    pub exposure: f64,
    /// 1σ standard error of `exposure` from the timing fit's covariance (largest over
    /// windows; 0 when given, 1 when the data do not determine it, as at a rate ratio of 1).
    #[serde(default)]
    pub exposure_std: f64,
    /// Rolling-shutter line time in microseconds (fitted or given; 0 for a global shutter or
    /// when the frame rate is unknown: see `line_delay_frames`).
    #[serde(default)]
    pub line_time_us: f64,
    /// Rolling-shutter line delay in frame periods per row (0 for a global shutter).
    #[serde(default)]
    pub line_delay_frames: f64,
    /// 1σ standard error of `line_delay_frames` from the fit (largest over windows; 0 when
    /// given or when the rows agree and no line delay was fitted).
    #[serde(default)]
    pub line_delay_std_frames: f64,
    /// Cost reduction of the fitted line delay against the best fit without one, noise
    /// variances (smallest over windows; 0 when given or not fitted).
    #[serde(default)]
    pub line_delay_evidence: f64,
    /// Row bands with their own waveforms in the per-pixel fit (1 for a global shutter).
    #[serde(default)]
    pub row_bands: usize,
    /// RMS residual per frame sample of the timing model on the fit's pixel sample (fraction
    /// of full scale; close to the noise when the model fits).
    pub fit_residual: f64,
    /// Median per-frame pixel noise σ (fraction of full scale).
    pub median_noise: f64,
    /// Number of saturated pixels.
    pub saturated_pixels: usize,
    /// Number of under-exposed pixels.
    pub underexposed_pixels: usize,
    /// When pixels clip: how many, and how far the exposure may come down.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clipping: Option<super::clipping::ClippingAdvice>,
    /// Per-LED results.
    pub per_led: Vec<LedReport>,
    /// Whether the decode can be trusted, what looks wrong and what to try.
    #[serde(default)]
    pub verdict: Verdict,
    /// Room-light flicker and exposure drift found and modelled ([`super::nuisance`]).
    #[serde(default)]
    pub room: RoomReport,
    /// The lossy compression the video went through, as its container states it
    /// ([`super::compression`]); absent for uncompressed and lossless sources.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compression: Option<meb_core::capture::LossyCompression>,
    /// The modulation depths assumed and the scale each LED image was brought to full depth
    /// with ([`super::depth`]; absent in older decodes: full depth).
    #[serde(default)]
    pub modulation: ModulationReport,
}

impl DecodeReport {
    /// One line with the fitted timing and how well the data determine it: exposure and line
    /// delay with their standard errors, the line delay's evidence, and the verdict.
    pub fn timing_summary(&self) -> String {
        format!(
            "exposure {:.3} ± {:.3}, line delay {:.3e} ± {:.1e} frames/row (evidence {:.1} noise \
             variances), verdict {:?}",
            self.exposure,
            self.exposure_std,
            self.line_delay_frames,
            self.line_delay_std_frames,
            self.line_delay_evidence,
            self.verdict.status
        )
    }
}
