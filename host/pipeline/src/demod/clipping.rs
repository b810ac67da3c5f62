//! Exposure advice when pixels clip: how far the exposure may come down before the object's
//! diffuse level is lost in the noise.
//!
//! A glossy object exposed for its diffuse surface clips where it mirrors an LED. The decoder
//! flags those pixels (`saturated.npy`) and the reconstruction leaves them out (they are
//! filled), so clipped highlights cost coverage, not accuracy. Lowering the exposure by a
//! factor k scales every LED level A_i by 1/k while the noise stays; the object's diffuse level
//! D (the [`DIFFUSE_QUANTILE`] of the brightest LED over the lit pixels that do not clip)
//! remains usable while D/k ≥ [`USABLE_SNR`]·σ, σ the median per-pixel noise of the LED
//! images. [`ClippingAdvice`] states k_max = D/(USABLE_SNR·σ).

use ndarray::{Array2, Zip};
use serde::{Deserialize, Serialize};

/// Quantile of the brightest LED level over the lit, unclipped pixels taken as the object's
/// diffuse level.
pub const DIFFUSE_QUANTILE: f64 = 0.9;

/// Signal-to-noise ratio (level over σ) below which an LED level is not usable: at 20σ the
/// level's relative error is 5 %, a few degrees of normal.
pub const USABLE_SNR: f64 = 20.0;

/// What clipped and how much the exposure may be lowered (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClippingAdvice {
    /// Pixels that clip in some frame.
    pub clipped_pixels: usize,
    /// Share of the lit pixels (clipped or with an LED above 3σ) that clip.
    pub clipped_share: f64,
    /// The object's diffuse level D, fraction of full scale (linear).
    pub diffuse_level: f64,
    /// Largest factor k by which the exposure may be lowered with D/k ≥ 20σ.
    pub max_exposure_reduction: f64,
    /// The advice in words.
    pub message: String,
}

impl ClippingAdvice {
    /// Advice for a decode with LED `images`, per-pixel `noise` and `saturated` pixels; `None`
    /// when nothing clips or no lit pixel is left to measure the diffuse level.
    pub fn of(
        images: &[Array2<f32>],
        noise: &Array2<f32>,
        saturated: &Array2<bool>,
        underexposed: &Array2<bool>,
    ) -> Option<Self> {
        let clipped_pixels = saturated.iter().filter(|&&s| s).count();
        if clipped_pixels == 0 || images.is_empty() {
            return None;
        }
        let brightest = images.iter().skip(1).fold(images[0].clone(), |mut m, im| {
            Zip::from(&mut m).and(im).for_each(|m, &v| *m = m.max(v));
            m
        });
        let usable = |p: (usize, usize)| !saturated[p] && !underexposed[p];
        let sigma = meb_core::stats::quantile(
            noise
                .indexed_iter()
                .filter(|&(p, _)| usable(p))
                .map(|(_, &s)| s),
            0.5,
        )?;
        let lit: Vec<f32> = brightest
            .indexed_iter()
            .filter(|&(p, &v)| usable(p) && v > 3.0 * sigma)
            .map(|(_, &v)| v)
            .collect();
        let diffuse = f64::from(meb_core::stats::quantile(
            lit.iter().copied(),
            DIFFUSE_QUANTILE,
        )?);
        let clipped_share = clipped_pixels as f64 / (clipped_pixels + lit.len()) as f64;
        let floor = USABLE_SNR * f64::from(sigma).max(1e-9);
        let max_reduction = diffuse / floor;
        let message = if max_reduction > 1.0 {
            format!(
                "{clipped_pixels} pixels ({:.1} % of the lit ones) clip, e.g. highlights of a \
                 glossy surface: they are left out of the reconstruction and filled. The \
                 object's diffuse level is {:.1} % of full scale; an exposure up to {:.1}× \
                 lower keeps it usable (≥ {USABLE_SNR:.0}σ) — lower it to recover clipped \
                 pixels, or keep it if they are few",
                100.0 * clipped_share,
                100.0 * diffuse,
                max_reduction
            )
        } else {
            format!(
                "{clipped_pixels} pixels ({:.1} % of the lit ones) clip, e.g. highlights of a \
                 glossy surface: they are left out of the reconstruction and filled. The \
                 object's diffuse level is only {:.1} % of full scale (under {USABLE_SNR:.0}σ \
                 of the noise): do not lower the exposure; add light or dull the surface instead",
                100.0 * clipped_share,
                100.0 * diffuse
            )
        };
        Some(Self {
            clipped_pixels,
            clipped_share,
            diffuse_level: diffuse,
            max_exposure_reduction: max_reduction,
            message,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10×10 object at level 0.2 with noise 0.001 and 4 clipped pixels: k_max = 0.2/0.02.
    #[test]
    fn advice_states_how_far_the_exposure_may_come_down() {
        let images = vec![Array2::from_elem((10, 10), 0.2f32); 3];
        let noise = Array2::from_elem((10, 10), 0.001f32);
        let mut saturated = Array2::from_elem((10, 10), false);
        let under = Array2::from_elem((10, 10), false);
        assert!(ClippingAdvice::of(&images, &noise, &saturated, &under).is_none());
        for p in [(1, 1), (1, 2), (2, 1), (2, 2)] {
            saturated[p] = true;
        }
        let advice = ClippingAdvice::of(&images, &noise, &saturated, &under).unwrap();
        assert_eq!(advice.clipped_pixels, 4);
        assert!((advice.clipped_share - 0.04).abs() < 1e-9);
        assert!(
            (advice.max_exposure_reduction - 10.0).abs() < 1e-3,
            "{advice:?}"
        );
        assert!(advice.message.contains("10.0× lower"), "{}", advice.message);
        // A dim object: do not lower the exposure.
        let dim = vec![Array2::from_elem((10, 10), 0.01f32); 3];
        let advice = ClippingAdvice::of(&dim, &noise, &saturated, &under).unwrap();
        assert!(
            advice.message.contains("do not lower"),
            "{}",
            advice.message
        );
    }
}
