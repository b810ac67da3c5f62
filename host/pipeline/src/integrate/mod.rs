//! Normal integration: normals → depth on the camera grid
//! (docs/maths/integration.md#normal-integration, thesis §3.2).
//!
//! Normals become slopes of the unknown (\[`grid`\]): the height z with ∂z/∂x = −n_x/n_z,
//! ∂z/∂y = −n_y/n_z (y up, towards row 0) for an orthographic camera, or a pixel-unit log depth
//! for a perspective one (Quéau, Durou & Aujol, "Normal integration: a survey", 2018). Three
//! integrators work on arbitrary masks:
//!
//! - masked least squares (the Poisson equation on the mask; [`least_squares`]), the default;
//! - bilateral normal integration (Cao et al., ECCV 2022; [`bilateral`]): weighted least
//!   squares whose weights let depth jump where the surface is discontinuous;
//! - the thesis' Fast Marching integrator on W = z + λf ([`fast_marching`]).
//!
//! The least-squares solves use conjugate gradients with an aggregation-multigrid preconditioner
//! (\[`multigrid`\]). Pixels lit by only two LEDs and holes inside the object are integrated too
//! ([`coverage`]), so the object is not cut into islands; separate pieces of the mask are anchored
//! (and Fast-Marched) separately. Depth zero is put on each piece's outline. The thesis' artefact
//! filter ([`filter`]) then drops points that jump more than 10 mm from a neighbour. Everything
//! runs on the mask's bounding box only.

mod band_cholesky;
pub mod bilateral;
pub mod coverage;
pub mod fast_marching;
pub mod filter;
pub mod fusion;
pub mod gradients;
pub(crate) mod grid;
mod inpaint;
pub mod least_squares;
mod multigrid;
mod operators;
mod output;
mod parts;
mod passes;
mod pcg;
mod solve;
mod warm;
mod window;
pub mod workspace;

pub use coverage::NormalPlane;
pub use filter::{ArtefactFilter, filter_artefacts};
pub use gradients::SurfaceGradients;
pub use workspace::{IntegrationProfile, IntegrationWorkspace};

use grid::DepthGrid;
use meb_core::rig::Projection;
pub use meb_core::types::Confidence;
use meb_core::types::{DepthMap, NormalField};
use nalgebra::Vector3;
use ndarray::{Array2, Array3};
use rayon::prelude::*;
use solve::{Problem, solve_window};
use std::time::Instant;
use thiserror::Error;
use window::Window;

/// Which integrator to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Bilateral normal integration: discontinuity-preserving weighted least squares. Better
    /// across depth discontinuities (Suzanne through `meb reconstruct` 4.9 mm vs 7.6 mm), worse
    /// on smooth surfaces (vase NRMSE 0.35 % vs 0.15 %), so not the default.
    Bilateral,
    /// Masked least squares (Poisson) with a preconditioned conjugate-gradient solver (default).
    #[default]
    LeastSquares,
    /// The thesis' Fast Marching integrator (W = z + λf).
    FastMarching,
    /// Least squares with the depth discontinuities cut: bilateral reweighting finds the grid
    /// edges across which both one-sided equations turn away (the surface jumps there), then
    /// plain least squares is solved with those edges removed. Quadratic (least squares) where
    /// the surface is continuous, discontinuity-preserving where it is not; the decision comes
    /// from the normals alone ([`Integration::discontinuity_edges`]).
    Auto,
}

/// Where depth zero is put (integration fixes depth only up to a constant per piece).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepthAnchor {
    /// The mean depth along each piece's outline is zero (the silhouette lies on z = 0, as for a
    /// sphere centred at the rig's origin).
    #[default]
    Outline,
    /// The mean depth over each piece is zero.
    Mean,
}

/// Settings of bilateral normal integration (Cao et al. 2022).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BilateralConfig {
    /// Stiffness k of the sigmoid weights (paper: 2); larger cuts at smaller jumps but leans
    /// one-sided on smooth curved surfaces too (vase NRMSE 0.35 % at 2, 0.67 % at 10).
    pub stiffness: f64,
    /// Most reweighting iterations.
    pub max_iterations: usize,
    /// Relative energy change below which the iterations stop.
    pub tolerance: f64,
}

impl Default for BilateralConfig {
    fn default() -> Self {
        Self {
            stiffness: 2.0,
            max_iterations: 100,
            tolerance: 1e-4,
        }
    }
}

/// Settings of the automatic integrator ([`Integrator::Auto`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AutoConfig {
    /// A pixel is near a discontinuity when one of its one-sided bilateral weights is below
    /// this (the surface continues on one side only).
    pub decisive_weight: f64,
    /// ... and the depth across that side's edge departs from the edge's slopes by at least
    /// this many pixels (0: no such test). Noise makes stiff weights decisive on smooth
    /// surfaces, where depth still follows the slopes.
    pub min_jump_px: f64,
    /// ... and the pixels on that side run on along the axis for at least this many grid
    /// steps: at the end of a line the one-sided differences of a steep rim differ by its
    /// curvature alone.
    pub rim: usize,
    /// Pixels within this many grid steps of such a pixel keep their bilateral weights.
    pub radius: usize,
    /// A grid edge is cut only when, besides both its one-sided weights turning away and the
    /// run-on and jump tests above, it belongs to a chain of at least this many cut edges
    /// joined end to end: a discontinuity is a curve, noise cuts an edge here and there.
    pub min_cut_chain: usize,
}

