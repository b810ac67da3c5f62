//! Motion in a window: pixels whose frames the LED model cannot explain.
//!
//! The decoder fits every pixel of a window with a still scene: a background plus each LED's
//! received waveform times the pixel's on-level A_i (SPEC §3–§4). What that fit leaves over —
//! the energy outside the LED waveforms, reported as the per-pixel noise σ — is sensor noise
//! for a still object, but an object that moves during the window changes its pixels'
//! brightness in ways no carrier does (a silhouette edge sweeping over a pixel is a step, a
//! turning surface a ramp), and that lands in the residual. This is the thesis' proposed
//! frame selection (Ch. 5.4: detect when the object moves, decode where it is still) done on
//! the decoder's own residual instead of frame differences, which the LED modulation itself
//! would trip.
//!
//! A pixel counts as moving when its σ exceeds `sigmas` times the σ typical of still lit
//! pixels at least as bright in the same window (the smallest median σ of its brightness
//! octile and the brighter ones: shot noise grows with brightness and is not motion, while
//! half-covered, moving edge pixels crowd the dim octiles). The window's motion score is the
//! fraction of lit pixels that move; above `threshold` the window is moving.

use crate::demod::Decoded;
use serde::{Deserialize, Serialize};

/// Largest number of pixels the score is computed from (an evenly strided sample).
const SAMPLE_PIXELS: usize = 1 << 17;
/// Brightness bins of the noise reference.
const LEVEL_BINS: usize = 8;

/// What to do with windows in which the object moved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionPolicy {
    /// Reconstruct every window and record its motion.
    #[default]
    Mark,
    /// Leave moving windows out (recorded as skipped).
    Skip,
    /// Move a moving window later, a few frames at a time, until the object is still in it
    /// (at most up to the next window's start); reconstruct it there.
    Place,
}

/// Motion detection settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MotionConfig {
    /// What to do with moving windows.
    pub policy: MotionPolicy,
    /// A pixel moves when its residual σ exceeds this many times its brightness class's.
    pub sigmas: f32,
    /// A window moves when more than this fraction of its lit pixels move.
    pub threshold: f64,
    /// Pixels brighter (Σ A_i) than this fraction of the 99th percentile count as lit.
    pub lit_fraction: f32,
    /// Frames a [`MotionPolicy::Place`] window moves per try.
    pub place_step: usize,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self {
            policy: MotionPolicy::Mark,
            sigmas: 3.0,
            threshold: 0.02,
            lit_fraction: 0.05,
            place_step: 4,
        }
    }
}

/// The motion measured in one window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotionEstimate {
    /// Fraction of lit pixels whose residual marks them as moving.
    pub score: f64,
    /// Whether the score exceeds the threshold.
    pub moving: bool,
    /// Lit pixels in the sample.
    pub lit_pixels: usize,
    /// Moving pixels in the sample.
    pub moving_pixels: usize,
}

