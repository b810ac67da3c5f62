//! Fusion of a normal field with measured positions: depth that follows the normals while
//! staying near a coarse, confidence-weighted range measurement (Nehab, Rusinkiewicz, Davis &
//! Ramamoorthi, "Efficiently combining positions and normals for precise 3D geometry",
//! SIGGRAPH 2005, on the masked pixel grid of an orthographic camera).
//!
//! With slopes g from the normals (docs/maths/integration.md#slopes-from-normals), every pair of
//! 4-neighbouring mask pixels i, j gives
//! the normal equation z_j − z_i = h·(g_i + g_j)/2 with standard deviation σ_e = σ_g·h (σ_g the
//! slope noise), and every pixel with a prior position p_i of weight w_i = 1/σ_i² one position
//! equation z_i = p_i. Minimising
//!
//! ```text
//! E(z) = Σ_edges (z_j − z_i − h·ḡ_ij)² + Σ_i λ_i (z_i − p_i)²,     λ_i = σ_e²·w_i
//! ```
//!
//! is the linear system (L + Λ) z = Dᵀḡ + Λ p: the mask's graph Laplacian plus a diagonal.
//! Its slowest mode is a constant per connected component (the offset the positions fix), whose
//! eigenvalue Σλ_i is tiny next to the Laplacian's, so conjugate gradients is preconditioned by
//! the aggregation multigrid V-cycle of \[`super::multigrid`\] *plus* an exact solve on the space of
//! per-component constants (additive two-level deflation; Tang, Nabben, Vuik & Erlangga,
//! J. Sci. Comput. 2009): B r = MG(r) + Σ_c 1_c·(Σ_{i∈c} r_i)/(Σ_{i∈c} λ_i). Components with no
//! position at all cannot be placed and are left out.

use super::least_squares::Topology;
use super::multigrid::{GridLaplacian, Multigrid, NONE};
use super::pcg::{CgVectors, Stop, preconditioned_cg};
use super::{IntegrateError, SurfaceGradients};
use meb_core::types::{DepthMap, NormalField};
use ndarray::Array2;

/// Regularising diagonal shift for pixels without a position (as in least squares).
const REGULARISATION: f64 = 1e-10;

/// Measured positions on the camera grid.
#[derive(Debug, Clone, PartialEq)]
pub struct PositionPrior {
    /// Depth z in mm (scene coordinates); ignored where `weight` is 0.
    pub depth_mm: Array2<f32>,
    /// Inverse variance 1/σ² in 1/mm² of each pixel's depth (0: no measurement). Correlated
    /// samples (one coarse measurement spread over k pixels) should carry 1/(k·σ²) each.
    pub weight: Array2<f32>,
}

/// Settings of the fusion.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FusionConfig {
    /// Standard deviation σ_g of the slopes from the normals (dimensionless; ~tan of the normal
    /// error).
    pub slope_sigma: f64,
    /// Slopes are clipped to ±this.
    pub max_slope: f64,
    /// Relative preconditioned residual at which conjugate gradients stops.
    pub tolerance: f64,
    /// Iteration cap.
    pub max_iterations: usize,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            slope_sigma: 0.02,
            max_slope: 20.0,
            tolerance: 1e-9,
            max_iterations: 3000,
        }
    }
}

/// The fused depth and how it came about.
#[derive(Debug, Clone)]
pub struct Fusion {
    /// Fused depth (NaN outside the solved pixels).
    pub depth: DepthMap,
    /// Pixels solved.
    pub solved: Array2<bool>,
    /// Conjugate-gradient iterations.
    pub iterations: usize,
    /// Pixels with a position measurement among the solved ones.
    pub prior_pixels: usize,
    /// Mask pixels left out because their component has no position measurement.
    pub unanchored_pixels: usize,
    /// Weighted RMS of (fused − prior) over the measured pixels, mm.
    pub rms_to_prior_mm: f64,
}