impl Default for AutoConfig {
    fn default() -> Self {
        Self {
            decisive_weight: 0.05,
            min_jump_px: 0.0,
            rim: 2,
            radius: 2,
            min_cut_chain: 4,
        }
    }
}

/// Settings of pixels without a full normal ([`coverage`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CoverageConfig {
    /// Weight of a two-LED pixel's equations relative to a measured pixel's.
    pub two_led_weight: f64,
    /// Weight of a filled hole pixel's equations.
    pub fill_weight: f64,
    /// Most depth ↔ normal alternations for two-LED pixels (least squares; the bilateral
    /// integrator alternates once per reweighting).
    pub iterations: usize,
    /// Relative energy change below which the alternations stop.
    pub tolerance: f64,
}

impl Default for CoverageConfig {
    fn default() -> Self {
        Self {
            two_led_weight: 1.0,
            fill_weight: 0.1,
            iterations: 50,
            tolerance: 1e-4,
        }
    }
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
    /// Bilateral integrator settings.
    pub bilateral: BilateralConfig,
    /// Automatic integrator settings.
    #[serde(default)]
    pub auto: AutoConfig,
    /// Two-LED pixels and holes.
    pub coverage: CoverageConfig,
    /// Where depth zero is put.
    pub anchor: DepthAnchor,
    /// Artefact filter (thesis: drop points jumping > 10 mm from a neighbour).
    pub filter: ArtefactFilter,
}

impl Default for IntegrateConfig {
    fn default() -> Self {
        Self {
            integrator: Integrator::default(),
            max_slope: 20.0,
            lambda: 0.06,
            tolerance: 1e-7,
            max_iterations: 5000,
            bilateral: BilateralConfig::default(),
            auto: AutoConfig::default(),
            coverage: CoverageConfig::default(),
            anchor: DepthAnchor::Outline,
            filter: ArtefactFilter::default(),
        }
    }
}

impl IntegrateConfig {
    /// Checks every setting; the error names the first bad one.
    pub fn validate(&self) -> Result<(), IntegrateError> {
        let positive = |name: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(IntegrateError::BadSetting {
                    name,
                    value: v,
                    reason: "must be a positive number",
                })
            }
        };
        positive("lambda", self.lambda)?;
        positive("max_slope", self.max_slope)?;
        positive("tolerance", self.tolerance)?;
        positive("bilateral stiffness", self.bilateral.stiffness)?;
        positive("bilateral tolerance", self.bilateral.tolerance)?;
        positive("auto decisive weight", self.auto.decisive_weight)?;
        if !(self.auto.min_jump_px.is_finite() && self.auto.min_jump_px >= 0.0) {
            return Err(IntegrateError::BadSetting {
                name: "auto min_jump_px",
                value: self.auto.min_jump_px,
                reason: "must be a number ≥ 0",
            });
        }
        positive("two-LED weight", self.coverage.two_led_weight)?;
        positive("fill weight", self.coverage.fill_weight)?;
        positive("coverage tolerance", self.coverage.tolerance)?;
        if let Some(jump) = self.filter.max_jump_mm {
            positive("artefact filter jump", jump)?;
        }
        for (name, count) in [
            ("max_iterations", self.max_iterations),
            ("bilateral max_iterations", self.bilateral.max_iterations),
            ("coverage iterations", self.coverage.iterations),
        ] {
            if count == 0 {
                return Err(IntegrateError::BadSetting {
                    name,
                    value: 0.0,
                    reason: "must be at least 1",
                });
            }
        }
        Ok(())
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
    /// No normal inside the mask can be turned into slopes.
    #[error(
        "no usable normal inside the mask: {zero} are zero and {facing_away} face away from the camera or lie edge-on"
    )]
    NoUsableNormals {
        /// Zero-length normals.
        zero: usize,
        /// Normals with n·v ≤ 0 (or nearly).
        facing_away: usize,
    },
    /// A setting is out of range.
    #[error("integration setting {name} = {value}: {reason}")]
    BadSetting {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
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
    /// Solver iterations (conjugate gradients, summed over reweightings) or accepted pixels
    /// (Fast Marching).
    pub iterations: usize,
    /// Reweighting / coverage passes of the least-squares solver (1 for a plain solve).
    pub passes: usize,
    /// Separately anchored pieces of the integrated mask.
    pub pieces: usize,
    /// Piece of every kept pixel (`u32::MAX` elsewhere).
    pub piece: Array2<u32>,
    /// Parts: the pieces split further along depth discontinuities that the bilateral
    /// integrator found all the way across one (the normals cannot tell their relative depth).
    pub parts: usize,
    /// Part of every kept pixel (`u32::MAX` elsewhere).
    pub part: Array2<u32>,
    /// How each pixel's depth is known ([`Confidence::None`] where not kept).
    pub confidence: Array2<Confidence>,
    /// Normals the integrator chose for two-LED and filled pixels (NaN elsewhere).
    pub completed_normals: Array3<f32>,
    /// [`Integrator::Auto`]: the grid edges it found to be depth discontinuities and cut
    /// (zero: the result is the plain least-squares one); `None` for the other integrators.
    pub discontinuity_edges: Option<usize>,
    /// [`Integrator::Auto`]: the pixels near discontinuities that kept their bilateral
    /// weights (zero: plain least squares); `None` for the other integrators.
    pub bilateral_pixels: Option<usize>,
}

