//! The camera's sensor response after light integration: Poisson–Gaussian noise, an optional
//! tone curve, saturation and quantisation to the bit depth.
//!
//! Noise follows the usual Poisson–Gaussian model of raw sensors (Foi et al., 2008) in its
//! Gaussian approximation: a value v (fraction of full scale) becomes
//! `v + sqrt(v / K)·N₁ + σ·N₂` with K the full-well capacity in electrons (shot noise, off
//! when absent) and σ the read noise as a fraction of full scale. The tone curve is off by
//! default (linear response), `Gamma(G)` encodes v^(1/G), `Srgb` the IEC 61966-2-1 curve.
//! Values outside [0, 1] saturate.

use rand::{Rng, RngExt};
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// Sensor noise parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseModel {
    /// Gaussian read-noise standard deviation, fraction of full scale.
    pub sigma: f64,
    /// Full-well capacity in electrons for shot noise; `None` = no shot noise.
    pub full_well_electrons: Option<f64>,
}

impl NoiseModel {
    /// No noise at all.
    pub const NONE: Self = Self {
        sigma: 0.0,
        full_well_electrons: None,
    };

    /// Whether any noise is drawn.
    pub fn is_noiseless(&self) -> bool {
        self.sigma == 0.0 && self.full_well_electrons.is_none()
    }

    /// Adds noise to a value v (fraction of full scale).
    pub fn apply<R: Rng + ?Sized>(&self, v: f64, rng: &mut R) -> f64 {
        let mut out = v;
        if let Some(k) = self.full_well_electrons {
            let n: f64 = rng.sample(StandardNormal);
            out += (v.max(0.0) / k).sqrt() * n;
        }
        if self.sigma > 0.0 {
            let n: f64 = rng.sample(StandardNormal);
            out += self.sigma * n;
        }
        out
    }
}

/// Output tone curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ToneCurve {
    /// Code proportional to light (the default).
    Linear,
    /// Power law: code ∝ light^(1/G).
    Gamma(f64),
    /// The sRGB transfer curve.
    Srgb,
}

impl ToneCurve {
    /// Encodes a linear value in [0, 1].
    pub fn encode(&self, v: f64) -> f64 {
        let v = v.clamp(0.0, 1.0);
        match *self {
            Self::Linear => v,
            Self::Gamma(g) => v.powf(1.0 / g),
            Self::Srgb => {
                if v <= 0.003_130_8 {
                    12.92 * v
                } else {
                    1.055 * v.powf(1.0 / 2.4) - 0.055
                }
            }
        }
    }
}

/// Saturates v to [0, 1] and quantises it to a code value of `bit_depth` bits.
pub fn quantise(v: f64, bit_depth: u8) -> u16 {
    let max = f64::from((1u32 << bit_depth) - 1);
    (v.clamp(0.0, 1.0) * max).round() as u16
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn tone_curves_and_quantisation() {
        assert_eq!(ToneCurve::Linear.encode(0.25), 0.25);
        assert!((ToneCurve::Gamma(2.0).encode(0.25) - 0.5).abs() < 1e-12);
        assert!((ToneCurve::Srgb.encode(1.0) - 1.0).abs() < 1e-12);
        assert_eq!(quantise(1.7, 8), 255);
        assert_eq!(quantise(-0.1, 12), 0);
        assert_eq!(quantise(0.5, 10), 512);
    }

    #[test]
    fn noise_has_the_requested_spread() {
        let model = NoiseModel {
            sigma: 0.01,
            full_well_electrons: Some(10_000.0),
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let n = 20_000;
        let samples: Vec<f64> = (0..n).map(|_| model.apply(0.5, &mut rng) - 0.5).collect();
        let var = samples.iter().map(|d| d * d).sum::<f64>() / n as f64;
        let expected = 0.01f64.powi(2) + 0.5 / 10_000.0;
        assert!((var / expected - 1.0).abs() < 0.05, "{var} vs {expected}");
    }
}
