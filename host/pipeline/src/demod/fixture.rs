//! A decode to test code that reads one, without decoding frames.

use super::{DecodeReport, Decoded, Estimator};
use meb_core::types::LedImages;
use ndarray::Array2;

/// A decode of three LEDs with these levels (LED 2 at half) and per-pixel noise.
pub(crate) fn decoded(levels: Array2<f32>, noise: Array2<f32>) -> Decoded {
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
            exposure_std: 0.0,
            line_time_us: 0.0,
            line_delay_frames: 0.0,
            line_delay_std_frames: 0.0,
            line_delay_evidence: 0.0,
            row_bands: 1,
            fit_residual: 0.0,
            median_noise: 0.0,
            saturated_pixels: 0,
            underexposed_pixels: 0,
            clipping: None,
            per_led: vec![],
            verdict: Default::default(),
            room: Default::default(),
            compression: None,
            modulation: Default::default(),
        },
    }
}
