//! What a real room and a real phone add to a capture: a room lamp flickering on the mains, an
//! auto-exposure that drifts, and frames the camera drops or repeats.
//!
//! A lamp on mains of frequency f_m (50 or 60 Hz, in practice within ±0.5 % of nominal) emits
//! light with period 1/(2·f_m): its flicker sits at 2·f_m and its harmonics
//! (docs/maths/demodulation.md#the-received-signal's background B is then not constant). Its
//! waveform w(t), normalised to a mean of 1, is one of
//!
//! ```text
//! sin²:    w = 2·sin²(2π f_m t)                      (an LED driver with no storage: 100 % flicker,
//!                                                     a pure tone at 2 f_m)
//! |sin|:   w = (π/2)·|sin(2π f_m t)|                 (a rectified incandescent-like supply:
//!                                                     harmonics at 2k·f_m, amplitudes ∝ 1/(4k²−1))
//! clipped: w ∝ min(sin²(2π f_m t), c)                (a driver with a current limit: a flat top)
//! ```
//!
//! and a pixel (row r, column c) integrates `level · a(r, c) · w(t)` over its exposure window, with
//! a(r, c) a smooth spatial amplitude (a lamp off to one side: `1 + gradient·(2c/W − 1)`).
//! The integral of w over the window is taken numerically (a lamp's period is many exposure
//! windows long at the rates used, so [`LAMP_SUBSAMPLES`] points per window are ample).
//!
//! Auto-exposure multiplies all light of frame j by `1 + ramp·j/(F−1)` (a linear drift of the
//! camera's gain over the capture). A dropped frame k means the k-th frame written is the camera's
//! frame k + 1 (and so on); a duplicated frame k is written twice: the frame index the camera's
//! timing uses is then [`RoomEffects::camera_frame`] of the written index.

use std::f64::consts::PI;

/// Points per exposure window of the numerical integral of the lamp's waveform.
pub const LAMP_SUBSAMPLES: usize = 48;

/// The shape of a lamp's light over one mains half-period (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LampWaveform {
    /// sin²: a pure tone at twice the mains frequency, 100 % modulation.
    SinSquared,
    /// |sin|: a rectified sine, harmonics at every multiple of twice the mains frequency.
    AbsSin,
    /// sin² clipped at this fraction of its peak, in (0, 1].
    Clipped(f64),
}

impl LampWaveform {
    /// The waveform at mains phase `phase` (radians of 2π f_m t), not normalised.
    fn raw(self, phase: f64) -> f64 {
        let s = phase.sin();
        match self {
            Self::SinSquared => s * s,
            Self::AbsSin => s.abs(),
            Self::Clipped(c) => (s * s).min(c),
        }
    }

    /// Mean of [`LampWaveform::raw`] over a period.
    fn mean(self) -> f64 {
        match self {
            Self::SinSquared => 0.5,
            Self::AbsSin => 2.0 / PI,
            Self::Clipped(c) => {
                // sin²(x) < c on |x| < asin(√c) (mod π): mean = (1/π)·∫ min(sin², c).
                let c = c.clamp(0.0, 1.0);
                let edge = c.sqrt().asin();
                let under = edge - (2.0 * edge).sin() / 2.0; // ∫_{-edge}^{edge} sin² dx
                (under + c * (PI - 2.0 * edge)) / PI
            }
        }
    }
}

/// A room lamp on the mains.
#[derive(Debug, Clone, PartialEq)]
pub struct RoomLamp {
    /// Mains frequency, Hz (the flicker is at twice this).
    pub mains_hz: f64,
    /// Mean light on the scene, fraction of full scale (at spatial amplitude 1).
    pub level: f64,
    /// The waveform.
    pub waveform: LampWaveform,
    /// Spatial amplitude slope across the image: a(c) = 1 + gradient·(2c/W − 1), |gradient| < 1.
    pub gradient: f64,
    /// Mains phase at camera time 0, radians.
    pub phase: f64,
}

impl RoomLamp {
    /// A lamp of mean `level` on `mains_hz` mains with `waveform`, brighter to the right.
    pub fn new(mains_hz: f64, level: f64, waveform: LampWaveform) -> Self {
        Self {
            mains_hz,
            level,
            waveform,
            gradient: 0.4,
            phase: 0.3,
        }
    }

    /// The lamp's waveform averaged over camera times [t0, t0 + duration], mean 1 over a period.
    pub fn window_mean(&self, t0: f64, duration: f64) -> f64 {
        let omega = 2.0 * PI * self.mains_hz;
        let mean = self.waveform.mean();
        if duration <= 0.0 {
            return self.waveform.raw(omega * t0 + self.phase) / mean;
        }
        let step = duration / LAMP_SUBSAMPLES as f64;
        let sum: f64 = (0..LAMP_SUBSAMPLES)
            .map(|k| {
                let t = t0 + (k as f64 + 0.5) * step;
                self.waveform.raw(omega * t + self.phase)
            })
            .sum();
        sum / LAMP_SUBSAMPLES as f64 / mean
    }