/// What is known about the surface, for [`integrate_surface`].
#[derive(Debug, Clone, Copy)]
pub struct SurfaceEvidence<'a> {
    /// Measured normals inside `field.mask`.
    pub field: &'a NormalField,
    /// Pixels lit by exactly two LEDs.
    pub planes: &'a [NormalPlane],
    /// Pixels to reconstruct with no normal information (holes inside the object).
    pub fill: Option<&'a Array2<bool>>,
}

/// Integrates a normal field on an orthographic grid of pitch `pitch_mm`; `initial` (depth in
/// mm) warm-starts the least-squares solvers.
pub fn integrate_normals(
    field: &NormalField,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    check_pitch(pitch_mm)?;
    let shape = field.mask.dim();
    integrate_surface(
        &SurfaceEvidence {
            field,
            planes: &[],
            fill: None,
        },
        &Projection::centred(pitch_mm, (shape.1, shape.0)),
        config,
        initial,
    )
}

/// Integrates normals, two-LED pixels and holes ([`SurfaceEvidence`]) seen through `projection`.
pub fn integrate_surface(
    evidence: &SurfaceEvidence,
    projection: &Projection,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    integrate_surface_with(
        evidence,
        projection,
        config,
        initial,
        &mut IntegrationWorkspace::new(),
    )
}

/// [`integrate_surface`] with a [`IntegrationWorkspace`] kept by the caller between related
/// problems (the passes of a reconstruction, the windows of a video): the integration graph of
/// the last call is reused when the mask is the same, and the workspace records where the time
/// went ([`IntegrationWorkspace::profile`]).
pub fn integrate_surface_with(
    evidence: &SurfaceEvidence,
    projection: &Projection,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
    workspace: &mut IntegrationWorkspace,
) -> Result<Integration, IntegrateError> {
    workspace.profile = IntegrationProfile::default();
    let started = Instant::now();
    config.validate()?;
    let field = evidence.field;
    gradients::check_field_shape(field)?;
    let shape = field.mask.dim();
    if let Projection::Orthographic { pitch_mm, .. } = projection {
        check_pitch(*pitch_mm)?;
    }
    if let Some(fill) = evidence.fill
        && fill.dim() != shape
    {
        return Err(IntegrateError::SizeMismatch {
            what: "fill mask".into(),
            got: fill.dim(),
            expected: shape,
        });
    }
    if let Some(p) = evidence
        .planes
        .iter()
        .find(|p| p.pixel.0 >= shape.0 || p.pixel.1 >= shape.1)
    {
        return Err(IntegrateError::SizeMismatch {
            what: format!("two-LED pixel {:?}", p.pixel),
            got: p.pixel,
            expected: shape,
        });
    }
    let grid = DepthGrid::new(projection);
    // Every mask, fill and two-LED pixel is integrated (a mask pixel without a slope is filled
    // in): the window is their bounding box, and the pixel classes are found inside it only.
    let window = Window::around_all(
        &[Some(&field.mask), evidence.fill]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>(),
        evidence.planes.iter().map(|p| p.pixel),
    )
    .ok_or(IntegrateError::EmptyMask)?;
    let origin = (window.rows.start, window.cols.start);
    let inner = (window.rows.len(), window.cols.len());
    let mut class = match evidence.fill {
        Some(fill) => window.view(fill).mapv(|f| {
            if f {
                Confidence::Filled
            } else {
                Confidence::None
            }
        }),
        None => Array2::from_elem(inner, Confidence::None),
    };
    for p in evidence.planes {
        class[(p.pixel.0 - origin.0, p.pixel.1 - origin.1)] = Confidence::TwoLeds;
    }
    let (slopes, zero) = classify_pixels(field, &grid, &window, config.max_slope, &mut class)?;
    if !class
        .iter()
        .any(|&k| k == Confidence::Measured || k == Confidence::TwoLeds)
    {
        let total = field.mask.iter().filter(|&&m| m).count();
        if total > 0 {
            return Err(IntegrateError::NoUsableNormals {
                zero,
                facing_away: total - zero,
            });
        }
        return Err(IntegrateError::EmptyMask);
    }
    let problem = Problem {
        planes: evidence
            .planes
            .iter()
            .map(|p| NormalPlane {
                pixel: (p.pixel.0 - origin.0, p.pixel.1 - origin.1),
                ..*p
            })
            .filter(|p| class[p.pixel] == Confidence::TwoLeds)
            .collect(),
        class,
        slopes,
        albedo: window.view(&field.albedo).mapv(f64::from),
        origin,
        grid,
    };
    workspace.profile.add("pixel classes and slopes", started);
    solve_window(&problem, &window, shape, config, initial, workspace)
}