/// Fuses `field`'s normals with `prior` on the grid of pitch `pitch_mm` (module docs);
/// `initial` warm-starts the solver.
pub fn fuse_positions_and_normals(
    field: &NormalField,
    pitch_mm: f64,
    prior: &PositionPrior,
    config: &FusionConfig,
    initial: Option<&Array2<f32>>,
) -> Result<Fusion, IntegrateError> {
    if !(pitch_mm.is_finite() && pitch_mm > 0.0) {
        return Err(IntegrateError::BadPitch(pitch_mm));
    }
    let gradients = SurfaceGradients::from_normals(field, config.max_slope)?;
    gradients.validate()?;
    let shape = gradients.mask.dim();
    for (what, a) in [
        ("prior depth", &prior.depth_mm),
        ("prior weight", &prior.weight),
    ] {
        if a.dim() != shape {
            return Err(IntegrateError::SizeMismatch {
                what: what.into(),
                got: a.dim(),
                expected: shape,
            });
        }
    }
    let edge_variance = (config.slope_sigma.max(1e-6) * pitch_mm).powi(2);
    let system = System::assemble(&gradients, prior, pitch_mm, edge_variance);
    let (component, sizes) = system.components();
    // Per-component Σλ: components without positions are dropped.
    let mut anchor = vec![0.0; sizes.len()];
    for (k, &c) in component.iter().enumerate() {
        anchor[c] += system.data_weight[k];
    }
    let mut x: Vec<f64> = system
        .laplacian
        .cells
        .iter()
        .enumerate()
        .map(|(k, &p)| {
            initial
                .and_then(|d| d.get(p).copied())
                .filter(|z| z.is_finite())
                .map_or(system.prior[k], f64::from)
        })
        .collect();
    let mean_data = {
        let (s, n) = system
            .data_weight
            .iter()
            .filter(|&&w| w > 0.0)
            .fold((0.0, 0usize), |(s, n), &w| (s + w, n + 1));
        if n > 0 { s / n as f64 } else { 0.0 }
    };
    let iterations = solve(
        &system.laplacian,
        &system.rhs,
        &mut x,
        &Deflation {
            component: &component,
            anchor: &anchor,
        },
        mean_data.max(REGULARISATION),
        config,
    );
    let mut depth_mm = Array2::from_elem(shape, f32::NAN);
    let mut solved = Array2::from_elem(shape, false);
    let (mut prior_pixels, mut unanchored) = (0usize, 0usize);
    let (mut sum_w, mut sum_wr2) = (0.0, 0.0);
    for (k, &p) in system.laplacian.cells.iter().enumerate() {
        if anchor[component[k]] <= 0.0 {
            unanchored += 1;
            continue;
        }
        depth_mm[p] = x[k] as f32;
        solved[p] = true;
        let w = system.data_weight[k];
        if w > 0.0 {
            prior_pixels += 1;
            sum_w += w;
            sum_wr2 += w * (x[k] - system.prior[k]).powi(2);
        }
    }
    unanchored += gradients.mask.iter().filter(|&&m| m).count() - system.laplacian.len();
    if prior_pixels == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    Ok(Fusion {
        depth: DepthMap {
            depth_mm,
            pitch_mm,
            perspective: None,
        },
        solved,
        iterations,
        prior_pixels,
        unanchored_pixels: unanchored,
        rms_to_prior_mm: (sum_wr2 / sum_w).sqrt(),
    })
}

/// The assembled normal equations (L + Λ) z = b.
struct System {
    laplacian: GridLaplacian,
    rhs: Vec<f64>,
    /// λ_i per unknown.
    data_weight: Vec<f64>,
    /// p_i per unknown (0 where λ_i = 0).
    prior: Vec<f64>,
}

