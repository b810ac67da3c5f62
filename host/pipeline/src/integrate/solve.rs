//! The least-squares solve of one window problem: slopes of two-LED pixels and holes filled in
//! ([`super::inpaint`]), the two-LED alternation between depth and slopes ([`super::coverage`]),
//! bilateral reweighting ([`super::bilateral`]), multigrid-preconditioned conjugate gradients
//! ([`super::multigrid`]), then pieces, anchoring, the artefact filter and the full-grid output.

use super::grid::DepthGrid;
use super::inpaint::{Inpainting, inpaint};
use super::least_squares::{self, EdgeEquations, Topology};
use super::multigrid::{GridLaplacian, Multigrid};
use super::parts::{absorb_small_parts, anchor};
use super::pcg::{Stop, preconditioned_cg};
use super::warm::warm_start;
use super::window::Window;
use super::{
    Confidence, IntegrateConfig, IntegrateError, Integration, IntegrationWorkspace, Integrator,
    NormalPlane, SurfaceGradients, bilateral, coverage, fast_marching, filter_artefacts, workspace,
};
use meb_core::rig::Projection;
use meb_core::types::DepthMap;
use ndarray::{Array2, Array3, Zip};
use rayon::prelude::*;
use std::time::Instant;

/// Solve tolerance of a reweighting pass relative to the last pass's relative energy change.
const INEXACT_SOLVE: f64 = 1e-2;

/// Loosest relative residual of a reweighting pass's solve.
const LOOSEST_SOLVE: f64 = 1e-4;

/// A bilateral weight below which both sides of an edge have turned away from it.
const DISCONTINUITY_WEIGHT: f64 = 0.05;

/// Fewest pixels of a part (or 1 % of the mask, if more); smaller ones join a neighbour.
const MIN_PART_PIXELS: usize = 200;

/// One integration problem on a window of the grid.
pub(super) struct Problem {
    /// Class of every window pixel.
    pub class: Array2<Confidence>,
    /// Slopes (s_x, s_y) of measured pixels (others are filled in).
    pub slopes: Array2<(f64, f64)>,
    /// Two-LED pixels, in window coordinates.
    pub planes: Vec<NormalPlane>,
    /// Albedo of measured pixels (NaN elsewhere or when unknown).
    pub albedo: Array2<f64>,
    /// Window origin in the grid (row, column).
    pub origin: (usize, usize),
    /// The unknown and its slopes.
    pub grid: DepthGrid,
}

/// Two-LED pixels per parallel task of [`update_two_led_slopes`].
const PLANES_PER_TASK: usize = 1024;

/// Sets the slopes of every two-LED pixel `planes[i]` that `new(slopes, i)` gives a value for.
/// Each pixel's new value depends on the slopes before the update and its own data only, so
/// they are found in parallel and then stored.
fn update_two_led_slopes(
    slopes: &mut [(f64, f64)],
    planes: &[(usize, NormalPlane)],
    new: impl Fn(&[(f64, f64)], usize) -> Option<(f64, f64)> + Sync,
) {
    let before: &[(f64, f64)] = slopes;
    let updated: Vec<Option<(f64, f64)>> = (0..planes.len())
        .into_par_iter()
        .with_min_len(PLANES_PER_TASK)
        .map(|i| new(before, i))
        .collect();
    for ((k, _), s) in planes.iter().zip(updated) {
        if let Some(s) = s {
            slopes[*k] = s;
        }
    }
}