/// Rows of the window per parallel task when its pixels are classified.
const ROWS_PER_TASK: usize = 8;

/// What classifying one row of the window found: normals with a non-finite component (how
/// many, and the first one's pixel) and zero normals.
#[derive(Default)]
struct RowTally {
    non_finite: usize,
    first_non_finite: Option<(usize, usize)>,
    zero: usize,
}

/// Classifies the mask's pixels of `window` in `class` (window-sized; holes and two-LED pixels
/// marked already): `Measured` with their slopes (clipped to ±`max_slope`) where the normal has
/// one, `Filled` where it faces away and nothing else is known. Returns the slopes (0 elsewhere)
/// and how many normals were zero; a non-finite normal is an error. Rows in parallel.
fn classify_pixels(
    field: &NormalField,
    grid: &DepthGrid,
    window: &Window,
    max_slope: f64,
    class: &mut Array2<Confidence>,
) -> Result<(Array2<(f64, f64)>, usize), IntegrateError> {
    let origin = (window.rows.start, window.cols.start);
    let inner = (window.rows.len(), window.cols.len());
    if class.as_slice().is_none() {
        *class = class.as_standard_layout().into_owned();
    }
    let mut slopes = Array2::from_elem(inner, (0.0, 0.0));
    let mask = window.view(&field.mask);
    let (Some(class_all), Some(slopes_all)) = (class.as_slice_mut(), slopes.as_slice_mut()) else {
        unreachable!("arrays in standard layout")
    };
    let tallies: Vec<RowTally> = class_all
        .par_chunks_mut(inner.1)
        .zip(slopes_all.par_chunks_mut(inner.1))
        .enumerate()
        .with_min_len(ROWS_PER_TASK)
        .map(|(wr, (class_row, slope_row))| {
            let mut tally = RowTally::default();
            let r = wr + origin.0;
            let cells = class_row.iter_mut().zip(slope_row).zip(mask.row(wr));
            for (wc, ((class, slope), &m)) in cells.enumerate() {
                if !m {
                    continue;
                }
                let c = wc + origin.1;
                let n = Vector3::from([0, 1, 2].map(|j| f64::from(field.normals[(r, c, j)])));
                if !n.iter().all(|v| v.is_finite()) {
                    tally.first_non_finite.get_or_insert((r, c));
                    tally.non_finite += 1;
                    continue;
                }
                // A normal facing away from the camera carries no slope: the pixel is a hole.
                if n.norm() == 0.0 {
                    tally.zero += 1;
                }
                match grid.slopes(r, c, &n) {
                    Some((sx, sy)) => {
                        *class = Confidence::Measured;
                        *slope = (
                            sx.clamp(-max_slope, max_slope),
                            sy.clamp(-max_slope, max_slope),
                        );
                    }
                    None if *class == Confidence::None => *class = Confidence::Filled,
                    None => {}
                }
            }
            tally
        })
        .collect();
    let non_finite: usize = tallies.iter().map(|t| t.non_finite).sum();
    if let Some((row, col)) = tallies.iter().find_map(|t| t.first_non_finite) {
        return Err(IntegrateError::NonFinite {
            count: non_finite,
            row,
            col,
        });
    }
    Ok((slopes, tallies.iter().map(|t| t.zero).sum()))
}

