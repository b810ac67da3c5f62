//! Bilateral normal integration (Cao, Lin, Matsushita, Tao, "Bilateral Normal Integration",
//! ECCV 2022): a discontinuity-preserving weighted least-squares integrator.
//!
//! Every pixel i has one-sided equations along each axis, forward z_{i+1} − z_i = h·s_i and
//! backward z_i − z_{i−1} = h·s_i, scaled by n_z as in the paper (residual n_z·(Δz − h·s)). Their
//! weights w⁺ + w⁻ = 1 favour the side on which the surface continues smoothly:
//!
//! ```text
//! w⁺_i = σ(k · n_z² · ((z_i − z_{i−1})² − (z_{i+1} − z_i)²)),   σ(t) = 1/(1 + e^{−t})
//! ```
//!
//! with depth differences in pixel units and stiffness k (paper: 2). Across a depth jump the
//! weights of both pixels beside it turn away from it, so the jump no longer pulls the surfaces
//! together. The weights are updated from the current depth and the weighted problem re-solved
//! (iteratively reweighted least squares) until the energy changes by less than a tolerance.
//! Each edge collects the forward equation of its left/upper pixel and the backward equation of
//! its right/lower one; their weighted mean is the edge's target (\[`side_equations`\]), so every
//! solve is a weighted graph Laplacian for the multigrid-preconditioned CG of
//! [`super::least_squares`]. With w⁺ = w⁻ = ½ and no n_z factor this is plain least squares.

use super::AutoConfig;
use super::least_squares::{EdgeEquations, Topology};
use super::multigrid::{NONE, PARALLEL_BAND as NODES_PER_TASK};
use crate::regions::root;
use rayon::prelude::*;

/// Weights of a node's one-sided equations: right (forward x), down (forward row), left, up.
pub(crate) type SideWeights = [f64; 4];

/// Smallest edge weight kept, relative to the weights of its two pixels: across a cut the two
/// sides stay weakly tied (the near-field stage places them anyway), which keeps the system well
/// conditioned.
const WEIGHT_FLOOR: f64 = 1e-4;

/// ½·confidence on both sides of both axes: plain (confidence-weighted) least squares. Nodes
/// marked `scaled` get the n_z² factor of the bilateral equations, so a steep slope guessed
/// for a pixel without a measured normal cannot dominate its neighbours.
pub(crate) fn uniform(
    confidence: &[f64],
    slopes: &[(f64, f64)],
    scaled: &[bool],
) -> Vec<SideWeights> {
    confidence
        .par_iter()
        .with_min_len(NODES_PER_TASK)
        .zip(slopes)
        .zip(scaled)
        .map(|((&c, &(sx, sy)), &scale)| {
            let nz2 = if scale {
                1.0 / (1.0 + sx * sx + sy * sy)
            } else {
                1.0
            };
            [0.5 * c * nz2; 4]
        })
        .collect()
}

/// How steep the sigmoid weights are: `units` (pixels per unit of the unknown) and stiffness k.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Stiffness {
    /// Pixels per unit of the unknown.
    pub units: f64,
    /// Stiffness k.
    pub k: f64,
}

/// The bilateral weights at the current solution `x` (module docs).
pub(crate) fn bilateral(
    topology: &Topology,
    x: &[f64],
    slopes: &[(f64, f64)],
    confidence: &[f64],
    stiffness: Stiffness,
) -> Vec<SideWeights> {
    sigmoid_weights(topology, x, slopes, stiffness)
        .into_iter()
        .enumerate()
        .map(|(k, w)| {
            let (sx, sy) = slopes[k];
            let scale = confidence[k] / (1.0 + sx * sx + sy * sy);
            w.map(|v| v * scale)
        })
        .collect()
}

/// The sigmoid weights w⁺, w⁻ of every node along both axes (right, down, left, up), before the
/// n_z² and confidence factors.
fn sigmoid_weights(
    topology: &Topology,
    x: &[f64],
    slopes: &[(f64, f64)],
    stiffness: Stiffness,
) -> Vec<SideWeights> {
    let sigmoid = |t: f64| 1.0 / (1.0 + (-t).exp());
    let Stiffness {
        units,
        k: stiffness,
    } = stiffness;
    topology
        .neighbours
        .iter()
        .enumerate()
        .map(|(k, nb)| {
            let (sx, sy) = slopes[k];
            let nz2 = 1.0 / (1.0 + sx * sx + sy * sy);
            let mut w = [0.0; 4];
            // Axis 0: right (0) / left (2); axis 1: down (1) / up (3).
            for (forward, backward) in [(0, 2), (1, 3)] {
                let (f, b) = (nb[forward], nb[backward]);
                (w[forward], w[backward]) = match (f != NONE, b != NONE) {
                    (true, true) => {
                        let ahead = (x[f as usize] - x[k]) * units;
                        let behind = (x[k] - x[b as usize]) * units;
                        let wf = sigmoid(stiffness * nz2 * (behind * behind - ahead * ahead));
                        (wf, 1.0 - wf)
                    }
                    (true, false) => (1.0, 0.0),
                    (false, true) => (0.0, 1.0),
                    (false, false) => (0.0, 0.0),
                };
            }
            w
        })
        .collect()
}

