//! Normal integration: normals → depth on the camera grid (SPEC §6, thesis §3.2).
//!
//! Normals become slopes ∂z/∂x = −n_x/n_z, ∂z/∂y = −n_y/n_z with y up (towards row 0)
//! ([`gradients`]). Two integrators work on arbitrary masks: masked least squares (the Poisson
//! equation restricted to the mask, solved by conjugate gradients with a modified incomplete
//! Cholesky preconditioner; [`least_squares`]) as the default, and the thesis' Fast Marching
//! integrator on W = z + λf ([`fast_marching`]). The thesis' artefact filter ([`filter`]) then
//! drops points that jump more than 10 mm from a neighbour.

pub mod fast_marching;
pub mod filter;
pub mod gradients;
pub mod least_squares;

pub use filter::{ArtefactFilter, filter_artefacts};
pub use gradients::SurfaceGradients;

use crate::types::{DepthMap, NormalField};
use ndarray::Array2;
use thiserror::Error;

/// Which integrator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Masked least squares (Poisson) with a preconditioned conjugate-gradient solver.
    #[default]
    LeastSquares,
    /// The thesis' Fast Marching integrator (W = z + λf).
    FastMarching,
}

/// Where depth zero is put (integration fixes depth only up to a constant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthAnchor {
    /// The mean depth along the mask's outline is zero (the silhouette lies on z = 0, as for a
    /// sphere centred at the rig's origin).
    #[default]
    Outline,
    /// The mean depth over the mask is zero.
    Mean,
}

/// Settings of the integration stage.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IntegrateConfig {
    /// The integrator.
    pub integrator: Integrator,
    /// Slopes are clipped to ±this (steep rims would otherwise dominate).
    pub max_slope: f64,
    /// Fast Marching weight λ of the squared-distance term, per pixel² (thesis: 0.06).
    pub lambda: f64,
    /// Relative residual at which conjugate gradients stops.
    pub tolerance: f64,
    /// Iteration cap of conjugate gradients.
    pub max_iterations: usize,
    /// Where depth zero is put.
    pub anchor: DepthAnchor,
    /// Artefact filter (thesis: drop points jumping > 10 mm from a neighbour).
    pub filter: ArtefactFilter,
}

impl Default for IntegrateConfig {
    fn default() -> Self {
        Self {
            integrator: Integrator::LeastSquares,
            max_slope: 20.0,
            lambda: 0.06,
            tolerance: 1e-7,
            max_iterations: 5000,
            anchor: DepthAnchor::Outline,
            filter: ArtefactFilter::default(),
        }
    }
}

/// Errors of normal integration.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum IntegrateError {
    /// The mask has no pixel with a usable neighbour.
    #[error("empty mask: no two neighbouring pixels to integrate between")]
    EmptyMask,
    /// Normals or slopes inside the mask are NaN or infinite.
    #[error(
        "{count} pixels inside the mask have NaN or infinite normals/slopes (first at row {row}, column {col})"
    )]
    NonFinite {
        /// How many.
        count: usize,
        /// First offending pixel.
        row: usize,
        /// First offending pixel.
        col: usize,
    },
    /// Inputs of different sizes.
    #[error("{what} is {got:?}, expected {expected:?} (rows, columns)")]
    SizeMismatch {
        /// Which input.
        what: String,
        /// Its shape.
        got: (usize, usize),
        /// The expected shape.
        expected: (usize, usize),
    },
    /// The grid pitch is not a positive number.
    #[error("grid pitch must be a positive number of mm per pixel, got {0}")]
    BadPitch(f64),
}

/// Result of integrating one normal field.
#[derive(Debug, Clone)]
pub struct Integration {
    /// Depth in mm (NaN outside the kept pixels).
    pub depth: DepthMap,
    /// Pixels kept after the artefact filter.
    pub kept: Array2<bool>,
    /// Fraction of the integrated mask kept by the artefact filter (0..1).
    pub kept_fraction: f64,
    /// Solver iterations (conjugate gradients) or accepted pixels (Fast Marching).
    pub iterations: usize,
}

/// Integrates a normal field with grid pitch `pitch_mm`; `initial` warm-starts least squares.
pub fn integrate_normals(
    field: &NormalField,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    let gradients = SurfaceGradients::from_normals(field, config.max_slope)?;
    integrate_gradients(&gradients, pitch_mm, config, initial)
}

/// Integrates slopes ∂z/∂x, ∂z/∂y (dimensionless) with grid pitch `pitch_mm`.
pub fn integrate_gradients(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
        return Err(IntegrateError::BadPitch(pitch_mm));
    }
    gradients.validate()?;
    let (mut depth, iterations) = match config.integrator {
        Integrator::LeastSquares => least_squares::integrate(gradients, pitch_mm, config, initial)?,
        Integrator::FastMarching => fast_marching::integrate(gradients, pitch_mm, config.lambda)?,
    };
    let valid = depth.mapv(f64::is_finite);
    anchor(&mut depth, &valid, config.anchor);
    let (kept, kept_fraction) = filter_artefacts(&depth, &valid, &config.filter);
    let depth_mm = Array2::from_shape_fn(depth.dim(), |p| {
        if kept[p] { depth[p] as f32 } else { f32::NAN }
    });
    Ok(Integration {
        depth: DepthMap { depth_mm, pitch_mm },
        kept,
        kept_fraction,
        iterations,
    })
}

/// Shifts `depth` by a constant according to `anchor`.
fn anchor(depth: &mut Array2<f64>, valid: &Array2<bool>, anchor: DepthAnchor) {
    let (rows, cols) = depth.dim();
    let on_outline = |r: usize, c: usize| {
        r == 0
            || c == 0
            || r + 1 == rows
            || c + 1 == cols
            || !valid[(r - 1, c)]
            || !valid[(r + 1, c)]
            || !valid[(r, c - 1)]
            || !valid[(r, c + 1)]
    };
    let (mut sum, mut n) = (0.0, 0usize);
    for ((r, c), &v) in valid.indexed_iter() {
        if v && (anchor == DepthAnchor::Mean || on_outline(r, c)) {
            sum += depth[(r, c)];
            n += 1;
        }
    }
    if n > 0 {
        let offset = sum / n as f64;
        depth.mapv_inplace(|z| z - offset);
    }
}
