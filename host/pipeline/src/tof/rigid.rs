//! Per-object rigid placement against the ToF pixels' own ranges: the offset of a
//! reconstructed object taken from the positions, the rest of its shape from the normals (the
//! lowest-order case of Nehab, Rusinkiewicz, Davis & Ramamoorthi, "Efficiently combining
//! positions and normals for precise 3D geometry", SIGGRAPH 2005: positions set the low
//! frequencies, normals the high ones).
//!
//! The residual r = p − z of the positions p against the depth z is fitted by weighted least
//! squares with an offset and a tilt about the weighted centroid,
//!
//! ```text
//! r(x, y) ≈ a + bₓ·(x − x̄) + b_y·(y − ȳ),     weights w_i (the prior's inverse variances)
//! ```
//!
//! whose covariance is C = (XᵀWX)⁻¹. With the per-pixel (unsmoothed) ranges the weights count
//! each ToF pixel once (its inverse variance spread over the camera pixels it covers), so C is
//! the uncertainty set by the number of independent ToF pixels on the object. The offset a is
//! applied (about the centroid it does not depend on the tilt). The tilt b is only reported,
//! with χ² = bᵀ C_b⁻¹ b: photometric stereo's normals carry a systematic tilt (0.33 mm RMS on
//! the simulated hybrid scene's sphere, 0.8 mm on its cube, alike on every noise seed), but the
//! ToF's own tilt over a curved object is biased too (−0.075 mm per pixel across the sphere on
//! two seeds, χ² ≈ 10): applying it made the sphere worse (0.33 → 0.55–0.60 mm RMS tilt).

use crate::integrate::fusion::PositionPrior;
use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use ndarray::Array2;

/// The fitted rigid correction of one object.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RigidCorrection {
    /// Offset added at the centroid, mm.
    pub offset_mm: f64,
    /// Its standard deviation, mm.
    pub offset_sigma_mm: f64,
    /// Slope of the residual along columns and rows, mm per pixel (reported, not applied).
    pub tilt_mm_per_px: [f64; 2],
    /// χ² of the fitted tilt against its covariance (two degrees of freedom; 9.2 is the 99 %
    /// point).
    pub tilt_chi2: f64,
    /// Centroid (column, row) of the fit's pixels.
    pub centroid_px: [f64; 2],
}

impl RigidCorrection {
    /// `depth` with the offset added (NaN stays NaN).
    pub fn apply(&self, depth: &Array2<f32>) -> Array2<f32> {
        depth.mapv(|z| z + self.offset_mm as f32)
    }
}

/// Fits the offset and tilt that move `depth` onto `prior` over the pixels where `use_pixel`
/// holds, the depth is finite and the prior has weight (module docs); `None` when fewer than
/// three such pixels or they are collinear.
pub fn fit_rigid(
    depth: &Array2<f32>,
    prior: &PositionPrior,
    use_pixel: &Array2<bool>,
) -> Option<RigidCorrection> {
    let samples: Vec<(f64, f64, f64, f64)> = depth
        .indexed_iter()
        .filter_map(|((r, c), &z)| {
            let (p, w) = (prior.depth_mm[(r, c)], prior.weight[(r, c)]);
            (use_pixel[(r, c)] && z.is_finite() && p.is_finite() && w.is_finite() && w > 0.0)
                .then(|| (c as f64, r as f64, f64::from(p - z), f64::from(w)))
        })
        .collect();
    if samples.len() < 3 {
        return None;
    }
    let total: f64 = samples.iter().map(|s| s.3).sum();
    let cx = samples.iter().map(|s| s.0 * s.3).sum::<f64>() / total;
    let cy = samples.iter().map(|s| s.1 * s.3).sum::<f64>() / total;
    let (mut normal, mut rhs) = (Matrix3::zeros(), Vector3::zeros());
    for &(x, y, r, w) in &samples {
        let v = Vector3::new(1.0, x - cx, y - cy);
        normal += w * v * v.transpose();
        rhs += w * r * v;
    }
    let covariance = normal.try_inverse()?;
    let plane = covariance * rhs;
    let tilt = Vector2::new(plane[1], plane[2]);
    let tilt_covariance = Matrix2::new(
        covariance[(1, 1)],
        covariance[(1, 2)],
        covariance[(2, 1)],
        covariance[(2, 2)],
    );
    let tilt_chi2 = tilt_covariance
        .try_inverse()
        .map_or(0.0, |inverse| (tilt.transpose() * inverse * tilt)[0]);
    // The weighted centroid decouples the offset from the tilt: a is the weighted mean.
    let correction = RigidCorrection {
        offset_mm: plane[0],
        offset_sigma_mm: covariance[(0, 0)].sqrt(),
        tilt_mm_per_px: [tilt[0], tilt[1]],
        tilt_chi2,
        centroid_px: [cx, cy],
    };
    correction.offset_mm.is_finite().then_some(correction)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    fn prior(truth: &Array2<f32>, sigma: f64, seed: u64) -> PositionPrior {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        PositionPrior {
            depth_mm: truth.mapv(|z| z + noise.sample(&mut rng) as f32),
            weight: Array2::from_elem(truth.dim(), (1.0 / (sigma * sigma)) as f32),
        }
    }

    /// A depth map off by an offset and a tilt: the offset found is the residual's weighted mean
    /// (within three of its σ), the tilt is found within its standard error and is significant;
    /// positions too noisy to know the tilt give a small χ² and a large σ; no pixel, no fit.
    #[test]
    fn offset_and_tilt_against_the_positions() {
        let (rows, cols) = (60, 80);
        let disc = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (r as f64 - 30.0).hypot(c as f64 - 40.0) < 25.0
        });
        let truth = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (100.0 - 0.01 * ((r as f64 - 30.0).powi(2) + (c as f64 - 40.0).powi(2))) as f32
        });
        // Off by −2 mm at the disc's centre (40, 30), tilted by (+0.02, −0.01) mm per pixel.
        let wrong = Array2::from_shape_fn((rows, cols), |(r, c)| {
            truth[(r, c)] - 2.0 + 0.02 * (c as f32 - 40.0) - 0.01 * (r as f32 - 30.0)
        });
        let fit = fit_rigid(&wrong, &prior(&truth, 1.0, 1), &disc).unwrap();
        assert!(fit.tilt_chi2 > 100.0, "{fit:?}");
        assert!((fit.tilt_mm_per_px[0] + 0.02).abs() < 0.002, "{fit:?}");
        assert!((fit.tilt_mm_per_px[1] - 0.01).abs() < 0.002, "{fit:?}");
        assert!(
            (fit.offset_mm - 2.0).abs() < 3.0 * fit.offset_sigma_mm,
            "{fit:?}"
        );
        assert!(fit.offset_sigma_mm < 0.05, "{fit:?}");
        let fixed = fit.apply(&wrong);
        assert!((fixed[(30, 40)] - truth[(30, 40)]).abs() < 0.1);

        // σ = 200 mm per pixel: the tilt is not significant.
        let fit = fit_rigid(&wrong, &prior(&truth, 200.0, 2), &disc).unwrap();
        assert!(fit.tilt_chi2 < 20.0, "{fit:?}");
        assert!(fit.offset_sigma_mm > 3.0, "{fit:?}");
        assert!(
            (fit.offset_mm - 2.0).abs() < 4.0 * fit.offset_sigma_mm,
            "{fit:?}"
        );
        let nowhere = Array2::from_elem((rows, cols), false);
        assert!(fit_rigid(&wrong, &prior(&truth, 1.0, 3), &nowhere).is_none());
    }
}
