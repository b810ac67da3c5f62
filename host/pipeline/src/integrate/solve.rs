//! The least-squares solve of one window problem: slopes of two-LED pixels and holes filled in
//! ([`super::inpaint`]), the reweighting passes and the automatic integrator's cut solve
//! ([`super::passes`]), then pieces, anchoring, the artefact filter and the full-grid output
//! ([`super::output`]).

use super::coverage::TwoLedPixels;
use super::grid::DepthGrid;
use super::inpaint::{Inpainting, inpaint};
use super::least_squares::Topology;
use super::operators::Operators;
use super::output::{Counts, NodeResults, empty_integration, place_nodes};
use super::parts::{absorb_small_parts, anchor};
use super::passes::{DISCONTINUITY_WEIGHT, SolveState, WindowSystem};
use super::warm::warm_start;
use super::window::Window;
use super::{
    Confidence, IntegrateConfig, IntegrateError, Integration, IntegrationWorkspace, Integrator,
    NormalPlane, SurfaceGradients, bilateral, fast_marching, filter_artefacts, workspace,
};
use ndarray::{Array2, Zip};
use std::time::Instant;

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
    let IntegrationWorkspace {
        cached: cache,
        cg,
        profile,
    } = workspace;
    let t = Instant::now();
    let region = problem.class.mapv(|k| k != Confidence::None);
    // The graph (and hierarchy) of the last call when the mask is the same.
    let cached = cache
        .take()
        .filter(|c| c.origin == problem.origin && c.region == region);
    profile.reused_graph = cached.is_some();
    let (topology, laplacian, hierarchy) = match cached {
        Some(c) => (c.topology, c.laplacian, c.hierarchy),
        None => (Topology::new(&region), None, None),
    };
    profile.add("graph", t);
    if topology.len() == 0 {
        return Err(IntegrateError::EmptyMask);
    }
    let t = Instant::now();
    let grid = &problem.grid;
    let (filled_slopes, albedo) = filled_in(problem, &region, &topology);
    profile.add("inpainting", t);
    let t = Instant::now();
    let system = window_system(problem, &topology, &albedo, config);
    let mut slopes: Vec<(f64, f64)> = topology.cells.iter().map(|&p| filled_slopes[p]).collect();
    system.two_led.onto_circles(&mut slopes);
    profile.add("set-up", t);
    let t = Instant::now();
    let warm = initial
        .filter(|d| d.dim() == shape)
        .and_then(|d| warm_start(d, &topology, grid, problem.origin));
    let is_warm = warm.is_some();
    let x = warm.unwrap_or_else(|| vec![0.0; topology.len()]);
    profile.add("warm start", t);
    let mut state = SolveState {
        x,
        slopes,
        operators: Operators {
            laplacian,
            hierarchy,
            pieces: None,
        },
        iterations: 0,
        passes: 0,
        cg,
        profile,
    };
    system.reweighting_passes(&mut state, is_warm);
    // The automatic integrator reweights as the bilateral one does, then solves least squares
    // with the discontinuities it found cut.
    let auto = (config.integrator == Integrator::Auto).then(|| system.cut_solve(&mut state));
    let t = Instant::now();
    // Pieces, and parts: pieces further split where the bilateral integrator found a depth
    // discontinuity all the way across (their relative depth is unknown to the normals). The
    // two labellings are independent and run side by side (the pieces of a fresh graph were
    // labelled already, beside the hierarchy's set-up).
    let labelled = state.operators.pieces.take();
    let ((piece_of_node, pieces), bilateral_parts) = rayon::join(
        || labelled.unwrap_or_else(|| topology.components()),
        || {
            system.bilateral().then(|| {
                let cut = auto.as_ref().map_or_else(
                    || {
                        bilateral::discontinuities(
                            &topology,
                            &state.x,
                            &state.slopes,
                            system.stiffness,
                            DISCONTINUITY_WEIGHT,
                        )
                    },
                    |a| a.cut.clone(),
                );
                let min_part = MIN_PART_PIXELS.max(topology.len() / 100);
                absorb_small_parts(&topology, topology.components_without(&cut), min_part)
            })
        },
    );
    let mut depth = Array2::from_elem(region.dim(), f64::NAN);
    if config.integrator == Integrator::FastMarching {
        let (fm, accepted) =
            fast_marching_depth(&topology, &state.slopes, region.dim(), system.step, config)?;
        depth = fm;
        state.iterations = accepted;
        state.passes = 1;
    } else {
        for (k, &p) in topology.cells.iter().enumerate() {
            depth[p] = state.x[k];
        }
    }
    anchor(&mut depth, &topology, &piece_of_node, pieces, config.anchor);
    state.profile.add("pieces and anchoring", t);
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
    state.profile.add("artefact filter", t);
    let t = Instant::now();
    let counts = Counts {
        kept_fraction,
        iterations: state.iterations,
        passes: state.passes,
        pieces,
        parts,
        auto: auto
            .as_ref()
            .map(|a| (a.cut.iter().flatten().filter(|&&c| c).count(), a.near)),
    };
    let mut out = empty_integration(shape, grid, counts);
    place_nodes(
        &mut out,
        &NodeResults {
            topology: &topology,
            window,
            grid,
            class: &problem.class,
            kept: &kept,
            depth_mm: &depth_mm,
            slopes: &state.slopes,
            piece: &piece_of_node,
            part: &part_of_node,
        },
    );
    state.profile.add("output", t);
    let Operators {
        laplacian,
        hierarchy,
        ..
    } = state.operators;
    *cache = Some(workspace::CachedSystem {
        origin: problem.origin,
        region,
        topology,
        laplacian,
        hierarchy,
    });
    Ok(out)
}

/// What stays fixed over the solves of `problem` on `topology`: node weights, the bilateral
/// stiffness and the two-LED pixels.
fn window_system<'a>(
    problem: &'a Problem,
    topology: &'a Topology,
    albedo: &'a Array2<f64>,
    config: &'a IntegrateConfig,
) -> WindowSystem<'a> {
    let grid = &problem.grid;
    let confidence = topology
        .cells
        .iter()
        .map(|&p| match problem.class[p] {
            Confidence::Measured => 1.0,
            Confidence::TwoLeds => config.coverage.two_led_weight,
            _ => config.coverage.fill_weight,
        })
        .collect();
    let estimated = topology
        .cells
        .iter()
        .map(|&p| problem.class[p] != Confidence::Measured)
        .collect();
    WindowSystem {
        topology,
        step: grid.step(),
        confidence,
        estimated,
        stiffness: bilateral::Stiffness {
            units: grid.pixel_units(),
            k: config.bilateral.stiffness,
        },
        two_led: TwoLedPixels::new(
            &problem.planes,
            topology,
            grid,
            problem.origin,
            config.max_slope,
            albedo,
        ),
        config,
    }
}

/// Fast Marching over the nodes' slopes: the depth of every node and the pixels accepted.
fn fast_marching_depth(
    topology: &Topology,
    slopes: &[(f64, f64)],
    dim: (usize, usize),
    step: f64,
    config: &IntegrateConfig,
) -> Result<(Array2<f64>, usize), IntegrateError> {
    let gradients = SurfaceGradients {
        dzdx: Array2::from_shape_fn(dim, |p| topology.node(p).map_or(0.0, |k| slopes[k].0)),
        dzdy: Array2::from_shape_fn(dim, |p| topology.node(p).map_or(0.0, |k| slopes[k].1)),
        mask: Array2::from_shape_fn(dim, |p| topology.node(p).is_some()),
    };
    fast_marching::integrate(&gradients, step, config.lambda)
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
