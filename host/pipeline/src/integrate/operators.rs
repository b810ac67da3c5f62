//! The operators of a window's least-squares solves: the graph Laplacian, which takes each
//! solve's edge weights in place, and its multigrid hierarchy, whose aggregation depends on
//! the graph alone and whose coarse operators are recomputed for every solve
//! ([`super::workspace`] says why).

use super::IntegrationProfile;
use super::least_squares::{self, EdgeEquations, Topology};
use super::multigrid::{GridLaplacian, Multigrid};
use super::pcg::{CgVectors, Stop, preconditioned_cg};
use std::time::Instant;

/// Each node's piece (connected component of the graph) and the piece count.
pub(super) type Pieces = (Vec<u32>, usize);

/// The Laplacian and hierarchy of one graph (either built on first use).
pub(super) struct Operators {
    /// The graph Laplacian with the last solve's weights.
    pub laplacian: Option<GridLaplacian>,
    /// Its multigrid hierarchy.
    pub hierarchy: Option<Multigrid>,
    /// The graph's pieces, once labelled.
    pub pieces: Option<Pieces>,
}

/// How one solve stops.
#[derive(Debug, Clone, Copy)]
pub(super) struct SolveLimits {
    /// Relative residual norm to reach.
    pub tolerance: f64,
    /// Most conjugate-gradient iterations.
    pub max_iterations: usize,
}

impl Operators {
    /// Solves the weighted least-squares system of `equations` on `topology` into `x` (the
    /// start), by conjugate gradients preconditioned with the hierarchy; returns the
    /// iterations. A fresh hierarchy's set-up (mostly serial) runs beside the labelling of the
    /// graph's pieces when they are not labelled yet.
    pub fn solve(
        &mut self,
        topology: &Topology,
        equations: &EdgeEquations,
        x: &mut [f64],
        limits: SolveLimits,
        cg: &mut CgVectors,
        profile: &mut IntegrationProfile,
    ) -> usize {
        let t = Instant::now();
        let lap: &GridLaplacian = match self.laplacian.as_mut() {
            Some(l) => {
                topology.reweight_laplacian(l, &equations.weight);
                l
            }
            None => self.laplacian.insert(topology.laplacian(&equations.weight)),
        };
        let b = equations.right_hand_side(topology);
        profile.add("edge equations", t);
        let t = Instant::now();
        let multigrid = match self.hierarchy.as_mut() {
            Some(m) => {
                m.reweight(lap, least_squares::REGULARISATION);
                m
            }
            None if self.pieces.is_none() => {
                let (m, labelled) = rayon::join(
                    || Multigrid::new(lap, least_squares::REGULARISATION),
                    || topology.components(),
                );
                self.pieces = Some(labelled);
                self.hierarchy.insert(m)
            }
            None => self
                .hierarchy
                .insert(Multigrid::new(lap, least_squares::REGULARISATION)),
        };
        profile.add("hierarchy setup", t);
        let t = Instant::now();
        let solved = preconditioned_cg(
            |u, v| lap.apply(u, v),
            |r, z| multigrid.precondition(lap, r, z),
            &b,
            x,
            Stop::ResidualNorm(limits.tolerance),
            limits.max_iterations,
            cg,
        );
        profile.add("conjugate gradients", t);
        profile.solve_iterations.push(solved);
        solved
    }
}