/// Measures the motion in a decoded window (module docs).
pub fn detect_motion(decoded: &Decoded, config: &MotionConfig) -> MotionEstimate {
    let images = &decoded.leds.images;
    let noise = decoded.noise.as_slice_memory_order();
    let pixels = noise.map_or(0, <[f32]>::len);
    let stride = pixels.div_ceil(SAMPLE_PIXELS).max(1);
    let planes: Vec<&[f32]> = images
        .iter()
        .filter_map(|im| im.as_slice_memory_order())
        .collect();
    let (Some(noise), true) = (noise, planes.len() == images.len()) else {
        return MotionEstimate {
            score: 0.0,
            moving: false,
            lit_pixels: 0,
            moving_pixels: 0,
        };
    };
    // (brightness Σ A_i, residual σ) of the sampled pixels with data.
    let mut samples: Vec<(f32, f32)> = (0..pixels)
        .step_by(stride)
        .filter_map(|p| {
            let level: f32 = planes.iter().map(|plane| plane[p]).sum();
            (level.is_finite() && noise[p].is_finite()).then_some((level, noise[p]))
        })
        .collect();
    let top = crate::stats::quantile(samples.iter().map(|s| s.0), 0.99).unwrap_or(0.0);
    samples.retain(|s| s.0 > config.lit_fraction * top && top > 0.0);
    let lit = samples.len();
    if lit < LEVEL_BINS * 4 {
        return MotionEstimate {
            score: 0.0,
            moving: false,
            lit_pixels: lit,
            moving_pixels: 0,
        };
    }
    // Brightness octiles and the median σ of each. Moving pixels (partly covered by a
    // sweeping silhouette) gather in the dim octiles and can make up most of one, while still
    // noise only grows with brightness: each octile's reference is the smallest median of
    // it and every brighter octile.
    samples.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let bins: Vec<&[(f32, f32)]> = (0..LEVEL_BINS)
        .map(|bin| &samples[bin * lit / LEVEL_BINS..(bin + 1) * lit / LEVEL_BINS])
        .collect();
    let mut medians: Vec<f32> = bins
        .iter()
        .map(|part| crate::stats::median(part.iter().map(|s| s.1)).unwrap_or(0.0))
        .collect();
    for bin in (0..LEVEL_BINS - 1).rev() {
        medians[bin] = medians[bin].min(medians[bin + 1]);
    }
    let moving: usize = bins
        .iter()
        .zip(&medians)
        .map(|(part, reference)| {
            let limit = config.sigmas * reference;
            part.iter().filter(|s| s.1 > limit).count()
        })
        .sum();
    let score = moving as f64 / lit as f64;
    MotionEstimate {
        score,
        moving: score > config.threshold,
        lit_pixels: lit,
        moving_pixels: moving,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::demod::{DecodeReport, Estimator};
    use crate::types::LedImages;
    use ndarray::Array2;

    fn decoded(levels: Array2<f32>, noise: Array2<f32>) -> Decoded {
        let dim = levels.dim();
        Decoded {
            leds: LedImages {
                images: vec![levels.clone(), levels.mapv(|v| 0.5 * v), levels],
            },
            noise,
            saturated: Array2::from_elem(dim, false),
            underexposed: Array2::from_elem(dim, false),
            report: DecodeReport {
                estimator: Estimator::Waveform,
                leds: 3,
                detected_leds: None,
                frames_used: 16,
                windows: 1,
                width: dim.1,
                height: dim.0,
                rate_ratio: 1.0,
                fps: 1000.0,
                chip_rate_hz: 1000.0,
                exposure: 1.0,
                line_time_us: 0.0,
                line_delay_frames: 0.0,
                row_bands: 1,
                fit_residual: 0.0,
                median_noise: 0.0,
                saturated_pixels: 0,
                underexposed_pixels: 0,
                per_led: vec![],
                verdict: Default::default(),
            },
        }
    }

    /// A lit disc with shot-noise-like σ growing with brightness, on a dark background.
    fn disc() -> (Array2<f32>, Array2<f32>) {
        let levels = Array2::from_shape_fn((64, 64), |(r, c)| {
            let d2 = (r as f32 - 32.0).powi(2) + (c as f32 - 32.0).powi(2);
            if d2 < 400.0 {
                0.1 + 0.5 * (1.0 - d2 / 400.0)
            } else {
                0.0
            }
        });
        let noise = levels.mapv(|l| 0.004 * (1.0 + 2.0 * l) * (1.0 + 0.1 * (l * 97.0).sin()));
        (levels, noise)
    }

    #[test]
    fn a_still_window_scores_zero_even_with_brightness_dependent_noise() {
        let (levels, noise) = disc();
        let m = detect_motion(&decoded(levels, noise), &MotionConfig::default());
        assert!(m.lit_pixels > 1000);
        assert_eq!(m.moving_pixels, 0);
        assert!(!m.moving);
    }

    #[test]
    fn a_sweeping_edge_marks_the_window_moving() {
        let (levels, mut noise) = disc();
        // An edge crossing a band of lit pixels: residuals ten times the noise there.
        for ((r, c), n) in noise.indexed_iter_mut() {
            let d = ((r as f32 - 32.0).powi(2) + (c as f32 - 32.0).powi(2)).sqrt();
            if (17.0..20.0).contains(&d) {
                *n *= 10.0;
            }
        }
        let m = detect_motion(&decoded(levels, noise), &MotionConfig::default());
        assert!(m.moving, "{m:?}");
        assert!(m.score > 0.1 && m.score < 0.5, "{m:?}");
    }
}