/// Edges (right, down of each node) where both one-sided equations have turned away — the
/// forward weight of the node and the backward weight of its neighbour both below `cut`: the
/// depth discontinuities the bilateral integrator found.
pub(crate) fn discontinuities(
    topology: &Topology,
    x: &[f64],
    slopes: &[(f64, f64)],
    stiffness: Stiffness,
    cut: f64,
) -> Vec<[bool; 2]> {
    let w = sigmoid_weights(topology, x, slopes, stiffness);
    topology
        .neighbours
        .iter()
        .enumerate()
        .map(|(k, nb)| {
            [0, 1].map(|d| {
                let j = nb[d];
                j != NONE && w[k][d] < cut && w[j as usize][d + 2] < cut
            })
        })
        .collect()
}

/// Whether the edge i → j (right or down, axis `d`) departs from the slopes of its two pixels
/// by at least `jump`: the trapezoid rule's residual |Δz − h·(g_i + g_j)/2| in pixel units.
fn departs(
    x: &[f64],
    slopes: &[(f64, f64)],
    units: f64,
    (i, j, d): (usize, usize, usize),
    jump: f64,
) -> bool {
    let along = |k: usize| if d == 0 { slopes[k].0 } else { -slopes[k].1 };
    let residual = (x[j] - x[i]) * units - 0.5 * (along(i) + along(j));
    residual.abs() >= jump
}

/// Whether the pixels from node `k` run on for `steps` grid steps in direction `side`.
fn runs_on(topology: &Topology, k: usize, side: usize, steps: usize) -> bool {
    let mut node = k;
    (0..steps).all(|_| {
        let next = topology.neighbours[node][side];
        node = next as usize;
        next != NONE
    })
}

/// Keeps of the cut edges (as [`discontinuities`] finds them) those that pass the automatic
/// integrator's tests ([`AutoConfig`]): both pixels' lines run on across the edge for
/// `decision.rim` steps and the depth across it departs from its slopes ([`departs`]).
pub(crate) fn decisive_cuts(
    topology: &Topology,
    x: &[f64],
    slopes: &[(f64, f64)],
    stiffness: Stiffness,
    decision: &AutoConfig,
    cut: &mut [[bool; 2]],
) {
    for (k, edges) in cut.iter_mut().enumerate() {
        for (d, edge) in edges.iter_mut().enumerate() {
            if *edge {
                let j = topology.neighbours[k][d] as usize;
                *edge = runs_on(topology, k, d, decision.rim)
                    && runs_on(topology, j, d + 2, decision.rim)
                    && departs(x, slopes, stiffness.units, (k, j, d), decision.min_jump_px);
            }
        }
    }
}

/// Clears the cut edges of every chain shorter than `min_edges`: a depth discontinuity is a
/// curve in the image, so its cut edges join end to end (two edges are chained when their
/// segments between pixel corners share a corner), while noise cuts an edge here and there.
pub(crate) fn drop_short_cuts(topology: &Topology, cut: &mut [[bool; 2]], min_edges: usize) {
    if min_edges <= 1 {
        return;
    }
    // Corners of the pixels' bounding box, one more row and column than its pixels.
    let (rows, cols) = topology.cells.iter().fold((0, 0), |(rows, cols), &(r, c)| {
        (rows.max(r + 2), cols.max(c + 2))
    });
    let corner = |r: usize, c: usize| r * cols + c;
    // The segment between pixel corners that edge d of the node at (r, c) crosses.
    let segment = |(r, c): (usize, usize), d: usize| {
        if d == 0 {
            (corner(r, c + 1), corner(r + 1, c + 1))
        } else {
            (corner(r + 1, c), corner(r + 1, c + 1))
        }
    };
    let mut parent: Vec<u32> = (0..(rows * cols) as u32).collect();
    // Every cut edge as (node, axis).
    let edges: Vec<(usize, usize)> = cut
        .iter()
        .enumerate()
        .flat_map(|(k, e)| (0..2).filter(move |&d| e[d]).map(move |d| (k, d)))
        .collect();
    for &(k, d) in &edges {
        let (a, b) = segment(topology.cells[k], d);
        let (ra, rb) = (root(&mut parent, a as u32), root(&mut parent, b as u32));
        parent[ra as usize] = rb;
    }
    let chain_root = |parent: &mut [u32], k: usize, d: usize| {
        root(parent, segment(topology.cells[k], d).0 as u32) as usize
    };
    let mut chain_of = vec![0usize; rows * cols];
    for &(k, d) in &edges {
        chain_of[chain_root(&mut parent, k, d)] += 1;
    }
    for &(k, d) in &edges {
        cut[k][d] = chain_of[chain_root(&mut parent, k, d)] >= min_edges;
    }
}

