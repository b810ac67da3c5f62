//! Masked least-squares (Poisson) integration (Quéau, Durou, Aujol 2018, §3 "quadratic").
//!
//! Every pair of 4-neighbouring mask pixels i, j (j right of or below i) gives one equation
//! z_j − z_i = h·(g_i + g_j)/2 with g the slope along that edge (∂z/∂x to the right, −∂z/∂y
//! downwards because y points up). The normal equations are a graph Laplacian on the mask
//! (Neumann boundary, any shape), solved by conjugate gradients preconditioned with an
//! aggregation multigrid V-cycle ([`super::multigrid`]), which keeps the iteration count nearly
//! independent of the mask's size.

use super::multigrid::{GridLaplacian, Multigrid, NONE};
use super::{IntegrateConfig, IntegrateError, SurfaceGradients};
use ndarray::Array2;

/// Diagonal shift that makes the Neumann Laplacian definite (fixes the free constant).
const REGULARISATION: f64 = 1e-10;

/// The masked Laplacian: mask pixels with at least one mask neighbour, numbered in raster order.
fn masked_laplacian(mask: &Array2<bool>) -> GridLaplacian {
    let (rows, cols) = mask.dim();
    let inside = |r: usize, c: usize| r < rows && c < cols && mask[(r, c)];
    let mut index = vec![NONE; rows * cols];
    let mut cells = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let connected = inside(r, c)
                && ((r > 0 && inside(r - 1, c))
                    || inside(r + 1, c)
                    || (c > 0 && inside(r, c - 1))
                    || inside(r, c + 1));
            if connected {
                index[r * cols + c] = cells.len() as u32;
                cells.push((r, c));
            }
        }
    }
    let at = |r: usize, c: usize| {
        if r < rows && c < cols {
            index[r * cols + c]
        } else {
            NONE
        }
    };
    let mut neighbours = Vec::with_capacity(cells.len());
    let mut weights = Vec::with_capacity(cells.len());
    let mut diag = Vec::with_capacity(cells.len());
    for &(r, c) in &cells {
        let nb = [
            at(r, c + 1),
            at(r + 1, c),
            if c > 0 { at(r, c - 1) } else { NONE },
            if r > 0 { at(r - 1, c) } else { NONE },
        ];
        let w = nb.map(|j| if j == NONE { 0.0 } else { 1.0 });
        diag.push(REGULARISATION + w.iter().sum::<f64>());
        neighbours.push(nb);
        weights.push(w);
    }
    GridLaplacian::new((rows, cols), cells, neighbours, weights, diag)
}