/// The slopes of two-LED pixels and holes, and the albedo of two-LED pixels, filled in from
/// the measured pixels around them ([`super::inpaint`]).
fn filled_in(
    problem: &Problem,
    region: &Array2<bool>,
    topology: &Topology,
) -> (Array2<(f64, f64)>, Array2<f64>) {
    let known = problem.class.mapv(|k| k == Confidence::Measured);
    let albedo_known = Zip::from(&known)
        .and(&problem.albedo)
        .map_collect(|&k, &a| k && a.is_finite() && a > 0.0);
    let fill_slopes = known.iter().any(|&k| k) && known != region;
    let fill_albedo = problem
        .planes
        .iter()
        .any(|p| topology.node(p.pixel).is_some())
        && albedo_known.iter().any(|&k| k);
    if fill_albedo && albedo_known == known {
        // The albedo is known where the slopes are (and a two-LED pixel is in the region, so
        // not all of it is known): all three channels in one pass, each bit for bit as on
        // its own.
        let mut joint = Zip::from(&problem.slopes)
            .and(&problem.albedo)
            .map_collect(|&(sx, sy), &a| (sx, sy, a));
        Inpainting::new(&known, region).fill(&mut joint);
        return (joint.mapv(|(sx, sy, _)| (sx, sy)), joint.mapv(|j| j.2));
    }
    let (mut slopes, mut albedo) = (problem.slopes.clone(), problem.albedo.clone());
    rayon::join(
        || {
            if fill_slopes {
                // s_x and s_y in one pass over their shared pyramid and stencil.
                Inpainting::new(&known, region).fill(&mut slopes);
            }
        },
        || {
            if fill_albedo {
                inpaint(&mut albedo, &albedo_known, region);
            }
        },
    );
    (slopes, albedo)
}

