//! Masked least-squares (Poisson) integration (Quéau, Durou, Aujol 2018, §3 "quadratic").
//!
//! Every pair of 4-neighbouring mask pixels i, j (j right of or below i) gives one equation
//! z_j − z_i = h·(g_i + g_j)/2 with g the slope along that edge (∂z/∂x to the right, −∂z/∂y
//! downwards because y points up). The normal equations are a graph Laplacian on the mask
//! (Neumann boundary, any shape), solved by conjugate gradients preconditioned with modified
//! incomplete Cholesky MIC(0) in raster order (Bridson & Müller-Fischer's formulation), which
//! keeps iteration counts proportional to the mask's diameter rather than its area.

use super::{IntegrateConfig, IntegrateError, SurfaceGradients};
use ndarray::Array2;

/// Marks "no neighbour" in the compact neighbour tables.
const NONE: u32 = u32::MAX;
/// MIC(0) fill-in weight τ and pivot safeguard σ.
const MIC_TAU: f64 = 0.97;
const MIC_SIGMA: f64 = 0.25;
/// Diagonal shift that makes the Neumann Laplacian definite (fixes the free constant).
const REGULARISATION: f64 = 1e-10;

/// The masked Laplacian in compact form: pixel k ↔ grid position `pixels[k]`.
struct MaskedLaplacian {
    pixels: Vec<(usize, usize)>,
    right: Vec<u32>,
    down: Vec<u32>,
    left: Vec<u32>,
    up: Vec<u32>,
    diag: Vec<f64>,
}

impl MaskedLaplacian {
    /// Numbers the mask pixels with at least one mask neighbour in raster order.
    fn new(mask: &Array2<bool>) -> Self {
        let (rows, cols) = mask.dim();
        let inside = |r: usize, c: usize| r < rows && c < cols && mask[(r, c)];
        let mut index = Array2::from_elem((rows, cols), NONE);
        let mut pixels = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                let connected = inside(r, c)
                    && ((r > 0 && inside(r - 1, c))
                        || inside(r + 1, c)
                        || (c > 0 && inside(r, c - 1))
                        || inside(r, c + 1));
                if connected {
                    index[(r, c)] = pixels.len() as u32;
                    pixels.push((r, c));
                }
            }
        }
        let at = |r: usize, c: usize| {
            if r < rows && c < cols {
                index[(r, c)]
            } else {
                NONE
            }
        };
        let n = pixels.len();
        let (mut right, mut down, mut left, mut up) =
            (vec![NONE; n], vec![NONE; n], vec![NONE; n], vec![NONE; n]);
        let mut diag = vec![REGULARISATION; n];
        for (k, &(r, c)) in pixels.iter().enumerate() {
            right[k] = at(r, c + 1);
            down[k] = at(r + 1, c);
            left[k] = if c > 0 { at(r, c - 1) } else { NONE };
            up[k] = if r > 0 { at(r - 1, c) } else { NONE };
            diag[k] += [right[k], down[k], left[k], up[k]]
                .iter()
                .filter(|&&j| j != NONE)
                .count() as f64;
        }
        Self {
            pixels,
            right,
            down,
            left,
            up,
            diag,
        }
    }

    /// y = A x.
    fn apply(&self, x: &[f64], y: &mut [f64]) {
        for k in 0..x.len() {
            let mut s = self.diag[k] * x[k];
            for j in [self.right[k], self.down[k], self.left[k], self.up[k]] {
                if j != NONE {
                    s -= x[j as usize];
                }
            }
            y[k] = s;
        }
    }

    /// MIC(0) preconditioner: 1/√e_k per pixel (off-diagonals are −1 or absent).
    fn mic_precon(&self) -> Vec<f64> {
        let n = self.pixels.len();
        let mut precon = vec![0.0; n];
        for k in 0..n {
            let mut e = self.diag[k];
            for (j, fill) in [(self.left[k], &self.down), (self.up[k], &self.right)] {
                if j != NONE {
                    let j = j as usize;
                    let pj = precon[j];
                    // (a_kj · p_j)² with a_kj = −1, and the dropped fill-in −a_kj·a_j,other·p_j².
                    e -= pj * pj;
                    if fill[j] != NONE {
                        e -= MIC_TAU * pj * pj;
                    }
                }
            }
            if e < MIC_SIGMA * self.diag[k] {
                e = self.diag[k];
            }
            precon[k] = 1.0 / e.sqrt();
        }
        precon
    }

    /// z = M⁻¹ r for the MIC(0) factor M = (E + L) E⁻² (E + Lᵀ) … in Bridson's form.
    fn precondition(&self, precon: &[f64], r: &[f64], q: &mut [f64], z: &mut [f64]) {
        let n = r.len();
        for k in 0..n {
            let mut t = r[k];
            for j in [self.left[k], self.up[k]] {
                if j != NONE {
                    let j = j as usize;
                    t += precon[j] * q[j];
                }
            }
            q[k] = t * precon[k];
        }
        for k in (0..n).rev() {
            let mut t = q[k];
            for j in [self.right[k], self.down[k]] {
                if j != NONE {
                    t += precon[k] * z[j as usize];
                }
            }
            z[k] = t * precon[k];
        }
    }
}