    /// Spatial amplitude a of column `col` of `width`.
    pub fn amplitude(&self, col: usize, width: usize) -> f64 {
        let x = if width > 1 {
            2.0 * col as f64 / (width - 1) as f64 - 1.0
        } else {
            0.0
        };
        1.0 + self.gradient * x
    }
}

/// Real-room effects of a simulated capture (all off by default).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RoomEffects {
    /// A flickering room lamp.
    pub lamp: Option<RoomLamp>,
    /// Relative change of the camera's gain from the first frame to the last (0 = none).
    pub gain_ramp: f64,
    /// Written frame indices at which the camera dropped a frame (ascending).
    pub dropped: Vec<usize>,
    /// Written frame indices the camera wrote twice (ascending).
    pub duplicated: Vec<usize>,
}

impl RoomEffects {
    /// Whether any effect is on.
    pub fn is_off(&self) -> bool {
        self.lamp.is_none()
            && self.gain_ramp == 0.0
            && self.dropped.is_empty()
            && self.duplicated.is_empty()
    }

    /// The camera frame (whose timing the content has) of written frame `index`: each drop at
    /// or before `index` skips one camera frame, each duplicate before it repeats one.
    pub fn camera_frame(&self, index: usize) -> usize {
        let skipped = self.dropped.iter().filter(|&&d| d <= index).count();
        let repeated = self.duplicated.iter().filter(|&&d| d < index).count();
        (index + skipped).saturating_sub(repeated)
    }

    /// The gain factor of written frame `index` of `frames`.
    pub fn gain(&self, index: usize, frames: usize) -> f64 {
        if frames < 2 {
            return 1.0;
        }
        1.0 + self.gain_ramp * index as f64 / (frames - 1) as f64
    }

    /// Checks the settings; names the first bad one.
    pub fn validate(&self) -> Result<(), (&'static str, &'static str)> {
        if let Some(lamp) = &self.lamp {
            if !(lamp.mains_hz.is_finite() && lamp.mains_hz > 0.0) {
                return Err(("lamp-mains", "must be a positive frequency in Hz"));
            }
            if !(lamp.level.is_finite() && lamp.level >= 0.0) {
                return Err(("lamp-level", "must be a number ≥ 0"));
            }
            if !(lamp.gradient.is_finite() && lamp.gradient.abs() < 1.0) {
                return Err(("lamp-gradient", "must be in (−1, 1)"));
            }
            if let LampWaveform::Clipped(c) = lamp.waveform
                && !(c > 0.0 && c <= 1.0)
            {
                return Err(("lamp-waveform", "the clip level must be in (0, 1]"));
            }
        }
        if !(self.gain_ramp.is_finite() && self.gain_ramp > -1.0) {
            return Err(("gain-ramp", "must be a number > −1"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lamp_waveforms_average_to_one_over_a_period() {
        for waveform in [
            LampWaveform::SinSquared,
            LampWaveform::AbsSin,
            LampWaveform::Clipped(0.6),
        ] {
            let lamp = RoomLamp::new(50.0, 0.1, waveform);
            // Ten flicker periods (1/100 s each), finely.
            let mut sum = 0.0;
            let steps = 1000;
            for k in 0..steps {
                sum += lamp.window_mean(k as f64 * 1e-4, 1e-4);
            }
            let mean = sum / steps as f64;
            assert!((mean - 1.0).abs() < 1e-3, "{waveform:?}: mean {mean}");
        }
    }

    #[test]
    fn sin_squared_flickers_at_twice_the_mains() {
        let lamp = RoomLamp::new(50.0, 0.1, LampWaveform::SinSquared);
        // Half a mains period later the light repeats; half a flicker period (5 ms) later the
        // 100 %-modulated tone is at the opposite side of its mean.
        let (a, b) = (lamp.window_mean(0.0123, 0.0), lamp.window_mean(0.0223, 0.0));
        assert!((a - b).abs() < 1e-9);
        let c = lamp.window_mean(0.0123 + 0.005, 0.0);
        assert!(((a - 1.0) + (c - 1.0)).abs() < 1e-9, "{a} {c}");
    }

    #[test]
    fn dropped_and_duplicated_frames_map_to_camera_frames() {
        let drop = RoomEffects {
            dropped: vec![60],
            ..RoomEffects::default()
        };
        assert_eq!(drop.camera_frame(59), 59);
        assert_eq!(drop.camera_frame(60), 61);
        let dup = RoomEffects {
            duplicated: vec![60],
            ..RoomEffects::default()
        };
        assert_eq!(dup.camera_frame(60), 60);
        assert_eq!(dup.camera_frame(61), 60);
        assert_eq!(dup.camera_frame(62), 61);
    }
}
