//! Carrying the received waveform's timing from window to window.
//!
//! The decoder fits each LED's received waveform — shift, exposure, camera/chip rate ratio and
//! rolling-shutter line delay — from a window's spatial mean
//! (docs/maths/demodulation.md#the-timing-fit). Exposure, line delay
//! and rate ratio belong to the camera's sensor and the luminaire's clock, not to the window:
//! they stay put for a whole clip, while a 32-frame fit of them can go astray when the object's
//! mean brightness drifts (with the decoder's earlier per-window fit, one window in five of a
//! turning ellipsoid fitted a 1.6 % rate error and 4 % exposure, and its 3-D frame came out
//! 38 mm wrong). So the video decodes every window with the timing of the best free fit so far
//! and fits only the shifts. Carrying the line delay also spares each window the fit's
//! rolling-shutter test (band-wise and row-wise refinements, more than half of the timing
//! fit's work); a global-shutter fit carries a line delay of 0. A setting the user gives
//! (`DecodeConfig`) is never replaced by a carried one, in a region's decode as in a whole
//! frame's.
//!
//! "Best" is the lowest median per-pixel residual σ of the decode (how well the LED model
//! explains the pixels). The first [`FREE_WINDOWS`] windows are decoded both ways; later a
//! window is decoded freely too only when the carried timing explains it clearly worse than it
//! explained its own window ([`SUSPICIOUS_RATIO`]), and the better of the two is kept (and
//! carried on, when the free fit wins).
//!
//! A timing fitted to a window in which the object moved is provisional: motion blurs the
//! modulation the fit explains, so a moving window's fit can carry a rate ratio 0.1 % off
//! (0.16 chip of drift over the next 128 frames) and still explain its own window best. When
//! the object is then seen still in [`STILL_WINDOWS`] windows in a row, the next window is
//! decoded freely too, and its fit replaces the provisional one when it explains its window
//! better ([`TimingCarry::observe`]). A video that keeps moving keeps its carried timing, at no
//! extra cost.
//!
//! A window decoded in a region around the object ([`super::focus`]) is judged against the
//! median σ of the last whole-frame decode inside that region, not against the whole frame's
//! ([`TimingCarry::decode_region`]); its free fit may serve the window but is never carried on,
//! so the timing is learnt from whole frames alone.

use crate::demod::{DecodeConfig, Decoded, DemodError};
use meb_core::capture::{FrameFormat, Samples};
use serde::{Deserialize, Serialize};

/// Windows decoded both with the carried and a free timing before the carry is trusted.
pub const FREE_WINDOWS: usize = 3;
/// Windows in a row in which the object is seen still before a provisional timing is refitted.
pub const STILL_WINDOWS: usize = 2;
/// A carried decode whose median σ exceeds the carried fit's by this factor is refitted.
pub const SUSPICIOUS_RATIO: f64 = 1.5;

/// Where a window's waveform timing came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimingSource {
    /// Fitted to this window.
    Fitted,
    /// Carried over from an earlier window's fit.
    Carried,
    /// Fixed by the user's decoder settings.
    Given,
}

/// A free fit's timing and how well it explained its window.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Timing {
    rate_ratio: f64,
    exposure: f64,
    /// Seconds per row (0 for a global shutter); `None` when a rolling shutter's line delay
    /// cannot be given in seconds (no frame rate), so that every window fits it.
    line_time_s: Option<f64>,
    median_noise: f64,
    /// Fitted to a window in which the object moved (module docs).
    moving: bool,
}

impl Timing {
    fn of(decoded: &Decoded) -> Option<Self> {
        let r = &decoded.report;
        let ok = [
            r.rate_ratio,
            r.exposure,
            r.median_noise,
            r.line_delay_frames,
        ]
        .iter()
        .all(|v| v.is_finite())
            && r.exposure > 0.0
            && r.exposure <= 1.0;
        let line_time_s = if r.line_delay_frames == 0.0 {
            Some(0.0)
        } else {
            (r.fps > 0.0).then(|| r.line_delay_frames / r.fps)
        };
        ok.then_some(Self {
            rate_ratio: r.rate_ratio,
            exposure: r.exposure,
            line_time_s,
            median_noise: r.median_noise,
            moving: false,
        })
    }

    /// `config` with this timing wherever it leaves the timing to the fit.
    fn given_in(&self, config: &DecodeConfig) -> DecodeConfig {
        DecodeConfig {
            rate_ratio: config.rate_ratio.or(Some(self.rate_ratio)),
            exposure: config.exposure.or(Some(self.exposure)),
            line_time_s: config.line_time_s.or(self.line_time_s),
            ..config.clone()
        }
    }
}