/// Solves the masked least-squares problem; returns depth in mm (NaN outside) and CG iterations.
pub fn integrate(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<(Array2<f64>, usize), IntegrateError> {
    let lap = masked_laplacian(&gradients.mask);
    let n = lap.len();
    if n == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    // Right-hand side Dᵀg: edge k→j with z_j − z_i = g adds −g at i and +g at j.
    let mut b = vec![0.0; n];
    for (k, &(r, c)) in lap.cells.iter().enumerate() {
        let j = lap.neighbours[k][0];
        if j != NONE {
            let g = 0.5 * pitch_mm * (gradients.dzdx[(r, c)] + gradients.dzdx[(r, c + 1)]);
            b[k] -= g;
            b[j as usize] += g;
        }
        let j = lap.neighbours[k][1];
        if j != NONE {
            let g = -0.5 * pitch_mm * (gradients.dzdy[(r, c)] + gradients.dzdy[(r + 1, c)]);
            b[k] -= g;
            b[j as usize] += g;
        }
    }
    let mut x: Vec<f64> = lap
        .cells
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
    for (k, &p) in lap.cells.iter().enumerate() {
        depth[p] = x[k];
    }
    Ok((depth, iterations))
}

/// Multigrid-preconditioned conjugate gradients on `lap` x = b from the given x; returns
/// iterations.
fn conjugate_gradients(
    lap: &GridLaplacian,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: usize,
) -> usize {
    let n = b.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut multigrid = Multigrid::new(lap, REGULARISATION);
    let mut r = vec![0.0; n];
    lap.apply(x, &mut r);
    for (ri, bi) in r.iter_mut().zip(b) {
        *ri = bi - *ri;
    }
    let b_norm = dot(b, b).sqrt().max(f64::MIN_POSITIVE);
    let mut z = vec![0.0; n];
    multigrid.precondition(lap, &r, &mut z);
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
        multigrid.precondition(lap, &r, &mut z);
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

    /// A mask with a hole, a second component, a two-pixel island and a lone pixel.
    fn awkward_mask(rows: usize, cols: usize) -> Array2<bool> {
        Array2::from_shape_fn((rows, cols), |(r, c)| {
            let (y, x) = (r as f64 - 20.0, c as f64 - 22.0);
            let d2 = x * x + y * y;
            let ring = d2 < 17.0 * 17.0 && d2 > 5.0 * 5.0 && !(c == 30 && r < 25);
            let bar = (43..52).contains(&c) && (4..36).contains(&r) && r != 20;
            ring || bar || (r == 39 && (c == 50 || c == 51)) || (r == 0 && c == 55)
        })
    }

    /// Component label per pixel (4-connectivity), `usize::MAX` outside.
    fn components(mask: &Array2<bool>) -> Array2<usize> {
        let (rows, cols) = mask.dim();
        let mut label = Array2::from_elem((rows, cols), usize::MAX);
        let mut next = 0;
        for start in (0..rows).flat_map(|r| (0..cols).map(move |c| (r, c))) {
            if !mask[start] || label[start] != usize::MAX {
                continue;
            }
            let mut stack = vec![start];
            label[start] = next;
            while let Some((r, c)) = stack.pop() {
                for (rr, cc) in [
                    (r + 1, c),
                    (r.wrapping_sub(1), c),
                    (r, c + 1),
                    (r, c.wrapping_sub(1)),
                ] {
                    if rr < rows && cc < cols && mask[(rr, cc)] && label[(rr, cc)] == usize::MAX {
                        label[(rr, cc)] = next;
                        stack.push((rr, cc));
                    }
                }
            }
            next += 1;
        }
        label
    }

    /// Straightforward reference: unpreconditioned CG on the same normal equations, to 1e-13.
    fn plain_cg(g: &SurfaceGradients, h: f64) -> Array2<f64> {
        let lap = masked_laplacian(&g.mask);
        let n = lap.len();
        let mut b = vec![0.0; n];
        for (k, &(r, c)) in lap.cells.iter().enumerate() {
            let j = lap.neighbours[k][0];
            if j != NONE {
                let e = 0.5 * h * (g.dzdx[(r, c)] + g.dzdx[(r, c + 1)]);
                b[k] -= e;
                b[j as usize] += e;
            }
            let j = lap.neighbours[k][1];
            if j != NONE {
                let e = -0.5 * h * (g.dzdy[(r, c)] + g.dzdy[(r + 1, c)]);
                b[k] -= e;
                b[j as usize] += e;
            }
        }
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (mut x, mut r, mut p, mut ap) = (vec![0.0; n], b.clone(), b.clone(), vec![0.0; n]);
        let mut rr = dot(&r, &r);
        for _ in 0..20 * n {
            if rr <= 1e-26 * dot(&b, &b) {
                break;
            }
            lap.apply(&p, &mut ap);
            let alpha = rr / dot(&p, &ap);
            for k in 0..n {
                x[k] += alpha * p[k];
                r[k] -= alpha * ap[k];
            }
            let rr_new = dot(&r, &r);
            for k in 0..n {
                p[k] = r[k] + rr_new / rr * p[k];
            }
            rr = rr_new;
        }
        let mut depth = Array2::from_elem(g.mask.dim(), f64::NAN);
        for (k, &p) in lap.cells.iter().enumerate() {
            depth[p] = x[k];
        }
        depth
    }

    /// Largest difference of `a` and `b` once each component's mean difference is removed.
    fn worst_difference_per_component(a: &Array2<f64>, b: &Array2<f64>) -> f64 {
        let mask = a.mapv(f64::is_finite);
        assert_eq!(mask, b.mapv(f64::is_finite));
        let label = components(&mask);
        let count = label
            .iter()
            .filter(|&&l| l != usize::MAX)
            .max()
            .map_or(0, |m| m + 1);
        let (mut sum, mut n) = (vec![0.0; count], vec![0usize; count]);
        for (p, &l) in label.indexed_iter() {
            if l != usize::MAX {
                sum[l] += a[p] - b[p];
                n[l] += 1;
            }
        }
        label
            .indexed_iter()
            .filter(|(_, l)| **l != usize::MAX)
            .map(|(p, &l)| (a[p] - b[p] - sum[l] / n[l] as f64).abs())
            .fold(0.0, f64::max)
    }

    /// Non-integrable slopes on a mask with holes and several components: the multigrid-
    /// preconditioned solver reaches the same least-squares solution as plain CG.
    #[test]
    fn agrees_with_plain_cg_on_holes_and_components() {
        let (rows, cols, h) = (41usize, 57usize, 0.3);
        let mask = awkward_mask(rows, cols);
        let dzdx = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (0.3 * c as f64).sin() + 0.02 * r as f64
        });
        let dzdy = Array2::from_shape_fn((rows, cols), |(r, c)| {
            (0.2 * r as f64).cos() * 0.5 - 0.01 * c as f64
        });
        let g = SurfaceGradients { dzdx, dzdy, mask };
        let config = IntegrateConfig {
            tolerance: 1e-12,
            ..IntegrateConfig::default()
        };
        let (ours, iterations) = integrate(&g, h, &config, None).unwrap();
        let reference = plain_cg(&g, h);
        let worst = worst_difference_per_component(&ours, &reference);
        assert!(worst < 1e-8, "worst difference {worst} mm");
        assert!(iterations < 80, "{iterations} iterations");
        // The lone pixel has no neighbour and is not integrated.
        assert!(ours[(0, 55)].is_nan() && ours[(39, 50)].is_finite());
    }

    /// z = 0.02 x² − 0.01 x y + 0.2 y on the same awkward mask is reproduced exactly (the
    /// trapezoidal edge equations are exact for quadrics), up to a constant per component.
    #[test]
    fn recovers_a_quadric_on_holes_and_components() {
        let (rows, cols, h) = (41usize, 57usize, 0.5);
        let mask = awkward_mask(rows, cols);
        let xy = |r: usize, c: usize| (c as f64 * h, -(r as f64) * h);
        let z = |x: f64, y: f64| 0.02 * x * x - 0.01 * x * y + 0.2 * y;
        let dzdx = Array2::from_shape_fn((rows, cols), |(r, c)| {
            let (x, y) = xy(r, c);
            0.04 * x - 0.01 * y
        });
        let dzdy = Array2::from_shape_fn((rows, cols), |(r, c)| -0.01 * xy(r, c).0 + 0.2);
        let g = SurfaceGradients { dzdx, dzdy, mask };
        let (ours, _) = integrate(&g, h, &IntegrateConfig::default(), None).unwrap();
        let truth = Array2::from_shape_fn((rows, cols), |(r, c)| {
            if ours[(r, c)].is_finite() {
                let (x, y) = xy(r, c);
                z(x, y)
            } else {
                f64::NAN
            }
        });
        let worst = worst_difference_per_component(&ours, &truth);
        assert!(worst < 1e-4, "worst {worst} mm");
    }

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
