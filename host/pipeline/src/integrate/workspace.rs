//! State kept between integrations of similar problems, and where one integration's time went.
//!
//! A video reconstructs window after window of the same object, and each window runs several
//! photometric-stereo ↔ integration passes, so consecutive least-squares solves often share
//! their mask. [`IntegrationWorkspace`] keeps the last solve's integration graph;
//! [`super::integrate_surface_with`] reuses it when the next problem has the same mask on the
//! same window, with its multigrid aggregation (levels, node maps, components). The coarse
//! operators themselves are recomputed for every solve (\[`Multigrid::reweight`\]): the two-LED
//! pixels' edge weights follow their slopes, and operators built for the first coverage pass
//! doubled the conjugate-gradient iterations of the later ones on the turning ellipsoid (75
//! instead of 36). The graph's Laplacian is kept too and takes each solve's edge weights in
//! place, and the conjugate-gradient vectors are allocated once per workspace.

use super::least_squares::Topology;
use super::multigrid::{GridLaplacian, Multigrid};
use super::pcg::CgVectors;
use meb_core::timing::StageTiming;
use ndarray::Array2;
use std::time::Instant;

/// Where one integration's wall-clock time went.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IntegrationProfile {
    /// Milliseconds per step (summed over the coverage passes), in the order first reached.
    pub steps: Vec<StageTiming>,
    /// Conjugate-gradient iterations of each solve.
    pub solve_iterations: Vec<usize>,
    /// Whether the integration graph came from the workspace.
    pub reused_graph: bool,
}

impl IntegrationProfile {
    /// Adds the time since `start` to `step`.
    pub(crate) fn add(&mut self, step: &str, start: Instant) {
        let ms = start.elapsed().as_secs_f64() * 1e3;
        match self.steps.iter_mut().find(|s| s.stage == step) {
            Some(s) => s.ms += ms,
            None => self.steps.push(StageTiming {
                stage: step.to_string(),
                ms,
            }),
        }
    }

    /// Milliseconds of `step` (0 when it did not run).
    pub fn ms(&self, step: &str) -> f64 {
        self.steps
            .iter()
            .find(|s| s.stage == step)
            .map_or(0.0, |s| s.ms)
    }

    /// Total milliseconds over all steps.
    pub fn total_ms(&self) -> f64 {
        self.steps.iter().map(|s| s.ms).sum()
    }
}

/// The integration graph of one least-squares problem.
pub(crate) struct CachedSystem {
    /// Window origin in the grid (row, column).
    pub origin: (usize, usize),
    /// The integrated pixels of the window.
    pub region: Array2<bool>,
    /// Their graph.
    pub topology: Topology,
    /// The Laplacian of that graph, with the last solve's edge weights.
    pub laplacian: Option<GridLaplacian>,
    /// The multigrid aggregation on that graph, with the last solve's coarse operators.
    pub hierarchy: Option<Multigrid>,
}

/// What [`super::integrate_surface_with`] keeps between calls (module docs). Create one per
/// sequence of related problems (a video, one reconstruction's passes) and pass it to every
/// call; a fresh one gives exactly [`super::integrate_surface`].
#[derive(Default)]
pub struct IntegrationWorkspace {
    pub(crate) cached: Option<CachedSystem>,
    pub(crate) profile: IntegrationProfile,
    /// Scratch vectors of the conjugate-gradient solves.
    pub(crate) cg: CgVectors,
}

impl std::fmt::Debug for IntegrationWorkspace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("IntegrationWorkspace")
            .field(
                "cached_nodes",
                &self.cached.as_ref().map(|c| c.topology.len()),
            )
            .field("profile", &self.profile)
            .finish()
    }
}

impl IntegrationWorkspace {
    /// An empty workspace.
    pub fn new() -> Self {
        Self::default()
    }

    /// Where the last integration's time went.
    pub fn profile(&self) -> &IntegrationProfile {
        &self.profile
    }

    /// Forgets the cached graph (the next call builds them afresh).
    pub fn clear(&mut self) {
        self.cached = None;
    }
}