/// The timing carried through a video (module docs).
#[derive(Debug, Clone, Default)]
pub struct TimingCarry {
    enabled: bool,
    best: Option<Timing>,
    windows: usize,
    /// The last window decoded was fitted freely and its fit became `best`.
    best_is_last: bool,
    /// Windows in a row, up to the last one decoded, found still (and plausible).
    still_run: usize,
}

/// A decoded window and where its timing came from.
pub type DecodedWindow = (Result<Decoded, DemodError>, TimingSource);

impl TimingCarry {
    /// A carry (`enabled` false: every window is fitted freely).
    pub fn new(enabled: bool) -> Self {
        Self {
            enabled,
            ..Self::default()
        }
    }

    /// Decodes `frames` with `config`, carrying the timing as the module docs say.
    pub fn decode(
        &mut self,
        frames: &[Samples],
        format: &FrameFormat,
        config: &DecodeConfig,
    ) -> DecodedWindow {
        let given = config.rate_ratio.is_some() && config.exposure.is_some();
        self.windows += 1;
        self.best_is_last = false;
        let carried = match self.best.filter(|_| self.enabled && !given) {
            None => {
                let decoded = crate::demod::decode_frames(frames, format, config);
                let source = if given {
                    TimingSource::Given
                } else {
                    self.offer(&decoded);
                    TimingSource::Fitted
                };
                return (decoded, source);
            }
            Some(best) => best,
        };
        let first = crate::demod::decode_frames(frames, format, &carried.given_in(config));
        let provisional = carried.moving && self.still_run >= STILL_WINDOWS;
        let trusted = !provisional
            && self.windows > FREE_WINDOWS
            && first
                .as_ref()
                .is_ok_and(|d| d.report.median_noise <= SUSPICIOUS_RATIO * carried.median_noise);
        if trusted {
            return (first, TimingSource::Carried);
        }
        let free = crate::demod::decode_frames(frames, format, config);
        self.offer(&free);
        match (&first, &free) {
            (Ok(a), Ok(b)) if b.report.median_noise < a.report.median_noise => {
                (free, TimingSource::Fitted)
            }
            (Ok(_), _) => (first, TimingSource::Carried),
            _ => (free, TimingSource::Fitted),
        }
    }

    /// Whether the carry has settled: later windows are decoded with the carried timing unless
    /// it explains them clearly worse (or every window is fitted, or the timing is given).
    pub fn settled(&self) -> bool {
        !self.enabled || self.windows >= FREE_WINDOWS
    }

    /// Decodes `frames` over `config.roi`, a region around the object whose median σ in the
    /// last whole-frame decode was `reference_noise` (module docs).
    pub fn decode_region(
        &mut self,
        frames: &[Samples],
        format: &FrameFormat,
        config: &DecodeConfig,
        reference_noise: f64,
    ) -> DecodedWindow {
        let given = config.rate_ratio.is_some() && config.exposure.is_some();
        self.windows += 1;
        self.best_is_last = false;
        let Some(carried) = self.best.filter(|_| self.enabled && !given) else {
            let decoded = crate::demod::decode_frames(frames, format, config);
            let source = if given {
                TimingSource::Given
            } else {
                TimingSource::Fitted
            };
            return (decoded, source);
        };
        let first = crate::demod::decode_frames(frames, format, &carried.given_in(config));
        let trusted = first
            .as_ref()
            .is_ok_and(|d| d.report.median_noise <= SUSPICIOUS_RATIO * reference_noise);
        if trusted {
            return (first, TimingSource::Carried);
        }
        let free = crate::demod::decode_frames(frames, format, config);
        match (&first, &free) {
            (Ok(a), Ok(b)) if b.report.median_noise < a.report.median_noise => {
                (free, TimingSource::Fitted)
            }
            (Ok(_), _) => (first, TimingSource::Carried),
            _ => (free, TimingSource::Fitted),
        }
    }

    /// Keeps a free fit's timing when it explains its window better than the carried one.
    fn offer(&mut self, decoded: &Result<Decoded, DemodError>) {
        let Some(timing) = decoded.as_ref().ok().and_then(Timing::of) else {
            return;
        };
        if self
            .best
            .is_none_or(|best| timing.median_noise < best.median_noise)
        {
            self.best = Some(timing);
            self.best_is_last = true;
        }
    }

    /// Records whether the object was `still` (and the decode plausible) in the window
    /// decoded last: a fit of a window that was not still is provisional (module docs).
    pub fn observe(&mut self, still: bool) {
        if let Some(best) = self.best.as_mut().filter(|_| self.best_is_last && !still) {
            best.moving = true;
        }
        self.still_run = if still { self.still_run + 1 } else { 0 };
    }
}