/// Integrates slopes ∂z/∂x, ∂z/∂y (dimensionless) with grid pitch `pitch_mm` (orthographic).
pub fn integrate_gradients(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Integration, IntegrateError> {
    config.validate()?;
    check_pitch(pitch_mm)?;
    gradients.check_shapes()?;
    let shape = gradients.mask.dim();
    let window = Window::around(&gradients.mask).ok_or(IntegrateError::EmptyMask)?;
    let cropped = SurfaceGradients {
        dzdx: window.view(&gradients.dzdx).to_owned(),
        dzdy: window.view(&gradients.dzdy).to_owned(),
        mask: window.view(&gradients.mask).to_owned(),
    };
    cropped.validate().map_err(|e| window.shift_error(e))?;
    let problem = Problem {
        class: cropped.mask.mapv(|m| {
            if m {
                Confidence::Measured
            } else {
                Confidence::None
            }
        }),
        slopes: Array2::from_shape_fn(cropped.mask.dim(), |p| (cropped.dzdx[p], cropped.dzdy[p])),
        planes: Vec::new(),
        albedo: Array2::from_elem(cropped.mask.dim(), f64::NAN),
        origin: (window.rows.start, window.cols.start),
        grid: DepthGrid::Orthographic { pitch_mm },
    };
    solve_window(
        &problem,
        &window,
        shape,
        config,
        initial,
        &mut IntegrationWorkspace::new(),
    )
}

/// Rejects a grid pitch that is not a positive finite number.
fn check_pitch(pitch_mm: f64) -> Result<(), IntegrateError> {
    if pitch_mm.is_finite() && pitch_mm > 0.0 {
        Ok(())
    } else {
        Err(IntegrateError::BadPitch(pitch_mm))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::rig::{Camera, Intrinsics};

    /// Depth RMSE of `got` against `truth` over `mask` after removing the mean difference.
    fn rmse(got: &Array2<f32>, truth: &Array2<f64>, mask: &Array2<bool>) -> f64 {
        let d: Vec<f64> = mask
            .indexed_iter()
            .filter(|(p, m)| **m && got[*p].is_finite())
            .map(|(p, _)| f64::from(got[p]) - truth[p])
            .collect();
        assert!(!d.is_empty());
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        (d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt()
    }

    /// Unit normal of slopes (p, q) on an orthographic grid.
    fn normal(p: f64, q: f64) -> Vector3<f64> {
        Vector3::new(-p, -q, 1.0).normalize()
    }

    fn field_of(normals: &Array2<Vector3<f64>>, mask: &Array2<bool>) -> NormalField {
        let (rows, cols) = mask.dim();
        NormalField {
            normals: Array3::from_shape_fn((rows, cols, 3), |(r, c, j)| {
                if mask[(r, c)] {
                    normals[(r, c)][j] as f32
                } else {
                    f32::NAN
                }
            }),
            albedo: Array2::ones((rows, cols)),
            mask: mask.clone(),
        }
    }

    /// A tilted terrace: z = 0.3 x on the left, z = 0.3 x + 15 px on the right, and one column
    /// of wall between them seen nearly edge-on, its measured slope wrong by a different amount
    /// in every row (as at a real occluding contour). Least squares spreads that inconsistency
    /// and bends both terraces; the bilateral integrator cuts at the wall and keeps each planar.
    #[test]
    fn bilateral_keeps_both_sides_of_a_step_planar() {
        let (rows, cols) = (40usize, 60usize);
        let wall = 30;
        let truth = Array2::from_shape_fn((rows, cols), |(_, c)| {
            0.3 * c as f64 + if c > wall { 15.0 } else { 0.0 }
        });
        let normals = Array2::from_shape_fn((rows, cols), |(r, c)| {
            if c == wall {
                normal(5.0 + 0.5 * r as f64, 0.0)
            } else {
                normal(0.3, 0.0)
            }
        });
        let mask = Array2::from_elem((rows, cols), true);
        let field = field_of(&normals, &mask);
        let side_rmse = |integrator| {
            let config = IntegrateConfig {
                integrator,
                filter: ArtefactFilter { max_jump_mm: None },
                ..IntegrateConfig::default()
            };
            let out = integrate_normals(&field, 1.0, &config, None).unwrap();
            let left = Array2::from_shape_fn((rows, cols), |(_, c)| c < wall);
            let right = Array2::from_shape_fn((rows, cols), |(_, c)| c > wall);
            rmse(&out.depth.depth_mm, &truth, &left).max(rmse(&out.depth.depth_mm, &truth, &right))
        };
        let ls = side_rmse(Integrator::LeastSquares);
        let bilateral = side_rmse(Integrator::Bilateral);
        assert!(
            bilateral < 0.15 && ls > 5.0 * bilateral,
            "least squares {ls} px vs bilateral {bilateral} px"
        );
    }

    /// The automatic integrator on the terrace of the test above keeps the wall (both sides
    /// planar, as bilateral, with bilateral weights beside the wall) and on a smooth hemisphere
    /// weighs nothing as bilateral and gives the least-squares depth.
    #[test]
    fn auto_cuts_a_step_and_leaves_a_smooth_surface_to_least_squares() {
        let (rows, cols) = (40usize, 60usize);
        let wall = 30;
        let truth = Array2::from_shape_fn((rows, cols), |(_, c)| {
            0.3 * c as f64 + if c > wall { 15.0 } else { 0.0 }
        });
        let normals = Array2::from_shape_fn((rows, cols), |(r, c)| {
            if c == wall {
                normal(5.0 + 0.5 * r as f64, 0.0)
            } else {
                normal(0.3, 0.0)
            }
        });
        let mask = Array2::from_elem((rows, cols), true);
        let config = |integrator| IntegrateConfig {
            integrator,
            filter: ArtefactFilter { max_jump_mm: None },
            ..IntegrateConfig::default()
        };
        let out = integrate_normals(
            &field_of(&normals, &mask),
            1.0,
            &config(Integrator::Auto),
            None,
        )
        .unwrap();
        let left = Array2::from_shape_fn((rows, cols), |(_, c)| c < wall);
        let right = Array2::from_shape_fn((rows, cols), |(_, c)| c > wall);
        let sides =
            rmse(&out.depth.depth_mm, &truth, &left).max(rmse(&out.depth.depth_mm, &truth, &right));
        let bilateral_pixels = out.bilateral_pixels.unwrap();
        assert!(
            sides < 0.15 && bilateral_pixels > 0,
            "side RMSE {sides} px, {bilateral_pixels} pixels weighted as bilateral"
        );

        let radius = 25.0;
        let (rows, cols) = (61usize, 61usize);
        let centre = 30.0;
        let height = |r: usize, c: usize| {
            let (x, y) = (c as f64 - centre, centre - r as f64);
            (radius * radius - x * x - y * y).sqrt()
        };
        let mask = Array2::from_shape_fn((rows, cols), |(r, c)| height(r, c) > 8.0);
        let normals = Array2::from_shape_fn((rows, cols), |(r, c)| {
            let (x, y) = (c as f64 - centre, centre - r as f64);
            Vector3::new(x, y, height(r, c).max(0.0)).normalize()
        });
        let field = field_of(&normals, &mask);
        let auto = integrate_normals(&field, 1.0, &config(Integrator::Auto), None).unwrap();
        let ls = integrate_normals(&field, 1.0, &config(Integrator::LeastSquares), None).unwrap();
        assert_eq!(auto.discontinuity_edges, Some(0));
        assert_eq!(auto.bilateral_pixels, Some(0));
        assert_eq!(ls.discontinuity_edges, None);
        let truth = Array2::from_shape_fn((rows, cols), |(r, c)| height(r, c));
        let (e_auto, e_ls) = (
            rmse(&auto.depth.depth_mm, &truth, &mask),
            rmse(&ls.depth.depth_mm, &truth, &mask),
        );
        assert!(
            (e_auto - e_ls).abs() < 1e-3 * e_ls.max(1e-3),
            "auto {e_auto} px, LS {e_ls} px"
        );
    }

    /// A hemisphere whose middle band is lit by two LEDs only: with the band's circles the
    /// integrator joins both halves into one piece that matches the sphere; without them the
    /// halves are separate pieces.
    #[test]
    fn two_led_band_joins_the_halves() {
        let (field, planes, truth) = banded_hemisphere();
        let (rows, cols) = field.mask.dim();
        let config = IntegrateConfig {
            filter: ArtefactFilter { max_jump_mm: None },
            ..IntegrateConfig::default()
        };
        let projection = Projection::centred(1.0, (cols, rows));
        let evidence = SurfaceEvidence {
            field: &field,
            planes: &planes,
            fill: None,
        };
        let joined = integrate_surface(&evidence, &projection, &config, None).unwrap();
        assert_eq!(joined.pieces, 1);
        let in_band = Array2::from_shape_fn((rows, cols), |(r, c)| {
            joined.confidence[(r, c)] == Confidence::TwoLeds
        });
        assert!(in_band.iter().filter(|&&b| b).count() > 250);
        let everywhere = joined.kept.clone();
        let e_all = rmse(&joined.depth.depth_mm, &truth, &everywhere);
        let e_band = rmse(&joined.depth.depth_mm, &truth, &in_band);
        // The rim (slopes up to 20) dominates `all`; measured 0.36 px and 0.028 px.
        assert!(
            e_all < 0.45 && e_band < 0.05,
            "all {e_all} px, band {e_band} px"
        );
        let apart = integrate_normals(&field, 1.0, &config, None).unwrap();
        assert_eq!(apart.pieces, 2);
    }

    /// A hemisphere (radius 28 px) whose rows 27..34 are lit by two LEDs only: the measured
    /// field, the band's circles and the true height.
    fn banded_hemisphere() -> (NormalField, Vec<NormalPlane>, Array2<f64>) {
        let (rows, cols, radius) = (61usize, 61usize, 28.0);
        let inside = |r: usize, c: usize| {
            let (x, y) = (c as f64 - 30.0, 30.0 - r as f64);
            x * x + y * y < radius * radius
        };
        let height = |r: usize, c: usize| {
            let (x, y) = (c as f64 - 30.0, 30.0 - r as f64);
            (radius * radius - x * x - y * y).max(0.0).sqrt()
        };
        let truth = Array2::from_shape_fn((rows, cols), |(r, c)| height(r, c));
        let normals = Array2::from_shape_fn((rows, cols), |(r, c)| {
            Vector3::new(c as f64 - 30.0, 30.0 - r as f64, height(r, c)).normalize()
        });
        let band = |r: usize| (27..34).contains(&r);
        let measured = Array2::from_shape_fn((rows, cols), |(r, c)| inside(r, c) && !band(r));
        let lights = [Vector3::new(0.5, 0.1, 0.86), Vector3::new(-0.4, 0.3, 0.87)];
        let planes: Vec<NormalPlane> = measured
            .indexed_iter()
            .filter(|&((r, c), _)| inside(r, c) && band(r))
            .filter(|&((r, c), _)| lights.iter().all(|l| normals[(r, c)].dot(l) > 0.05))
            .map(|((r, c), _)| {
                let n = normals[(r, c)];
                let (a1, a2) = (n.dot(&lights[0]), n.dot(&lights[1]));
                let (ii, ij, jj) = (
                    lights[0].dot(&lights[0]),
                    lights[0].dot(&lights[1]),
                    lights[1].dot(&lights[1]),
                );
                let det = ii * jj - ij * ij;
                NormalPlane {
                    pixel: (r, c),
                    across: lights[0] * a2 - lights[1] * a1,
                    towards: lights[0] + lights[1],
                    least_albedo: lights[0] * ((jj * a1 - ij * a2) / det)
                        + lights[1] * ((ii * a2 - ij * a1) / det),
                }
            })
            .collect();
        (field_of(&normals, &measured), planes, truth)
    }

    /// A workspace reuses the integration graph when the mask repeats and gives the
    /// depth of a fresh integration; a warm start from a result moved by 3 px (as the offset
    /// search moves it) takes the two-LED pixels' slopes from it, needs fewer solves and
    /// iterations, and lands on the same surface. Each of fixed-seed random perturbations of
    /// the normals (a different problem each) is checked.
    #[test]
    fn workspace_and_warm_start_keep_the_result() {
        use rand::{RngExt, SeedableRng};
        let (mut field, planes, truth) = banded_hemisphere();
        let shape = field.mask.dim();
        let projection = Projection::centred(1.0, (shape.1, shape.0));
        let config = IntegrateConfig {
            filter: ArtefactFilter { max_jump_mm: None },
            tolerance: 1e-5,
            coverage: CoverageConfig {
                iterations: 8,
                ..CoverageConfig::default()
            },
            ..IntegrateConfig::default()
        };
        let clean = field.normals.clone();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(14);
        let mut workspace = IntegrationWorkspace::new();
        for round in 0..4 {
            field.normals.zip_mut_with(&clean, |n, &c| {
                *n = c + 0.01 * (rng.random::<f32>() - 0.5);
            });
            let evidence = SurfaceEvidence {
                field: &field,
                planes: &planes,
                fill: None,
            };
            let fresh = integrate_surface(&evidence, &projection, &config, None).unwrap();
            let reused =
                integrate_surface_with(&evidence, &projection, &config, None, &mut workspace)
                    .unwrap();
            assert_eq!(workspace.profile().reused_graph, round > 0);
            let worst = fresh
                .depth
                .depth_mm
                .iter()
                .zip(&reused.depth.depth_mm)
                .filter(|(a, _)| a.is_finite())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst < 1e-3,
                "round {round}: reused graph moved depth {worst} px"
            );
            let moved = fresh.depth.depth_mm.mapv(|z| z + 3.0);
            let warm = integrate_surface_with(
                &evidence,
                &projection,
                &config,
                Some(&moved),
                &mut workspace,
            )
            .unwrap();
            assert!(
                warm.passes < fresh.passes && warm.iterations < fresh.iterations,
                "round {round}: warm {} passes {} iterations, cold {} passes {} iterations",
                warm.passes,
                warm.iterations,
                fresh.passes,
                fresh.iterations
            );
            let (e_cold, e_warm) = (
                rmse(&fresh.depth.depth_mm, &truth, &fresh.kept),
                rmse(&warm.depth.depth_mm, &truth, &warm.kept),
            );
            assert!(
                e_warm < e_cold + 0.01 && e_warm < 0.5,
                "round {round}: warm {e_warm} px, cold {e_cold} px"
            );
        }
    }

    /// A hole with no information inside a paraboloid is filled, marked as such, and close to
    /// the surface.
    #[test]
    fn holes_are_filled() {
        let (rows, cols) = (50usize, 50usize);
        let truth = Array2::from_shape_fn((rows, cols), |(r, c)| {
            0.01 * ((c as f64 - 25.0).powi(2) + (r as f64 - 25.0).powi(2))
        });
        let normals = Array2::from_shape_fn((rows, cols), |(r, c)| {
            normal(0.02 * (c as f64 - 25.0), -0.02 * (r as f64 - 25.0))
        });
        let hole = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (20..27).contains(&r) && (18..30).contains(&c)
        });
        let measured = hole.mapv(|h| !h);
        let field = field_of(&normals, &measured);
        let out = integrate_surface(
            &SurfaceEvidence {
                field: &field,
                planes: &[],
                fill: Some(&hole),
            },
            &Projection::centred(1.0, (cols, rows)),
            &IntegrateConfig {
                integrator: Integrator::Bilateral,
                ..IntegrateConfig::default()
            },
            None,
        )
        .unwrap();
        assert_eq!(out.pieces, 1);
        assert!(
            hole.indexed_iter()
                .all(|(p, &h)| !h || out.confidence[p] == Confidence::Filled)
        );
        let e = rmse(&out.depth.depth_mm, &truth, &hole);
        assert!(e < 0.05, "hole rmse {e}");
    }

    /// A sphere seen by a pinhole camera with distortion: its exact normals integrate in
    /// log depth to the true depth; read as orthographic they do not.
    #[test]
    fn perspective_sphere_integrates_in_log_depth() {
        let camera = Camera {
            width: 90,
            height: 70,
            fps: 960.0,
            distance_mm: 200.0,
            fov_deg: None,
            pixel_pitch_mm: None,
            intrinsics: Some(Intrinsics {
                fx: 600.0,
                fy: 600.0,
                cx: 44.0,
                cy: 35.0,
                k1: -0.2,
                k2: 0.0,
            }),
            axis_px: None,
        };
        let radius = 20.0;
        let shape = (camera.height, camera.width);
        let mut truth = Array2::from_elem(shape, f64::NAN);
        let mut normals = Array2::from_elem(shape, Vector3::zeros());
        for r in 0..shape.0 {
            for c in 0..shape.1 {
                let ray = camera.ray(r as f64, c as f64);
                // |base + z·slope| = R, the root nearer the camera.
                let (a, b, k) = (
                    ray.slope.norm_squared(),
                    2.0 * ray.base.dot(&ray.slope),
                    ray.base.norm_squared() - radius * radius,
                );
                let disc = b * b - 4.0 * a * k;
                if disc > 0.0 {
                    let z = (-b + disc.sqrt()) / (2.0 * a);
                    truth[(r, c)] = z;
                    normals[(r, c)] = ray.at(z) / radius;
                }
            }
        }
        // Leave out the grazing rim, where slopes are clipped.
        let mask = Array2::from_shape_fn(shape, |(r, c)| {
            truth[(r, c)].is_finite()
                && normals[(r, c)].dot(&camera.ray(r as f64, c as f64).towards_camera()) > 0.3
        });
        let field = field_of(&normals, &mask);
        let config = IntegrateConfig {
            integrator: Integrator::LeastSquares,
            ..IntegrateConfig::default()
        };
        let evidence = SurfaceEvidence {
            field: &field,
            planes: &[],
            fill: None,
        };
        let out = integrate_surface(&evidence, &camera.projection(), &config, None).unwrap();
        // Log depth fixes the distance D − z only up to a scale (the near-field stage chooses
        // it): compare after the best scale, s = Σab / Σa² for a = D − z_got, b = D − z_true.
        let d = camera.distance_mm;
        let (mut ab, mut aa) = (0.0, 0.0);
        for (p, &m) in mask.indexed_iter() {
            let z = f64::from(out.depth.depth_mm[p]);
            if m && z.is_finite() {
                ab += (d - z) * (d - truth[p]);
                aa += (d - z) * (d - z);
            }
        }
        let scale = ab / aa;
        let scaled = out
            .depth
            .depth_mm
            .mapv(|z| (d - scale * (d - f64::from(z))) as f32);
        let e = rmse(&scaled, &truth, &mask);
        let ortho = integrate_normals(&field, camera.pitch_mm(), &config, None).unwrap();
        let e_ortho = rmse(&ortho.depth.depth_mm, &truth, &mask);
        assert!(
            e < 0.05 && e_ortho > 1.5 * e,
            "perspective {e} mm, orthographic reading {e_ortho} mm"
        );
    }

    #[test]
    fn bad_settings_and_unusable_normals_are_named() {
        let mask = Array2::from_elem((5, 6), true);
        let field = NormalField {
            normals: Array3::zeros((5, 6, 3)),
            albedo: Array2::ones((5, 6)),
            mask,
        };
        let err = integrate_normals(&field, 1.0, &IntegrateConfig::default(), None).unwrap_err();
        assert!(
            matches!(
                err,
                IntegrateError::NoUsableNormals {
                    zero: 30,
                    facing_away: 0
                }
            ),
            "{err}"
        );
        // Non-finite normals are counted and the first in raster order named, in grid
        // coordinates, whichever row band of the classification found it.
        let shape = (40, 30);
        let mask = Array2::from_shape_fn(shape, |(r, c)| r >= 3 && c >= 2);
        let mut normals = Array3::zeros((shape.0, shape.1, 3));
        for r in 0..shape.0 {
            for c in 0..shape.1 {
                normals[(r, c, 2)] = 1.0;
            }
        }
        for (r, c, j) in [(25, 3, 0), (13, 20, 2), (13, 7, 1), (1, 1, 0)] {
            normals[(r, c, j)] = f32::NAN;
        }
        let field = NormalField {
            normals,
            albedo: Array2::ones(shape),
            mask,
        };
        let err = integrate_normals(&field, 1.0, &IntegrateConfig::default(), None).unwrap_err();
        assert!(
            matches!(
                err,
                IntegrateError::NonFinite {
                    count: 3,
                    row: 13,
                    col: 7
                }
            ),
            "{err}"
        );
        for lambda in [f64::NAN, -0.06, 0.0, f64::INFINITY] {
            let config = IntegrateConfig {
                lambda,
                ..IntegrateConfig::default()
            };
            let err = config.validate().unwrap_err();
            assert!(err.to_string().contains("lambda"), "{err}");
            assert!(integrate_normals(&field, 1.0, &config, None).is_err());
        }
    }
}