impl System {
    /// Unknowns: mask pixels with a mask neighbour or a position, in raster order.
    fn assemble(g: &SurfaceGradients, prior: &PositionPrior, h: f64, edge_variance: f64) -> Self {
        let lambda = |r: usize, c: usize| {
            let w = f64::from(prior.weight[(r, c)]);
            let z = f64::from(prior.depth_mm[(r, c)]);
            if w.is_finite() && w > 0.0 && z.is_finite() {
                (edge_variance * w, z)
            } else {
                (0.0, 0.0)
            }
        };
        let topology = Topology::with_isolated(&g.mask, |(r, c)| lambda(r, c).0 > 0.0);
        let n = topology.len();
        let mut weights = Vec::with_capacity(n);
        let mut diag = Vec::with_capacity(n);
        let mut rhs = vec![0.0; n];
        let mut data_weight = Vec::with_capacity(n);
        let mut prior_z = Vec::with_capacity(n);
        for (k, (&(r, c), &nb)) in topology.cells.iter().zip(&topology.neighbours).enumerate() {
            let w = nb.map(|j| if j == NONE { 0.0 } else { 1.0 });
            let (l, z) = lambda(r, c);
            diag.push(w.iter().sum::<f64>() + l + REGULARISATION);
            data_weight.push(l);
            prior_z.push(z);
            rhs[k] += l * z;
            // Edge to the right: z_j − z_i = h·(∂z/∂x_i + ∂z/∂x_j)/2; downwards y decreases.
            if nb[0] != NONE {
                let e = 0.5 * h * (g.dzdx[(r, c)] + g.dzdx[(r, c + 1)]);
                rhs[k] -= e;
                rhs[nb[0] as usize] += e;
            }
            if nb[1] != NONE {
                let e = -0.5 * h * (g.dzdy[(r, c)] + g.dzdy[(r + 1, c)]);
                rhs[k] -= e;
                rhs[nb[1] as usize] += e;
            }
            weights.push(w);
        }
        Self {
            laplacian: GridLaplacian::new(
                topology.shape,
                topology.cells,
                topology.neighbours,
                weights,
                diag,
            ),
            rhs,
            data_weight,
            prior: prior_z,
        }
    }

    /// Connected component of every unknown and the component sizes.
    fn components(&self) -> (Vec<usize>, Vec<usize>) {
        let a = &self.laplacian;
        let mut label = vec![usize::MAX; a.len()];
        let mut sizes = Vec::new();
        let mut stack = Vec::new();
        for seed in 0..a.len() {
            if label[seed] != usize::MAX {
                continue;
            }
            label[seed] = sizes.len();
            stack.push(seed);
            let mut size = 0;
            while let Some(k) = stack.pop() {
                size += 1;
                for &j in a.neighbours[k].iter().filter(|&&j| j != NONE) {
                    if label[j as usize] == usize::MAX {
                        label[j as usize] = sizes.len();
                        stack.push(j as usize);
                    }
                }
            }
            sizes.push(size);
        }
        (label, sizes)
    }
}

/// The per-component constant space and its exact (diagonal) Galerkin operator Σλ.
struct Deflation<'a> {
    component: &'a [usize],
    anchor: &'a [f64],
}

impl Deflation<'_> {
    /// z += Σ_c 1_c (Σ_{i∈c} r_i)/(Σ_{i∈c} λ_i) over anchored components.
    fn add_correction(&self, r: &[f64], z: &mut [f64]) {
        let mut sums = vec![0.0; self.anchor.len()];
        for (ri, &c) in r.iter().zip(self.component) {
            sums[c] += ri;
        }
        for (zi, &c) in z.iter_mut().zip(self.component) {
            if self.anchor[c] > 0.0 {
                *zi += sums[c] / self.anchor[c];
            }
        }
    }
}

