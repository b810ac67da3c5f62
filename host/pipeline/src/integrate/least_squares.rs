//! Weighted least-squares integration on a mask (Quéau, Durou, Aujol 2018, §3 "quadratic").
//!
//! Every pair of 4-neighbouring mask pixels i, j (j right of or below i) gives one equation
//! z_j − z_i = t_ij with weight w_ij. Plain least squares uses w = 1 and the trapezoidal target
//! t = h·(g_i + g_j)/2 (g the slope along the edge: ∂z/∂x to the right, −∂z/∂y downwards because
//! y points up); the bilateral integrator ([`super::bilateral`]) and the coverage loop
//! ([`super::coverage`]) reweight the two one-sided equations of each edge. The normal equations
//! are a weighted graph Laplacian on the mask (Neumann boundary, any shape, one free constant per
//! connected piece), solved by conjugate gradients preconditioned with an aggregation multigrid
//! V-cycle (\[`super::multigrid`\]), which keeps the iteration count nearly independent of the
//! mask's size.

use super::multigrid::{GridLaplacian, Multigrid, NONE, PARALLEL_BAND as NODES_PER_TASK};
use super::pcg::{CgVectors, Stop, preconditioned_cg};
use super::{IntegrateConfig, IntegrateError, SurfaceGradients};
use ndarray::Array2;
use rayon::prelude::*;

/// Diagonal shift that makes the Neumann Laplacian definite (fixes the free constant).
pub(crate) const REGULARISATION: f64 = 1e-10;

/// The integration graph: mask pixels with at least one mask neighbour, in raster order.
#[derive(Debug, Clone)]
pub(crate) struct Topology {
    /// Grid size (rows, columns).
    pub shape: (usize, usize),
    /// Grid position of each node.
    pub cells: Vec<(usize, usize)>,
    /// Node of each grid pixel (row-major), [`NONE`] outside.
    pub index: Vec<u32>,
    /// Neighbour node (or [`NONE`]) right, down, left, up.
    pub neighbours: Vec<[u32; 4]>,
}

impl Topology {
    /// The graph of `mask`.
    pub fn new(mask: &Array2<bool>) -> Self {
        Self::with_isolated(mask, |_| false)
    }