/// Nodes within `decision.radius` grid steps of a node where the bilateral weights are
/// decisive ([`AutoConfig`]): one of its one-sided weights (on an axis with both neighbours) is
/// below `decision.decisive_weight` (the surface continues on one side only), the pixels on that
/// side run on along the axis for at least `decision.rim` steps (at the end of a line the
/// one-sided differences of a steep curved rim differ by its curvature alone), and the depth
/// across that side's edge departs from the slopes of its two pixels by at least
/// `decision.min_jump_px` ([`departs`]). Elsewhere both sides agree and least squares is as
/// good.
pub(crate) fn near_discontinuities(
    topology: &Topology,
    x: &[f64],
    slopes: &[(f64, f64)],
    stiffness: Stiffness,
    decision: &AutoConfig,
) -> Vec<bool> {
    let (cut, jump) = (decision.decisive_weight, decision.min_jump_px);
    let w = sigmoid_weights(topology, x, slopes, stiffness);
    let mut near: Vec<bool> = (0..topology.len())
        .map(|k| {
            [(0, 2), (1, 3)].iter().any(|&(f, b)| {
                let decisive =
                    |side: usize| w[k][side] < cut && runs_on(topology, k, side, decision.rim);
                let nb = topology.neighbours[k];
                nb[f] != NONE
                    && nb[b] != NONE
                    && ((decisive(f)
                        && departs(x, slopes, stiffness.units, (k, nb[f] as usize, f), jump))
                        || (decisive(b)
                            && departs(x, slopes, stiffness.units, (nb[b] as usize, k, f), jump)))
            })
        })
        .collect();
    for _ in 0..decision.radius {
        let grown: Vec<bool> = topology
            .neighbours
            .iter()
            .enumerate()
            .map(|(k, nb)| near[k] || nb.iter().any(|&j| j != NONE && near[j as usize]))
            .collect();
        near = grown;
    }
    near
}

/// Removes both one-sided equations of every `cut` edge (right, down of each node, as
/// [`discontinuities`] finds them) from `sides`: the edge keeps only the floor weight of
/// [`side_equations`], so depth may jump across it.
pub(crate) fn cut_sides(topology: &Topology, cut: &[[bool; 2]], sides: &mut [SideWeights]) {
    for (k, (nb, edges)) in topology.neighbours.iter().zip(cut).enumerate() {
        for d in 0..2 {
            if edges[d] && nb[d] != NONE {
                sides[k][d] = 0.0;
                sides[nb[d] as usize][d + 2] = 0.0;
            }
        }
    }
}

/// The two one-sided equations of an edge k→j (right or down): the forward equation of node k
/// and the backward equation of node j, with their weights and slopes h·s along the edge.
struct EdgeSides {
    /// The left/upper node.
    k: usize,
    /// Axis: 0 right, 1 down.
    d: usize,
    /// Weights of the forward equation of k and the backward equation of j.
    w: (f64, f64),
    /// Slopes of k and j along the edge (y up, so negated for the down edges).
    g: (f64, f64),
    /// The right/lower node.
    j: usize,
}

/// The one-sided equations ([`EdgeSides`]) of node k's right and down edges.
fn node_edges<'a>(
    topology: &'a Topology,
    sides: &'a [SideWeights],
    slopes: &'a [(f64, f64)],
    k: usize,
) -> impl Iterator<Item = EdgeSides> + 'a {
    let nb = topology.neighbours[k];
    let (own_sides, own_slopes) = (&sides[k], slopes[k]);
    (0..2).filter_map(move |d| {
        let j = nb[d];
        if j == NONE {
            return None;
        }
        let j = j as usize;
        let g = match d {
            0 => (own_slopes.0, slopes[j].0),
            _ => (-own_slopes.1, -slopes[j].1),
        };
        Some(EdgeSides {
            k,
            d,
            w: (own_sides[d], sides[j][d + 2]),
            g,
            j,
        })
    })
}

