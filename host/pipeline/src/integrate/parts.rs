//! Pieces and parts of an integrated surface: each connected piece of the mask is anchored
//! separately (integration fixes depth only up to a constant per piece), and the bilateral
//! integrator's parts — pieces cut further at depth discontinuities — absorb parts too small
//! to stand on their own.

use super::DepthAnchor;
use super::least_squares::Topology;
use super::multigrid::NONE;
use ndarray::Array2;

/// Merges parts with fewer than `min` nodes into a neighbouring part and numbers the rest
/// 0, 1, …; a small part with no neighbour (a piece of its own) stays.
pub(super) fn absorb_small_parts(
    topology: &Topology,
    (mut label, count): (Vec<u32>, usize),
    min: usize,
) -> (Vec<u32>, usize) {
    let mut size = vec![0usize; count];
    for &l in &label {
        size[l as usize] += 1;
    }
    let small = |l: u32, size: &[usize]| size[l as usize] < min;
    loop {
        let mut changed = false;
        for k in 0..topology.len() {
            if !small(label[k], &size) {
                continue;
            }
            let big = topology.neighbours[k]
                .iter()
                .filter(|&&j| j != NONE)
                .map(|&j| label[j as usize])
                .find(|&l| !small(l, &size));
            if let Some(l) = big {
                size[label[k] as usize] -= 1;
                size[l as usize] += 1;
                label[k] = l;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    let mut renumber = vec![NONE; count];
    let mut next = 0u32;
    for l in &mut label {
        if renumber[*l as usize] == NONE {
            renumber[*l as usize] = next;
            next += 1;
        }
        *l = renumber[*l as usize];
    }
    (label, next as usize)
}

/// Shifts each piece of `depth` by a constant according to `anchor`: its outline (nodes with a
/// missing neighbour) or all of it gets mean zero.
pub(super) fn anchor(
    depth: &mut Array2<f64>,
    topology: &Topology,
    piece: &[u32],
    pieces: usize,
    anchor: DepthAnchor,
) {
    let mut sum = vec![0.0; pieces];
    let mut count = vec![0usize; pieces];
    for (k, &p) in topology.cells.iter().enumerate() {
        let on_outline = topology.neighbours[k].contains(&NONE);
        if depth[p].is_finite() && (anchor == DepthAnchor::Mean || on_outline) {
            sum[piece[k] as usize] += depth[p];
            count[piece[k] as usize] += 1;
        }
    }
    for (k, &p) in topology.cells.iter().enumerate() {
        let i = piece[k] as usize;
        if count[i] > 0 {
            depth[p] -= sum[i] / count[i] as f64;
        }
    }
}
