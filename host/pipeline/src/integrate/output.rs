//! A window's solution placed in the full grid: depth in mm, pieces and parts, classes and
//! the normals the integrator chose, for the pixels the artefact filter kept.

use super::grid::DepthGrid;
use super::least_squares::Topology;
use super::window::Window;
use super::{Confidence, Integration};
use meb_core::rig::Projection;
use meb_core::types::DepthMap;
use ndarray::{Array2, Array3};
use rayon::prelude::*;

/// The counts an [`Integration`] reports beside its arrays.
pub(super) struct Counts {
    /// Fraction of the integrated mask kept by the artefact filter.
    pub kept_fraction: f64,
    /// Solver iterations or accepted pixels.
    pub iterations: usize,
    /// Solves.
    pub passes: usize,
    /// Pieces of the graph.
    pub pieces: usize,
    /// Parts (pieces split along discontinuities).
    pub parts: usize,
    /// The automatic integrator's cut edges and pixels near them (`None` for the others).
    pub auto: Option<(usize, usize)>,
}

/// An empty `shape` result on `grid` with `counts`, whose arrays [`place_nodes`] fills.
pub(super) fn empty_integration(
    shape: (usize, usize),
    grid: &DepthGrid,
    counts: Counts,
) -> Integration {
    let (pitch_mm, perspective) = match grid {
        DepthGrid::Orthographic { pitch_mm } => (*pitch_mm, None),
        DepthGrid::Perspective {
            intrinsics,
            distance_mm,
        } => (
            distance_mm / intrinsics.fx,
            Some(Projection::Perspective {
                intrinsics: *intrinsics,
                distance_mm: *distance_mm,
            }),
        ),
    };
    Integration {
        depth: DepthMap {
            depth_mm: Array2::from_elem(shape, f32::NAN),
            pitch_mm,
            perspective,
        },
        kept: Array2::from_elem(shape, false),
        kept_fraction: counts.kept_fraction,
        iterations: counts.iterations,
        passes: counts.passes,
        pieces: counts.pieces,
        piece: Array2::from_elem(shape, u32::MAX),
        parts: counts.parts,
        part: Array2::from_elem(shape, u32::MAX),
        confidence: Array2::from_elem(shape, Confidence::None),
        completed_normals: Array3::from_elem((shape.0, shape.1, 3), f32::NAN),
        discontinuity_edges: counts.auto.map(|(edges, _)| edges),
        bilateral_pixels: counts.auto.map(|(_, near)| near),
    }
}

/// Rows of the output per parallel task.
const ROWS_PER_TASK: usize = 8;

/// What a window's solve found at its nodes, for [`place_nodes`].
pub(super) struct NodeResults<'a> {
    /// The window's graph.
    pub topology: &'a Topology,
    /// The window in the grid.
    pub window: &'a Window,
    /// The grid.
    pub grid: &'a DepthGrid,
    /// Each window pixel's class.
    pub class: &'a Array2<Confidence>,
    /// Window pixels the artefact filter kept.
    pub kept: &'a Array2<bool>,
    /// Depth of each window pixel (mm).
    pub depth_mm: &'a Array2<f64>,
    /// Slopes, piece and part of each node.
    pub slopes: &'a [(f64, f64)],
    pub piece: &'a [u32],
    pub part: &'a [u32],
}

/// Writes the kept nodes' depth, piece, part, class and (where not measured) completed normal
/// into `out`'s full-grid arrays (fresh, row-major), one output row per task: a window row's
/// nodes are a run of the raster-ordered nodes.
pub(super) fn place_nodes(out: &mut Integration, nodes: &NodeResults) {
    let cols = out.kept.ncols();
    let cells = &nodes.topology.cells;
    let (Some(depth), Some(kept), Some(piece), Some(part), Some(confidence), Some(normals)) = (
        out.depth.depth_mm.as_slice_mut(),
        out.kept.as_slice_mut(),
        out.piece.as_slice_mut(),
        out.part.as_slice_mut(),
        out.confidence.as_slice_mut(),
        out.completed_normals.as_slice_mut(),
    ) else {
        unreachable!("new arrays are in standard layout")
    };
    depth
        .par_chunks_mut(cols)
        .zip(kept.par_chunks_mut(cols))
        .zip(piece.par_chunks_mut(cols))
        .zip(part.par_chunks_mut(cols))
        .zip(confidence.par_chunks_mut(cols))
        .zip(normals.par_chunks_mut(3 * cols))
        .enumerate()
        .with_min_len(ROWS_PER_TASK)
        .for_each(
            |(row, (((((depth, kept), piece), part), confidence), normals))| {
                let Some(wr) = row.checked_sub(nodes.window.rows.start) else {
                    return;
                };
                let first = cells.partition_point(|&(r, _)| r < wr);
                let end = first + cells[first..].partition_point(|&(r, _)| r == wr);
                for (k, &(_, c)) in cells.iter().enumerate().take(end).skip(first) {
                    if !nodes.kept[(wr, c)] {
                        continue;
                    }
                    let col = c + nodes.window.cols.start;
                    depth[col] = nodes.depth_mm[(wr, c)] as f32;
                    kept[col] = true;
                    piece[col] = nodes.piece[k];
                    part[col] = nodes.part[k];
                    let class = nodes.class[(wr, c)];
                    confidence[col] = class;
                    if class != Confidence::Measured {
                        let (sx, sy) = nodes.slopes[k];
                        let n = nodes.grid.normal(row, col, sx, sy);
                        for j in 0..3 {
                            normals[3 * col + j] = n[j] as f32;
                        }
                    }
                }
            },
        );
}