/// Edge equations from one-sided equations: edge k→j (right or down) has weight
/// W = w_k(forward) + w_j(backward) and target the weighted mean of h·s_k and h·s_j (with the
/// sign of y up for the down edges). Every node's two edges are found on their own, in
/// parallel.
pub(crate) fn side_equations(
    topology: &Topology,
    sides: &[SideWeights],
    slopes: &[(f64, f64)],
    step: f64,
) -> EdgeEquations {
    // The floor scales with both nodes' side weights summed (computed here only: the energy
    // does not need them), once per node rather than once per edge end.
    let side_sums: Vec<f64> = sides
        .par_iter()
        .with_min_len(NODES_PER_TASK)
        .map(|s| s.iter().sum::<f64>())
        .collect();
    let (weight, target) = (0..topology.len())
        .into_par_iter()
        .with_min_len(NODES_PER_TASK)
        .map(|k| {
            let (mut weight, mut target) = ([0.0; 2], [0.0; 2]);
            for e in node_edges(topology, sides, slopes, k) {
                let (wk, wj) = e.w;
                let (gk, gj) = e.g;
                let total = wk + wj;
                let sides_total = side_sums[e.k] + side_sums[e.j];
                weight[e.d] = total.max(WEIGHT_FLOOR * sides_total).max(f64::MIN_POSITIVE);
                target[e.d] = if total > 0.0 {
                    step * (wk * gk + wj * gj) / total
                } else {
                    0.5 * step * (gk + gj)
                };
            }
            (weight, target)
        })
        .unzip();
    EdgeEquations { weight, target }
}