/// Solves a window problem and places depth, confidence and normals in a `shape` grid.
pub(super) fn solve_window(
    problem: &Problem,
    window: &Window,
    shape: (usize, usize),
    config: &IntegrateConfig,
    initial: Option<&Array2<f32>>,
    workspace: &mut IntegrationWorkspace,
) -> Result<Integration, IntegrateError> {
    let profile = &mut workspace.profile;
    let t = Instant::now();
    let region = problem.class.mapv(|k| k != Confidence::None);
    // The graph (and hierarchy) of the last call when the mask is the same.
    let cached = workspace
        .cached
        .take()
        .filter(|c| c.origin == problem.origin && c.region == region);
    profile.reused_graph = cached.is_some();
    let (topology, mut laplacian, mut hierarchy) = match cached {
        Some(c) => (c.topology, c.laplacian, c.hierarchy),
        None => (Topology::new(&region), None, None),
    };
    profile.add("graph", t);
    if topology.len() == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    let t = Instant::now();
    let grid = &problem.grid;
    let step = grid.step();
    let (r0, c0) = problem.origin;
    let (filled_slopes, albedo) = filled_in(problem, &region, &topology);
    profile.add("inpainting", t);
    let t = Instant::now();
    let mut slopes: Vec<(f64, f64)> = topology.cells.iter().map(|&p| filled_slopes[p]).collect();
    let planes: Vec<(usize, NormalPlane)> = problem
        .planes
        .iter()
        .filter_map(|p| topology.node(p.pixel).map(|k| (k, *p)))
        .collect();
    let clip = |s: (f64, f64)| {
        (
            s.0.clamp(-config.max_slope, config.max_slope),
            s.1.clamp(-config.max_slope, config.max_slope),
        )
    };
    // Two-LED pixels: the line a·s_x + b·s_y = c their circle is in slope space.
    let lines: Vec<(f64, f64, f64)> = planes
        .iter()
        .map(|(_, plane)| {
            let [a0, a1, a2] = grid.normal_affine(plane.pixel.0 + r0, plane.pixel.1 + c0);
            let m = plane.across;
            (m.dot(&a1), m.dot(&a2), -m.dot(&a0))
        })
        .collect();
    // Keeps slopes on the lit half of the circle, within its tilt limit.
    let on_circle = |plane: &NormalPlane, s: (f64, f64)| {
        let (r, c) = (plane.pixel.0 + r0, plane.pixel.1 + c0);
        plane
            .project(&grid.normal(r, c, s.0, s.1))
            .and_then(|n| grid.slopes(r, c, &n))
            .map(clip)
    };
    // The point of the circle with the interpolated albedo on the side of slopes `s` (`s` when
    // the albedo or the circle's g₀ is unknown).
    let with_albedo = |plane: &NormalPlane, s: (f64, f64)| {
        let (r, c) = (plane.pixel.0 + r0, plane.pixel.1 + c0);
        plane
            .with_albedo(albedo[plane.pixel], &grid.normal(r, c, s.0, s.1))
            .and_then(|m| grid.slopes(r, c, &m))
            .map_or(s, clip)
    };
    update_two_led_slopes(&mut slopes, &planes, |slopes, i| {
        let (k, plane) = &planes[i];
        on_circle(plane, slopes[*k])
    });
    let confidence: Vec<f64> = topology
        .cells
        .iter()
        .map(|&p| match problem.class[p] {
            Confidence::Measured => 1.0,
            Confidence::TwoLeds => config.coverage.two_led_weight,
            _ => config.coverage.fill_weight,
        })
        .collect();
    let estimated: Vec<bool> = topology
        .cells
        .iter()
        .map(|&p| problem.class[p] != Confidence::Measured)
        .collect();
    profile.add("set-up", t);
    let t = Instant::now();
    let warm = initial
        .filter(|d| d.dim() == shape)
        .and_then(|d| warm_start(d, &topology, grid, problem.origin));
    let mut x = warm.clone().unwrap_or_else(|| vec![0.0; topology.len()]);
    profile.add("warm start", t);
    // The automatic integrator reweights as the bilateral one does, then solves least squares
    // with the discontinuities it found cut ([`cut_solve`]).
    let bilateral = matches!(config.integrator, Integrator::Bilateral | Integrator::Auto);
    let stiffness = bilateral::Stiffness {
        units: grid.pixel_units(),
        k: config.bilateral.stiffness,
    };
    let passes_allowed = match config.integrator {
        Integrator::Bilateral | Integrator::Auto => config.bilateral.max_iterations,
        _ if planes.is_empty() => 1,
        _ => config.coverage.iterations,
    };
    let (mut iterations, mut passes) = (0, 0);
    // Each node's piece and the piece count, once labelled.
    let mut pieces_of_graph: Option<(Vec<u32>, usize)> = None;
    let mut previous_energy: Option<f64> = None;
    // Reweighting passes need solves only as exact as the weights are settled (inexact IRLS).
    let mut solve_tolerance = config.tolerance;
    let mut use_albedo = false;
    // From a warm start the depth has settled already (the previous pass's or window's): the
    // two-LED pixels take their slopes, and the albedo's side, from it before the first solve
    // instead of alternating from the filled-in slopes (typically 2–3 solves instead of 6–8).
    if warm.is_some() && !bilateral && !planes.is_empty() {
        let t = Instant::now();
        let sides = bilateral::uniform(&confidence, &slopes, &estimated);
        update_two_led_slopes(&mut slopes, &planes, |_, i| {
            let (k, plane) = &planes[i];
            coverage::slopes_on_line(&topology, &x, *k, &sides[*k], step, lines[i])
                .and_then(|s| on_circle(plane, s))
                .map(|s| with_albedo(plane, s))
        });
        use_albedo = true;
        profile.add("coverage", t);
    }
    for pass in 0..passes_allowed {
        passes = pass + 1;
        let t = Instant::now();
        let sides = if bilateral && (pass > 0 || warm.is_some()) {
            bilateral::bilateral(&topology, &x, &slopes, &confidence, stiffness)
        } else {
            bilateral::uniform(&confidence, &slopes, &estimated)
        };
        let equations: EdgeEquations = bilateral::side_equations(&topology, &sides, &slopes, step);
        // The graph's Laplacian is built once and then takes each pass's weights in place.
        let lap: &GridLaplacian = match laplacian.as_mut() {
            Some(l) => {
                topology.reweight_laplacian(l, &equations.weight);
                l
            }
            None => laplacian.insert(topology.laplacian(&equations.weight)),
        };
        let b = equations.right_hand_side(&topology);
        profile.add("edge equations", t);
        let t = Instant::now();
        // Fresh coarse operators for every solve: the two-LED pixels' weights 0.5·n_z² follow
        // their slopes, and operators kept from the first pass doubled the iterations on the
        // turning ellipsoid (cold: 75 instead of 36 over 6 passes). The aggregation depends
        // on the graph only, so it is kept across solves (and calls) on the same mask.
        let multigrid = match hierarchy.as_mut() {
            Some(m) => {
                m.reweight(lap, least_squares::REGULARISATION);
                m
            }
            None => {
                // The pieces depend on the graph alone: they are labelled beside the
                // hierarchy's (mostly serial) set-up instead of after the solves.
                let (m, labelled) = rayon::join(
                    || Multigrid::new(lap, least_squares::REGULARISATION),
                    || topology.components(),
                );
                pieces_of_graph.get_or_insert(labelled);
                hierarchy.insert(m)
            }
        };
        profile.add("hierarchy setup", t);
        let t = Instant::now();
        let solved = preconditioned_cg(
            |u, v| lap.apply(u, v),
            |r, z| multigrid.precondition(lap, r, z),
            &b,
            &mut x,
            Stop::ResidualNorm(solve_tolerance),
            config.max_iterations,
            &mut workspace.cg,
        );
        profile.add("conjugate gradients", t);
        profile.solve_iterations.push(solved);
        iterations += solved;
        let t = Instant::now();
        update_two_led_slopes(&mut slopes, &planes, |_, i| {
            let (k, plane) = &planes[i];
            coverage::slopes_on_line(&topology, &x, *k, &sides[*k], step, lines[i])
                .and_then(|s| on_circle(plane, s))
                .map(|s| if use_albedo { with_albedo(plane, s) } else { s })
        });
        if passes_allowed == 1 {
            break;
        }
        let e = bilateral::energy(&topology, &sides, &slopes, step, &x);
        profile.add("coverage", t);
        let relative = previous_energy.map(|p| (p - e).abs() / p.max(f64::MIN_POSITIVE));
        previous_energy = Some(e);
        if let Some(r) = relative {
            solve_tolerance = (r * INEXACT_SOLVE).clamp(config.tolerance, LOOSEST_SOLVE);
        }
        let tolerance = if bilateral {
            config.bilateral.tolerance
        } else {
            config.coverage.tolerance
        };
        let settled = relative.is_some_and(|r| r < tolerance);
        // The albedo's side is taken from the depth once the free alternation has settled
        // (or used half its passes): a flat face fits either mirror image, so a side picked
        // from the slopes filled in from other faces would stay.
        if !use_albedo && (settled || 2 * passes >= passes_allowed) {
            use_albedo = true;
            previous_energy = None;
            update_two_led_slopes(&mut slopes, &planes, |slopes, i| {
                let (k, plane) = &planes[i];
                Some(with_albedo(plane, slopes[*k]))
            });
            continue;
        }
        if settled {
            break;
        }
    }
    let mut auto_cut = None;
    let mut auto_near = 0;
    if config.integrator == Integrator::Auto {
        let t = Instant::now();
        let cut =
            bilateral::discontinuities(&topology, &x, &slopes, stiffness, DISCONTINUITY_WEIGHT);
        let near = bilateral::near_discontinuities(
            &topology,
            &x,
            &slopes,
            stiffness,
            config.auto.decisive_weight,
            config.auto.radius,
        );
        let weighted = bilateral::bilateral(&topology, &x, &slopes, &confidence, stiffness);
        let mut sides = bilateral::uniform(&confidence, &slopes, &estimated);
        for ((side, w), &n) in sides.iter_mut().zip(weighted).zip(&near) {
            if n {
                *side = w;
            }
        }
        bilateral::cut_sides(&topology, &cut, &mut sides);
        auto_near = near.iter().filter(|&&n| n).count();
        auto_cut = Some(cut);
        let equations = bilateral::side_equations(&topology, &sides, &slopes, step);
        let lap: &GridLaplacian = match laplacian.as_mut() {
            Some(l) => {
                topology.reweight_laplacian(l, &equations.weight);
                l
            }
            None => laplacian.insert(topology.laplacian(&equations.weight)),
        };
        let b = equations.right_hand_side(&topology);
        let multigrid = match hierarchy.as_mut() {
            Some(m) => {
                m.reweight(lap, least_squares::REGULARISATION);
                m
            }
            None => hierarchy.insert(Multigrid::new(lap, least_squares::REGULARISATION)),
        };
        let solved = preconditioned_cg(
            |u, v| lap.apply(u, v),
            |r, z| multigrid.precondition(lap, r, z),
            &b,
            &mut x,
            Stop::ResidualNorm(config.tolerance),
            config.max_iterations,
            &mut workspace.cg,
        );
        profile.solve_iterations.push(solved);
        iterations += solved;
        passes += 1;
        profile.add("least squares with the discontinuities cut", t);
    }
    let t = Instant::now();
    // Pieces, and parts: pieces further split where the bilateral integrator found a depth
    // discontinuity all the way across (their relative depth is unknown to the normals). The
    // two labellings are independent and run side by side (the pieces of a fresh graph were
    // labelled already, beside the hierarchy's set-up).
    let ((piece_of_node, pieces), bilateral_parts) = rayon::join(
        || pieces_of_graph.unwrap_or_else(|| topology.components()),
        || {
            bilateral.then(|| {
                let cut = auto_cut.clone().unwrap_or_else(|| {
                    bilateral::discontinuities(
                        &topology,
                        &x,
                        &slopes,
                        stiffness,
                        DISCONTINUITY_WEIGHT,
                    )
                });
                let min_part = MIN_PART_PIXELS.max(topology.len() / 100);
                absorb_small_parts(&topology, topology.components_without(&cut), min_part)
            })
        },
    );
    let mut depth = Array2::from_elem(region.dim(), f64::NAN);
    if config.integrator == Integrator::FastMarching {
        let gradients = SurfaceGradients {
            dzdx: Array2::from_shape_fn(region.dim(), |p| {
                topology.node(p).map_or(0.0, |k| slopes[k].0)
            }),
            dzdy: Array2::from_shape_fn(region.dim(), |p| {
                topology.node(p).map_or(0.0, |k| slopes[k].1)
            }),
            mask: Array2::from_shape_fn(region.dim(), |p| topology.node(p).is_some()),
        };
        let (fm, accepted) = fast_marching::integrate(&gradients, step, config.lambda)?;
        depth = fm;
        iterations = accepted;
        passes = 1;
    } else {
        for (k, &p) in topology.cells.iter().enumerate() {
            depth[p] = x[k];
        }
    }
    anchor(&mut depth, &topology, &piece_of_node, pieces, config.anchor);
    profile.add("pieces and anchoring", t);
    let t = Instant::now();
    let (part_of_node, parts) = bilateral_parts.unwrap_or_else(|| (piece_of_node.clone(), pieces));
    let depth_mm = depth.mapv(|u| {
        if u.is_finite() {
            grid.depth_mm(u)
        } else {
            f64::NAN
        }
    });
    let valid = depth_mm.mapv(f64::is_finite);
    let (kept, kept_fraction) = filter_artefacts(&depth_mm, &valid, &config.filter);
    profile.add("artefact filter", t);
    let t = Instant::now();
    let mut out = Integration {
        depth: DepthMap {
            depth_mm: Array2::from_elem(shape, f32::NAN),
            pitch_mm: match grid {
                DepthGrid::Orthographic { pitch_mm } => *pitch_mm,
                DepthGrid::Perspective { .. } => f64::NAN,
            },
            perspective: match grid {
                DepthGrid::Orthographic { .. } => None,
                DepthGrid::Perspective {
                    intrinsics,
                    distance_mm,
                } => Some(Projection::Perspective {
                    intrinsics: *intrinsics,
                    distance_mm: *distance_mm,
                }),
            },
        },
        kept: Array2::from_elem(shape, false),
        kept_fraction,
        iterations,
        passes,
        pieces,
        piece: Array2::from_elem(shape, u32::MAX),
        parts,
        part: Array2::from_elem(shape, u32::MAX),
        confidence: Array2::from_elem(shape, Confidence::None),
        completed_normals: Array3::from_elem((shape.0, shape.1, 3), f32::NAN),
        discontinuity_edges: auto_cut
            .as_ref()
            .map(|cut| cut.iter().flatten().filter(|&&c| c).count()),
        bilateral_pixels: auto_cut.as_ref().map(|_| auto_near),
    };
    if let DepthGrid::Perspective {
        distance_mm,
        intrinsics,
    } = grid
    {
        out.depth.pitch_mm = distance_mm / intrinsics.fx;
    }
    place_nodes(
        &mut out,
        &NodeResults {
            topology: &topology,
            window,
            grid,
            class: &problem.class,
            kept: &kept,
            depth_mm: &depth_mm,
            slopes: &slopes,
            piece: &piece_of_node,
            part: &part_of_node,
        },
    );
    profile.add("output", t);
    workspace.cached = Some(workspace::CachedSystem {
        origin: problem.origin,
        region,
        topology,
        laplacian,
        hierarchy,
    });
    Ok(out)
}

