//! Depth errors: RMSE after removing the best constant offset, NRMSE, % reconstructed.

use super::MetricsError;
use ndarray::Array2;

/// Depth accuracy of one reconstruction.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DepthErrors {
    /// RMSE in mm after removing the best constant offset.
    pub rmse_mm: f64,
    /// RMSE / (max − min of the true depth over the compared pixels); `None` (JSON `null`)
    /// when the true depth is flat.
    pub nrmse: Option<f64>,
    /// Fraction (0..1) of true-surface pixels with an estimate.
    pub reconstructed_fraction: f64,
    /// Pixels compared.
    pub compared_pixels: usize,
    /// The offset removed (mean of estimate − truth), mm.
    pub offset_mm: f64,
    /// Per-pixel signed error after the offset, mm (NaN where not compared).
    #[serde(skip)]
    pub error_map: Array2<f32>,
}

/// Compares `estimate` with `truth` (both mm, NaN = none) over the truth's finite pixels,
/// restricted to `surface` when given.
pub fn compare_depth(
    estimate: &Array2<f32>,
    truth: &Array2<f32>,
    surface: Option<&Array2<bool>>,
) -> Result<DepthErrors, MetricsError> {
    if estimate.dim() != truth.dim() || surface.is_some_and(|s| s.dim() != truth.dim()) {
        return Err(MetricsError::SizeMismatch {
            estimate: estimate.dim(),
            truth: truth.dim(),
        });
    }
    let on_surface = |p: (usize, usize)| truth[p].is_finite() && surface.is_none_or(|s| s[p]);
    let mut surface_pixels = 0usize;
    let mut pairs = Vec::new();
    for (p, &t) in truth.indexed_iter() {
        if !on_surface(p) {
            continue;
        }
        surface_pixels += 1;
        let e = estimate[p];
        if e.is_finite() {
            pairs.push((p, f64::from(e), f64::from(t)));
        }
    }
    if pairs.is_empty() {
        return Err(MetricsError::NoOverlap);
    }
    let n = pairs.len() as f64;
    let offset = pairs.iter().map(|(_, e, t)| e - t).sum::<f64>() / n;
    let mse = pairs
        .iter()
        .map(|(_, e, t)| (e - t - offset).powi(2))
        .sum::<f64>()
        / n;
    let (lo, hi) = pairs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (_, _, t)| {
            (lo.min(*t), hi.max(*t))
        });
    let rmse = mse.sqrt();
    let mut error_map = Array2::from_elem(truth.dim(), f32::NAN);
    for (p, e, t) in &pairs {
        error_map[*p] = (e - t - offset) as f32;
    }
    Ok(DepthErrors {
        rmse_mm: rmse,
        nrmse: (hi > lo).then(|| rmse / (hi - lo)),
        reconstructed_fraction: pairs.len() as f64 / surface_pixels as f64,
        compared_pixels: pairs.len(),
        offset_mm: offset,
        error_map,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_is_removed_and_coverage_counted() {
        let truth = Array2::from_shape_fn((4, 4), |(r, c)| (r + c) as f32);
        let mut est = truth.mapv(|t| t + 5.0);
        est[(0, 0)] += 1.0;
        est[(3, 3)] = f32::NAN;
        let e = compare_depth(&est, &truth, None).unwrap();
        assert!((e.reconstructed_fraction - 15.0 / 16.0).abs() < 1e-12);
        // errors: one pixel +1 among 15 → offset 5 + 1/15, RMSE = sqrt(1/15 · 14/15).
        assert!(
            (e.rmse_mm - (14.0f64 / 225.0).sqrt()).abs() < 1e-6,
            "{}",
            e.rmse_mm
        );
        assert!(e.nrmse.is_some_and(|n| (n - e.rmse_mm / 5.0).abs() < 1e-9));
        let none = Array2::from_elem((4, 4), f32::NAN);
        assert!(matches!(
            compare_depth(&none, &truth, None),
            Err(MetricsError::NoOverlap)
        ));
    }
}