/// Σ over one-sided equations of w·(Δz − h·s)² at `x` (the bilateral energy), summed in
/// parallel over fixed bands of nodes and then over the bands in order, so the sum does not
/// depend on how the work was shared.
pub(crate) fn energy(
    topology: &Topology,
    sides: &[SideWeights],
    slopes: &[(f64, f64)],
    step: f64,
    x: &[f64],
) -> f64 {
    let bands: Vec<f64> = (0..topology.len().div_ceil(NODES_PER_TASK))
        .into_par_iter()
        .map(|band| {
            let nodes = band * NODES_PER_TASK..((band + 1) * NODES_PER_TASK).min(topology.len());
            // Summed in order from −0 like `Iterator::sum`.
            let mut sum = -0.0;
            for k in nodes {
                for e in node_edges(topology, sides, slopes, k) {
                    let delta = x[e.j] - x[e.k];
                    sum += e.w.0 * (delta - step * e.g.0).powi(2)
                        + e.w.1 * (delta - step * e.g.1).powi(2);
                }
            }
            sum
        })
        .collect();
    bands.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// Two flat terraces 10 pixels apart in height with zero slopes everywhere except the
    /// (wrongly smooth) slope across the step: the weights beside the step turn away from it.
    #[test]
    fn weights_turn_away_from_a_step() {
        let mask = Array2::from_elem((3, 8), true);
        let topology = Topology::new(&mask);
        let x: Vec<f64> = topology
            .cells
            .iter()
            .map(|&(_, c)| if c < 4 { 0.0 } else { 10.0 })
            .collect();
        let slopes = vec![(0.0, 0.0); topology.len()];
        let stiffness = Stiffness { units: 1.0, k: 2.0 };
        let w = bilateral(
            &topology,
            &x,
            &slopes,
            &vec![1.0; topology.len()],
            stiffness,
        );
        let left_of_step = topology.node((1, 3)).unwrap();
        let right_of_step = topology.node((1, 4)).unwrap();
        assert!(w[left_of_step][0] < 1e-6 && w[left_of_step][2] > 1.0 - 1e-6);
        assert!(w[right_of_step][2] < 1e-6 && w[right_of_step][0] > 1.0 - 1e-6);
        let flat = topology.node((1, 1)).unwrap();
        assert!((w[flat][0] - 0.5).abs() < 1e-12);
        // The edge across the step keeps only the floor weight.
        let eq = side_equations(&topology, &w, &slopes, 1.0);
        assert!(eq.weight[left_of_step][0] < 1e-3);
        assert!((eq.weight[flat][0] - 1.0).abs() < 1e-12);
    }

    /// Which nodes [`near_discontinuities`] marks on a 9 × 12 grid whose depth (pixel units)
    /// along each row is `profile(col)` with slopes `slope(col)`, for `auto` (radius 0).
    fn near_columns(
        profile: impl Fn(f64) -> f64,
        slope: impl Fn(f64) -> f64,
        k: f64,
        auto: AutoConfig,
    ) -> Vec<usize> {
        let mask = Array2::from_elem((9, 12), true);
        let topology = Topology::new(&mask);
        let x: Vec<f64> = topology
            .cells
            .iter()
            .map(|&(_, c)| profile(c as f64))
            .collect();
        let slopes: Vec<(f64, f64)> = topology
            .cells
            .iter()
            .map(|&(_, c)| (slope(c as f64), 0.0))
            .collect();
        let stiffness = Stiffness { units: 1.0, k };
        let near = near_discontinuities(
            &topology,
            &x,
            &slopes,
            stiffness,
            &AutoConfig { radius: 0, ..auto },
        );
        let mut columns: Vec<usize> = topology
            .cells
            .iter()
            .zip(&near)
            .filter(|&(&(r, _), &n)| n && r == 4)
            .map(|(&(_, c), _)| c)
            .collect();
        columns.dedup();
        columns
    }

    /// A jump in depth inside the grid is a discontinuity; a steep parabola whose depth follows
    /// its slopes is one only without the jump test, and a jump beside the outline only without
    /// the rim test.
    #[test]
    fn discontinuities_need_a_jump_away_from_the_outline() {
        let auto = AutoConfig::default;
        let step = |at: f64| move |c: f64| if c < at { 0.0 } else { 10.0 };
        let flat = |_: f64| 0.0;
        assert_eq!(near_columns(step(6.0), flat, 2.0, auto()), vec![5, 6]);
        let small_jumps = AutoConfig {
            min_jump_px: 0.5,
            ..auto()
        };
        assert_eq!(
            near_columns(step(6.0), flat, 2.0, small_jumps.clone()),
            vec![5, 6]
        );
        let large_jumps = AutoConfig {
            min_jump_px: 20.0,
            ..auto()
        };
        assert!(near_columns(step(6.0), flat, 2.0, large_jumps).is_empty());
        // z = c²/2 with slope c: the trapezoid rule is exact, the stiff sigmoid still decisive.
        let parabola = |c: f64| 0.5 * c * c;
        let any_jump = AutoConfig {
            min_jump_px: 0.0,
            ..auto()
        };
        assert!(!near_columns(parabola, |c| c, 10.0, any_jump).is_empty());
        assert!(near_columns(parabola, |c| c, 10.0, small_jumps).is_empty());
        // A jump between columns 0 and 1: the line behind column 1 ends after one step.
        let no_rim = AutoConfig { rim: 0, ..auto() };
        assert_eq!(near_columns(step(1.0), flat, 2.0, no_rim), vec![1]);
        assert!(near_columns(step(1.0), flat, 2.0, auto()).is_empty());
    }

    /// Cut edges along a wall survive as one chain, a lone cut edge is dropped, and a wall
    /// beside the outline or one whose depth follows the slopes is not cut.
    #[test]
    fn cuts_are_chains_of_jumps_away_from_the_outline() {
        let mask = Array2::from_elem((9, 12), true);
        let topology = Topology::new(&mask);
        let wall = |at: usize| -> Vec<[bool; 2]> {
            topology
                .cells
                .iter()
                .map(|&(_, c)| [c + 1 == at, false])
                .collect()
        };
        let mut cut = wall(6);
        let lone = topology.node((2, 1)).unwrap();
        cut[lone][1] = true;
        drop_short_cuts(&topology, &mut cut, 4);
        let kept: Vec<(usize, usize)> = topology
            .cells
            .iter()
            .zip(&cut)
            .flat_map(|(&(r, c), e)| (0..2).filter(|&d| e[d]).map(move |d| (r * 12 + c, d)))
            .collect();
        assert_eq!(kept.len(), 9, "{kept:?}");
        assert!(kept.iter().all(|&(k, d)| k % 12 == 5 && d == 0));

        let decide = |at: usize, depth_step: f64| {
            let x: Vec<f64> = topology
                .cells
                .iter()
                .map(|&(_, c)| if c < at { 0.0 } else { depth_step })
                .collect();
            // Flat slopes: the step departs from them by `depth_step` pixels.
            let slopes = vec![(0.0, 0.0); topology.len()];
            let mut cut = wall(at);
            let stiffness = Stiffness { units: 1.0, k: 2.0 };
            let auto = AutoConfig {
                min_jump_px: 1.0,
                ..AutoConfig::default()
            };
            decisive_cuts(&topology, &x, &slopes, stiffness, &auto, &mut cut);
            cut.iter().filter(|e| e[0]).count()
        };
        assert_eq!(decide(6, 10.0), 9);
        assert_eq!(decide(1, 10.0), 0, "beside the outline");
        assert_eq!(decide(6, 0.5), 0, "within the jump the slopes allow");
    }
}