    /// The graph of `mask`, also keeping the mask pixels without a mask neighbour for which
    /// `keep` holds (isolated nodes, e.g. pixels tied only to a position prior).
    pub fn with_isolated(mask: &Array2<bool>, keep: impl Fn((usize, usize)) -> bool) -> Self {
        let (rows, cols) = mask.dim();
        let inside = |r: usize, c: usize| r < rows && c < cols && mask[(r, c)];
        let mut index = vec![NONE; rows * cols];
        let mut cells = Vec::new();
        for r in 0..rows {
            for c in 0..cols {
                let linked = (r > 0 && inside(r - 1, c))
                    || inside(r + 1, c)
                    || (c > 0 && inside(r, c - 1))
                    || inside(r, c + 1);
                if inside(r, c) && (linked || keep((r, c))) {
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
        let neighbours = cells
            .iter()
            .map(|&(r, c)| {
                [
                    at(r, c + 1),
                    at(r + 1, c),
                    if c > 0 { at(r, c - 1) } else { NONE },
                    if r > 0 { at(r - 1, c) } else { NONE },
                ]
            })
            .collect();
        Self {
            shape: (rows, cols),
            cells,
            index,
            neighbours,
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Node of pixel `p`, if it is one.
    pub fn node(&self, p: (usize, usize)) -> Option<usize> {
        let k = self.index[p.0 * self.shape.1 + p.1];
        (k != NONE).then_some(k as usize)
    }

    /// Connected piece of every node and the number of pieces.
    pub fn components(&self) -> (Vec<u32>, usize) {
        self.components_without(&[])
    }

    /// Connected pieces when the edges marked in `cut` (right, down of each node; empty for
    /// none) are removed.
    pub fn components_without(&self, cut: &[[bool; 2]]) -> (Vec<u32>, usize) {
        let is_cut = |k: usize, d: usize| {
            // Right/down edges are stored at k; left/up ones at the neighbour.
            match d {
                0 | 1 => cut.get(k).is_some_and(|c| c[d]),
                _ => {
                    let j = self.neighbours[k][d];
                    j != NONE && cut.get(j as usize).is_some_and(|c| c[d - 2])
                }
            }
        };
        let mut label = vec![NONE; self.len()];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for start in 0..self.len() {
            if label[start] != NONE {
                continue;
            }
            label[start] = count;
            stack.push(start);
            while let Some(k) = stack.pop() {
                for (d, &j) in self.neighbours[k].iter().enumerate() {
                    if j != NONE && label[j as usize] == NONE && !is_cut(k, d) {
                        label[j as usize] = count;
                        stack.push(j as usize);
                    }
                }
            }
            count += 1;
        }
        (label, count as usize)
    }

    /// The weighted Laplacian of edge weights `weight[k]` = (right, down) edges of node k.
    pub fn laplacian(&self, weight: &[[f64; 2]]) -> GridLaplacian {
        let n = self.len();
        let (mut weights, mut diag) = (vec![[0.0; 4]; n], vec![0.0; n]);
        self.laplacian_weights(weight, &mut weights, &mut diag);
        GridLaplacian::new(
            self.shape,
            self.cells.clone(),
            self.neighbours.clone(),
            weights,
            diag,
        )
    }

    /// Gives `lap`, a Laplacian of this graph ([`Self::laplacian`]), the edge weights `weight`
    /// in place: equal to `self.laplacian(weight)` without copying the graph again.
    pub fn reweight_laplacian(&self, lap: &mut GridLaplacian, weight: &[[f64; 2]]) {
        assert!(
            lap.len() == self.len() && lap.shape == self.shape,
            "a Laplacian of another graph"
        );
        debug_assert!(lap.neighbours == self.neighbours);
        lap.update(|weights, diag| self.laplacian_weights(weight, weights, diag));
    }

    /// The Laplacian's edge weights towards each neighbour (right, down, left, up) and its
    /// diagonal for edge weights `weight`; every node's row is gathered on its own, in
    /// parallel.
    fn laplacian_weights(&self, weight: &[[f64; 2]], weights: &mut [[f64; 4]], diag: &mut [f64]) {
        assert!(
            weight.len() == self.len(),
            "one (right, down) weight pair per node"
        );
        weights
            .par_iter_mut()
            .with_min_len(NODES_PER_TASK)
            .zip(diag.par_iter_mut())
            .zip(&self.neighbours)
            .enumerate()
            .for_each(|(k, ((w, dk), nb))| {
                *w = [0.0; 4];
                for d in 0..4 {
                    let j = nb[d];
                    if j != NONE {
                        // Right/down edges are stored at k, left/up ones at the neighbour.
                        w[d] = if d < 2 {
                            weight[k][d]
                        } else {
                            weight[j as usize][d - 2]
                        };
                    }
                }
                *dk = REGULARISATION + w.iter().sum::<f64>();
            });
    }
}

/// The edge equations z_j − z_i = target with weight, per node for its right and down edges.
#[derive(Debug, Clone)]
pub(crate) struct EdgeEquations {
    /// Weight of the right and down edge of each node (0 where there is none).
    pub weight: Vec<[f64; 2]>,
    /// Target difference z_j − z_i of the right and down edge.
    pub target: Vec<[f64; 2]>,
}

impl EdgeEquations {
    /// Plain least squares: weight 1, trapezoidal targets from the slopes per node.
    pub fn trapezoidal(topology: &Topology, sx: &[f64], sy: &[f64], step: f64) -> Self {
        let n = topology.len();
        let mut weight = vec![[0.0; 2]; n];
        let mut target = vec![[0.0; 2]; n];
        for (k, nb) in topology.neighbours.iter().enumerate() {
            if nb[0] != NONE {
                weight[k][0] = 1.0;
                target[k][0] = 0.5 * step * (sx[k] + sx[nb[0] as usize]);
            }
            if nb[1] != NONE {
                weight[k][1] = 1.0;
                target[k][1] = -0.5 * step * (sy[k] + sy[nb[1] as usize]);
            }
        }
        Self { weight, target }
    }

    /// Solves the normal equations from the given `x` (warm start); returns CG iterations.
    pub fn solve(
        &self,
        topology: &Topology,
        x: &mut [f64],
        tolerance: f64,
        max_iterations: usize,
    ) -> usize {
        let lap = topology.laplacian(&self.weight);
        let b = self.right_hand_side(topology);
        conjugate_gradients(&lap, &b, x, tolerance, max_iterations)
    }

    /// The right-hand side Dᵀ W t of the normal equations: edge k→j with z_j − z_k = t adds
    /// −w·t at k and +w·t at j.
    pub fn right_hand_side(&self, topology: &Topology) -> Vec<f64> {
        // b_k = Σ over k's edges of ±w·t: the edge from the node above and the one from the
        // node to the left arrive first, then k's own right and down edges leave (the order
        // in which a pass over the edges would add them up).
        let flow = |j: u32, d: usize| {
            let j = j as usize;
            self.weight[j][d] * self.target[j][d]
        };
        topology
            .neighbours
            .par_iter()
            .with_min_len(NODES_PER_TASK)
            .enumerate()
            .map(|(k, nb)| {
                let mut b = 0.0;
                if nb[3] != NONE {
                    b += flow(nb[3], 1);
                }
                if nb[2] != NONE {
                    b += flow(nb[2], 0);
                }
                for (d, &j) in nb.iter().enumerate().take(2) {
                    if j != NONE {
                        b -= flow(k as u32, d);
                    }
                }
                b
            })
            .collect()
    }
}

/// Solves the plain masked least-squares problem; returns depth in mm (NaN outside) and CG
/// iterations.
pub fn integrate(
    gradients: &SurfaceGradients,
    pitch_mm: f64,
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
) -> Result<(Array2<f64>, usize), IntegrateError> {
    let topology = Topology::new(&gradients.mask);
    if topology.len() == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    let sx: Vec<f64> = topology.cells.iter().map(|&p| gradients.dzdx[p]).collect();
    let sy: Vec<f64> = topology.cells.iter().map(|&p| gradients.dzdy[p]).collect();
    let equations = EdgeEquations::trapezoidal(&topology, &sx, &sy, pitch_mm);
    let mut x: Vec<f64> = topology
        .cells
        .iter()
        .map(|&p| {
            initial
                .and_then(|d| d.get(p).copied())
                .filter(|z| z.is_finite())
                .map_or(0.0, f64::from)
        })
        .collect();
    let iterations = equations.solve(&topology, &mut x, config.tolerance, config.max_iterations);
    let mut depth = Array2::from_elem(gradients.mask.dim(), f64::NAN);
    for (k, &p) in topology.cells.iter().enumerate() {
        depth[p] = x[k];
    }
    Ok((depth, iterations))
}

/// Multigrid-preconditioned conjugate gradients on `lap` x = b from the given x; returns
/// iterations.
pub(crate) fn conjugate_gradients(
    lap: &GridLaplacian,
    b: &[f64],
    x: &mut [f64],
    tolerance: f64,
    max_iterations: usize,
) -> usize {
    let mut multigrid = Multigrid::new(lap, REGULARISATION);
    preconditioned_cg(
        |u, v| lap.apply(u, v),
        |r, z| multigrid.precondition(lap, r, z),
        b,
        x,
        Stop::ResidualNorm(tolerance),
        max_iterations,
        &mut CgVectors::default(),
    )
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

    /// Straightforward reference: unpreconditioned CG on the same normal equations, to 1e-13.
    fn plain_cg(g: &SurfaceGradients, h: f64) -> Array2<f64> {
        let topology = Topology::new(&g.mask);
        let lap = topology.laplacian(&vec![[1.0; 2]; topology.len()]);
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
        let regions = crate::regions::label(&mask);
        let count = regions.sizes.len();
        let (mut sum, mut n) = (vec![0.0; count], vec![0usize; count]);
        for (p, &l) in regions.label.indexed_iter() {
            if l != crate::regions::OUTSIDE {
                sum[l as usize] += a[p] - b[p];
                n[l as usize] += 1;
            }
        }
        regions
            .label
            .indexed_iter()
            .filter(|(_, l)| **l != crate::regions::OUTSIDE)
            .map(|(p, &l)| (a[p] - b[p] - sum[l as usize] / n[l as usize] as f64).abs())
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
        let config = IntegrateConfig {
            integrator: crate::integrate::Integrator::LeastSquares,
            ..IntegrateConfig::default()
        };
        let out = integrate_gradients(&g, h, &config, None).unwrap();
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
