//! Normal integration: normals → depth on the camera grid (SPEC §6, thesis §3.2).
//!
//! Normals become slopes ∂z/∂x = −n_x/n_z, ∂z/∂y = −n_y/n_z with y up (towards row 0)
//! ([`gradients`]). Two integrators work on arbitrary masks: masked least squares (the Poisson
//! equation restricted to the mask, solved by conjugate gradients with an aggregation-multigrid
//! preconditioner; [`least_squares`]) as the default, and the thesis' Fast Marching integrator
//! on W = z + λf ([`fast_marching`]). The thesis' artefact filter ([`filter`]) then drops points
//! that jump more than 10 mm from a neighbour. Both work on the mask's bounding box only.

pub mod fast_marching;
pub mod filter;
pub mod fusion;
pub mod gradients;
pub mod least_squares;
mod multigrid;

pub use filter::{ArtefactFilter, filter_artefacts};
pub use gradients::SurfaceGradients;

use crate::types::{DepthMap, NormalField};
use ndarray::{Array2, s};
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
    gradients::check_field_shape(field)?;
    let shape = field.mask.dim();
    check_pitch(pitch_mm)?;
    let window = Window::around(&field.mask).ok_or(IntegrateError::EmptyMask)?;
    let gradients = SurfaceGradients::from_normal_views(
        field
            .normals
            .slice(s![window.rows.clone(), window.cols.clone(), ..]),
        window.view(&field.mask),
        config.max_slope,
    )
    .map_err(|e| window.shift_error(e))?;
    integrate_window(&gradients, &window, shape, pitch_mm, config, initial)
}

/// Integrates slopes ∂z/∂x, ∂z/∂y (dimensionless) with grid pitch `pitch_mm`.
pub fn integrate_gradients(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    check_pitch(pitch_mm)?;
    gradients.check_shapes()?;
    let shape = gradients.mask.dim();
    let window = Window::around(&gradients.mask).ok_or(IntegrateError::EmptyMask)?;
    let cropped = SurfaceGradients {
        dzdx: window.view(&gradients.dzdx).to_owned(),
        dzdy: window.view(&gradients.dzdy).to_owned(),
        mask: window.view(&gradients.mask).to_owned(),
    };
    integrate_window(&cropped, &window, shape, pitch_mm, config, initial)
}

/// Rejects a grid pitch that is not a positive finite number.
fn check_pitch(pitch_mm: f64) -> Result<(), IntegrateError> {
    if pitch_mm.is_finite() && pitch_mm > 0.0 {
        Ok(())
    } else {
        Err(IntegrateError::BadPitch(pitch_mm))
    }
}

/// Integrates `gradients` cropped to `window` of a `shape` grid and places the result in it.
fn integrate_window(
    gradients: &SurfaceGradients,
    window: &Window,
    shape: (usize, usize),
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    gradients.validate().map_err(|e| window.shift_error(e))?;
    let initial = initial
        .filter(|d| d.dim() == shape)
        .map(|d| window.view(d).to_owned());
    let (mut depth, iterations) = match config.integrator {
        Integrator::LeastSquares => {
            least_squares::integrate(gradients, pitch_mm, config, initial.as_ref())?
        }
        Integrator::FastMarching => fast_marching::integrate(gradients, pitch_mm, config.lambda)?,
    };
    let valid = depth.mapv(f64::is_finite);
    anchor(&mut depth, &valid, config.anchor);
    let (kept, kept_fraction) = filter_artefacts(&depth, &valid, &config.filter);
    let mut depth_mm = Array2::from_elem(shape, f32::NAN);
    let mut kept_full = Array2::from_elem(shape, false);
    ndarray::Zip::from(window.view_mut(&mut depth_mm))
        .and(window.view_mut(&mut kept_full))
        .and(&depth)
        .and(&kept)
        .for_each(|out, k_out, &z, &k| {
            if k {
                *out = z as f32;
                *k_out = true;
            }
        });
    Ok(Integration {
        depth: DepthMap { depth_mm, pitch_mm },
        kept: kept_full,
        kept_fraction,
        iterations,
    })
}

/// The bounding box of a mask: everything outside it is unmasked, so integrating inside it gives
/// the same result as on the whole grid at a fraction of the cost.
struct Window {
    rows: std::ops::Range<usize>,
    cols: std::ops::Range<usize>,
}

impl Window {
    /// The smallest box holding every set pixel of `mask`, or `None` if there is none.
    fn around(mask: &Array2<bool>) -> Option<Self> {
        let mut rows: Option<(usize, usize)> = None;
        let (mut c0, mut c1) = (usize::MAX, 0);
        for (r, row) in mask.outer_iter().enumerate() {
            let first = row.iter().position(|&m| m);
            if let Some(first) = first {
                let last = row.len() - 1 - row.iter().rev().position(|&m| m).unwrap_or(0);
                rows = Some((rows.map_or(r, |(r0, _)| r0), r + 1));
                c0 = c0.min(first);
                c1 = c1.max(last + 1);
            }
        }
        rows.map(|(r0, r1)| Self {
            rows: r0..r1,
            cols: c0..c1,
        })
    }

    /// The part of `a` inside the window.
    fn view<'a, T>(&self, a: &'a Array2<T>) -> ndarray::ArrayView2<'a, T> {
        a.slice(s![self.rows.clone(), self.cols.clone()])
    }

    /// The part of `a` inside the window, mutable.
    fn view_mut<'a, T>(&self, a: &'a mut Array2<T>) -> ndarray::ArrayViewMut2<'a, T> {
        a.slice_mut(s![self.rows.clone(), self.cols.clone()])
    }

    /// Moves pixel positions in an error from window to grid coordinates.
    fn shift_error(&self, e: IntegrateError) -> IntegrateError {
        match e {
            IntegrateError::NonFinite { count, row, col } => IntegrateError::NonFinite {
                count,
                row: row + self.rows.start,
                col: col + self.cols.start,
            },
            other => other,
        }
    }
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