/// Conjugate gradients on `a` x = b preconditioned by multigrid + deflation; returns iterations.
fn solve(
    a: &GridLaplacian,
    b: &[f64],
    x: &mut [f64],
    deflation: &Deflation,
    coarse_shift: f64,
    config: &FusionConfig,
) -> usize {
    let mut multigrid = Multigrid::new(a, coarse_shift);
    preconditioned_cg(
        |u, v| a.apply(u, v),
        |r, z| {
            multigrid.precondition(a, r, z);
            deflation.add_correction(r, z);
        },
        b,
        x,
        Stop::PreconditionedResidual(config.tolerance),
        config.max_iterations,
        &mut CgVectors::default(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    /// Normals of z = f(x, y) on a grid of pitch h, and the truth.
    fn surface(
        rows: usize,
        cols: usize,
        h: f64,
        f: impl Fn(f64, f64) -> (f64, f64, f64),
        mask: impl Fn(usize, usize) -> bool,
    ) -> (NormalField, Array2<f64>) {
        let mut normals = Array3::<f32>::from_elem((rows, cols, 3), f32::NAN);
        let mut truth = Array2::from_elem((rows, cols), f64::NAN);
        let m = Array2::from_shape_fn((rows, cols), |(r, c)| mask(r, c));
        for r in 0..rows {
            for c in 0..cols {
                let (x, y) = (c as f64 * h, -(r as f64) * h);
                let (z, zx, zy) = f(x, y);
                truth[(r, c)] = z;
                let n = nalgebra::Vector3::new(-zx, -zy, 1.0).normalize();
                for j in 0..3 {
                    normals[(r, c, j)] = n[j] as f32;
                }
            }
        }
        let field = NormalField {
            normals,
            albedo: Array2::ones((rows, cols)),
            mask: m,
        };
        (field, truth)
    }

    /// Exact normals of a quadric on two separate discs and positions offset by a different
    /// constant on each: the fused depth is the true shape placed at the (noise-free) positions,
    /// and a disc without positions is left out, not guessed.
    #[test]
    fn places_each_component_at_its_positions() {
        let (rows, cols, h) = (60, 90, 0.5);
        let disc = |r: usize, c: usize, r0: f64, c0: f64| {
            (r as f64 - r0).powi(2) + (c as f64 - c0).powi(2) < 20.0f64.powi(2)
        };
        let f = |x: f64, y: f64| {
            (
                0.01 * x * x - 0.02 * x * y + 0.3 * y,
                0.02 * x - 0.02 * y,
                -0.02 * x + 0.3,
            )
        };
        let (field, truth) = surface(rows, cols, h, f, |r, c| {
            disc(r, c, 30.0, 25.0) || disc(r, c, 30.0, 68.0) || (r < 3 && c > 86)
        });
        let depth = truth.mapv(|z| z as f32);
        let weight = Array2::from_shape_fn((rows, cols), |(_, c)| if c < 80 { 0.01 } else { 0.0 });
        let prior = PositionPrior {
            depth_mm: depth.clone(),
            weight,
        };
        let fused =
            fuse_positions_and_normals(&field, h, &prior, &FusionConfig::default(), None).unwrap();
        let mut worst: f64 = 0.0;
        for ((r, c), &s) in fused.solved.indexed_iter() {
            if s {
                worst = worst.max((f64::from(fused.depth.depth_mm[(r, c)]) - truth[(r, c)]).abs());
            }
        }
        assert!(
            worst < 0.01,
            "worst {worst} mm after {} iterations",
            fused.iterations
        );
        assert!(fused.iterations < 200, "{}", fused.iterations);
        assert_eq!(
            fused.unanchored_pixels, 9,
            "the corner square has no positions"
        );

        // Noisy positions (σ = 5 mm, independent per pixel) are averaged down by the normals.
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = rand_distr::Normal::new(0.0, 5.0).unwrap();
        let noisy = PositionPrior {
            depth_mm: depth.mapv(|z| z + noise.sample(&mut rng) as f32),
            weight: Array2::from_elem((rows, cols), 1.0 / 25.0),
        };
        let fused =
            fuse_positions_and_normals(&field, h, &noisy, &FusionConfig::default(), None).unwrap();
        let mut sum2 = 0.0;
        let mut n = 0.0;
        for ((r, c), &s) in fused.solved.indexed_iter() {
            if s {
                sum2 += (f64::from(fused.depth.depth_mm[(r, c)]) - truth[(r, c)]).powi(2);
                n += 1.0;
            }
        }
        let rmse = (sum2 / n).sqrt();
        // ~1250 samples per disc: the offset alone is good to 5/√1250 = 0.14 mm.
        assert!(rmse < 0.4, "rmse {rmse} mm");
        assert!(fused.unanchored_pixels == 0, "{}", fused.unanchored_pixels);

        let without = PositionPrior {
            depth_mm: depth,
            weight: Array2::zeros((rows, cols)),
        };
        assert!(matches!(
            fuse_positions_and_normals(&field, h, &without, &FusionConfig::default(), None),
            Err(IntegrateError::EmptyMask)
        ));
    }
}
