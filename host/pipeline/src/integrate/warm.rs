//! Warm starts: the unknown of every node of a new problem from a depth map found before (the
//! previous pass of a reconstruction, or the previous window of a video), so conjugate
//! gradients starts near the solution and the two-LED pixels can take their slopes from a
//! settled surface ([`super::solve`]).

use super::grid::DepthGrid;
use super::inpaint::inpaint;
use super::least_squares::Topology;
use ndarray::Array2;

/// The unknown at every node from depth `depth` (mm, whole grid; NaN where unknown), nodes
/// without a depth filled from their neighbours (push–pull, [`inpaint`]) so that they
/// do not start far from the surface; `None` when no node has a depth.
pub(super) fn warm_start(
    depth: &Array2<f32>,
    topology: &Topology,
    grid: &DepthGrid,
    (r0, c0): (usize, usize),
) -> Option<Vec<f64>> {
    let mut x: Vec<f64> = topology
        .cells
        .iter()
        .map(|&(r, c)| grid.unknown_of(f64::from(depth[(r + r0, c + c0)])))
        .collect();
    let missing = x.iter().filter(|u| !u.is_finite()).count();
    if missing == x.len() {
        return None;
    }
    if missing > 0 {
        let mut values = Array2::from_elem(topology.shape, f64::NAN);
        let mut known = Array2::from_elem(topology.shape, false);
        let mut wanted = Array2::from_elem(topology.shape, false);
        for (&p, &u) in topology.cells.iter().zip(&x) {
            values[p] = u;
            known[p] = u.is_finite();
            wanted[p] = true;
        }
        inpaint(&mut values, &known, &wanted);
        for (u, &p) in x.iter_mut().zip(&topology.cells) {
            if !u.is_finite() {
                *u = if values[p].is_finite() {
                    values[p]
                } else {
                    0.0
                };
            }
        }
    }
    Some(x)
}