/// Rows of the output per parallel task.
const ROWS_PER_TASK: usize = 8;

/// What a window's solve found at its nodes, for [`place_nodes`].
struct NodeResults<'a> {
    topology: &'a Topology,
    window: &'a Window,
    grid: &'a DepthGrid,
    /// Each window pixel's class.
    class: &'a Array2<Confidence>,
    /// Window pixels the artefact filter kept.
    kept: &'a Array2<bool>,
    /// Depth of each window pixel (mm).
    depth_mm: &'a Array2<f64>,
    /// Slopes, piece and part of each node.
    slopes: &'a [(f64, f64)],
    piece: &'a [u32],
    part: &'a [u32],
}

/// Writes the kept nodes' depth, piece, part, class and (where not measured) completed normal
/// into `out`'s full-grid arrays (fresh, row-major), one output row per task: a window row's
/// nodes are a run of the raster-ordered nodes.
fn place_nodes(out: &mut Integration, nodes: &NodeResults) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A 12×15 region (its first column outside) whose measured pixels surround a block of
    /// two-LED pixels and a hole.
    fn problem() -> Problem {
        let shape = (12, 15);
        let class = Array2::from_shape_fn(shape, |(r, c)| match (r, c) {
            (_, 0) => Confidence::None,
            (3..6, 4..9) => Confidence::TwoLeds,
            (8..10, 10..13) => Confidence::Filled,
            _ => Confidence::Measured,
        });
        let measured = |p: (usize, usize)| class[p] == Confidence::Measured;
        let slopes = Array2::from_shape_fn(shape, |(r, c)| {
            if measured((r, c)) {
                (0.1 * r as f64 - 0.02 * c as f64, (0.3 * c as f64).sin())
            } else {
                (f64::NAN, f64::NAN)
            }
        });
        let albedo = Array2::from_shape_fn(shape, |(r, c)| {
            if measured((r, c)) {
                0.5 + 0.01 * (r * c) as f64
            } else {
                f64::NAN
            }
        });
        let planes = class
            .indexed_iter()
            .filter(|(_, k)| **k == Confidence::TwoLeds)
            .map(|(pixel, _)| NormalPlane {
                pixel,
                across: Vector3::x(),
                towards: Vector3::z(),
                least_albedo: Vector3::zeros(),
            })
            .collect();
        Problem {
            class,
            slopes,
            planes,
            albedo,
            origin: (0, 0),
            grid: DepthGrid::Orthographic { pitch_mm: 1.0 },
        }
    }

    /// Slopes and albedo filled in together (albedo known wherever slopes are) or apart (a
    /// measured pixel without an albedo) equal the separate fills bit for bit, and fill
    /// every region pixel.
    #[test]
    fn slopes_and_albedo_fill_in_together_or_apart_as_on_their_own() {
        for albedo_missing_at in [None, Some((1, 1)), Some((7, 3))] {
            let mut problem = problem();
            if let Some(p) = albedo_missing_at {
                problem.albedo[p] = f64::NAN;
            }
            let region = problem.class.mapv(|k| k != Confidence::None);
            let topology = Topology::new(&region);
            let (slopes, albedo) = filled_in(&problem, &region, &topology);
            let known = problem.class.mapv(|k| k == Confidence::Measured);
            let mut alone = problem.slopes.clone();
            Inpainting::new(&known, &region).fill(&mut alone);
            let albedo_known = Zip::from(&known)
                .and(&problem.albedo)
                .map_collect(|&k, &a| k && a.is_finite());
            let mut albedo_alone = problem.albedo.clone();
            inpaint(&mut albedo_alone, &albedo_known, &region);
            let bits = |a: &Array2<f64>| a.mapv(f64::to_bits);
            assert_eq!(bits(&slopes.mapv(|s| s.0)), bits(&alone.mapv(|s| s.0)));
            assert_eq!(bits(&slopes.mapv(|s| s.1)), bits(&alone.mapv(|s| s.1)));
            assert_eq!(bits(&albedo), bits(&albedo_alone));
            for (p, &inside) in region.indexed_iter() {
                if inside {
                    assert!(slopes[p].0.is_finite() && slopes[p].1.is_finite(), "{p:?}");
                    assert!(albedo[p].is_finite(), "{p:?} {albedo_missing_at:?}");
                }
            }
        }
    }
}