/// Solves the masked least-squares problem; returns depth in mm (NaN outside) and CG iterations.
pub fn integrate(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<(Array2<f64>, usize), IntegrateError> {
    let lap = MaskedLaplacian::new(&gradients.mask);
    let n = lap.pixels.len();
    if n == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    // Right-hand side Dᵀg: edge k→j with z_j − z_i = g adds −g at i and +g at j.
    let mut b = vec![0.0; n];
    for (k, &(r, c)) in lap.pixels.iter().enumerate() {
        let j = lap.right[k];
        if j != NONE {
            let g = 0.5 * pitch_mm * (gradients.dzdx[(r, c)] + gradients.dzdx[(r, c + 1)]);
            b[k] -= g;
            b[j as usize] += g;
        }
        let j = lap.down[k];
        if j != NONE {
            let g = -0.5 * pitch_mm * (gradients.dzdy[(r, c)] + gradients.dzdy[(r + 1, c)]);
            b[k] -= g;
            b[j as usize] += g;
        }
    }
    let mut x: Vec<f64> = lap
        .pixels
        .iter()
        .map(|&p| {
            initial
                .and_then(|d| d.get(p).copied())
                .filter(|z| z.is_finite())
                .map_or(0.0, f64::from)
        })
        .collect();
    let iterations = conjugate_gradients(&lap, &b, &mut x, config.tolerance, config.max_iterations);
    let mut depth = Array2::from_elem(gradients.mask.dim(), f64::NAN);
    for (k, &p) in lap.pixels.iter().enumerate() {
        depth[p] = x[k];
    }
    Ok((depth, iterations))
}

/// Preconditioned conjugate gradients on `lap` x = b from the given x; returns iterations.
fn conjugate_gradients(
    lap: &MaskedLaplacian,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: usize,
) -> usize {
    let n = b.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let precon = lap.mic_precon();
    let mut r = vec![0.0; n];
    lap.apply(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    let b_norm = dot(b, b).sqrt().max(f64::MIN_POSITIVE);
    let (mut q, mut z) = (vec![0.0; n], vec![0.0; n]);
    lap.precondition(&precon, &r, &mut q, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    for it in 0..max_iterations {
        if dot(&r, &r).sqrt() <= tolerance * b_norm {
            return it;
        }
        lap.apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap.is_nan() || pap <= 0.0 {
            return it;
        }
        let alpha = rz / pap;
        for k in 0..n {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        lap.precondition(&precon, &r, &mut q, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for k in 0..n {
            p[k] = z[k] + beta * p[k];
        }
    }
    max_iterations
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::{IntegrateConfig, integrate_gradients};

    /// Slopes of z = 0.01 (x² − 2y²) + 0.3 x on a disc mask, pitch 0.5 mm.
    #[test]
    fn recovers_a_quadric_on_a_disc() {
        let (rows, cols, h) = (60usize, 80usize, 0.5);
        let xy = |r: usize, c: usize| ((c as f64 - 40.0) * h, (30.0 - r as f64) * h);
        let z = |x: f64, y: f64| 0.01 * (x * x - 2.0 * y * y) + 0.3 * x;
        let mask = Array2::from_shape_fn((rows, cols), |(r, c)| {
            let (x, y) = xy(r, c);
            x * x + y * y < 14.0 * 14.0
        });
        let dzdx = Array2::from_shape_fn((rows, cols), |(r, c)| 0.02 * xy(r, c).0 + 0.3);
        let dzdy = Array2::from_shape_fn((rows, cols), |(r, c)| -0.04 * xy(r, c).1);
        let g = SurfaceGradients { dzdx, dzdy, mask };
        let out = integrate_gradients(&g, h, &IntegrateConfig::default(), None).unwrap();
        let mut diffs = Vec::new();
        for ((r, c), &m) in g.mask.indexed_iter() {
            if m {
                let (x, y) = xy(r, c);
                diffs.push(f64::from(out.depth.depth_mm[(r, c)]) - z(x, y));
            }
        }
        let mean = diffs.iter().sum::<f64>() / diffs.len() as f64;
        let worst = diffs.iter().map(|d| (d - mean).abs()).fold(0.0, f64::max);
        assert!(worst < 0.01, "worst {worst}");
        assert!(out.iterations < 200, "{}", out.iterations);
    }
}
