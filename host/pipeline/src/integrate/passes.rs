//! The solves of one window problem: the reweighting passes (two-LED alternation, bilateral
//! weights) and the automatic integrator's last solve with the discontinuities it found cut.

use super::bilateral::{self, SideWeights, Stiffness};
use super::coverage::TwoLedPixels;
use super::least_squares::Topology;
use super::operators::{Operators, SolveLimits};
use super::pcg::CgVectors;
use super::{IntegrateConfig, IntegrationProfile, Integrator};
use std::time::Instant;

/// Solve tolerance of a reweighting pass relative to the last pass's relative energy change.
const INEXACT_SOLVE: f64 = 1e-2;

/// Loosest relative residual of a reweighting pass's solve.
const LOOSEST_SOLVE: f64 = 1e-4;

/// A bilateral weight below which both sides of an edge have turned away from it.
pub(super) const DISCONTINUITY_WEIGHT: f64 = 0.05;

/// What stays fixed over a window's solves.
pub(super) struct WindowSystem<'a> {
    /// The integration graph.
    pub topology: &'a Topology,
    /// Grid step of the unknown.
    pub step: f64,
    /// Each node's confidence weight.
    pub confidence: Vec<f64>,
    /// Nodes without a measured normal (their slopes are estimated).
    pub estimated: Vec<bool>,
    /// Steepness of the bilateral weights.
    pub stiffness: Stiffness,
    /// The two-LED pixels.
    pub two_led: TwoLedPixels<'a>,
    /// The integrator's settings.
    pub config: &'a IntegrateConfig,
}

/// What the solves update.
pub(super) struct SolveState<'w> {
    /// The unknown at every node.
    pub x: Vec<f64>,
    /// Each node's slopes (s_x, s_y).
    pub slopes: Vec<(f64, f64)>,
    /// The Laplacian and its hierarchy.
    pub operators: Operators,
    /// Conjugate-gradient iterations so far.
    pub iterations: usize,
    /// Solves so far.
    pub passes: usize,
    /// The conjugate-gradient vectors.
    pub cg: &'w mut CgVectors,
    /// Where the time went.
    pub profile: &'w mut IntegrationProfile,
}

/// The automatic integrator's discontinuities: the cut edges and how many pixels near them
/// kept their bilateral weights.
pub(super) struct CutEdges {
    /// Each node's right and down edge, cut or not.
    pub cut: Vec<[bool; 2]>,
    /// Pixels near a discontinuity that kept their bilateral weights.
    pub near: usize,
}

impl WindowSystem<'_> {
    /// Whether the passes reweight bilaterally (the bilateral and automatic integrators).
    pub fn bilateral(&self) -> bool {
        matches!(
            self.config.integrator,
            Integrator::Bilateral | Integrator::Auto
        )
    }

    /// Solves once with `sides`' weights from the present `x`.
    fn solve(&self, state: &mut SolveState, sides: &[SideWeights], tolerance: f64) {
        let t = Instant::now();
        let equations = bilateral::side_equations(self.topology, sides, &state.slopes, self.step);
        state.profile.add("edge equations", t);
        let solved = state.operators.solve(
            self.topology,
            &equations,
            &mut state.x,
            SolveLimits {
                tolerance,
                max_iterations: self.config.max_iterations,
            },
            state.cg,
            state.profile,
        );
        state.iterations += solved;
        state.passes += 1;
    }

    /// From a warm start the depth has settled already (the previous pass's or window's): the
    /// two-LED pixels take their slopes, and the albedo's side, from it before the first solve
    /// instead of alternating from the filled-in slopes (typically 2–3 solves instead of 6–8).
    fn slopes_from_warm_depth(&self, state: &mut SolveState) {
        let t = Instant::now();
        let sides = bilateral::uniform(&self.confidence, &state.slopes, &self.estimated);
        self.two_led.follow_depth(
            &mut state.slopes,
            self.topology,
            &state.x,
            &sides,
            self.step,
            true,
        );
        state.profile.add("coverage", t);
    }

    /// The reweighting passes: each solves with the present weights, moves the two-LED pixels'
    /// slopes to fit the depth, and stops once the energy settles. Two-LED pixels take the
    /// interpolated albedo's side once the alternation without it has settled (or used half
    /// its passes): a flat face fits either mirror image, so a side picked from the slopes
    /// filled in from other faces would stay.
    pub fn reweighting_passes(&self, state: &mut SolveState, warm: bool) {
        let config = self.config;
        let bilateral = self.bilateral();
        let passes_allowed = match config.integrator {
            Integrator::Bilateral | Integrator::Auto => config.bilateral.max_iterations,
            _ if self.two_led.is_empty() => 1,
            _ => config.coverage.iterations,
        };
        let tolerance = if bilateral {
            config.bilateral.tolerance
        } else {
            config.coverage.tolerance
        };
        let mut use_albedo = false;
        if warm && !bilateral && !self.two_led.is_empty() {
            self.slopes_from_warm_depth(state);
            use_albedo = true;
        }
        let mut previous_energy: Option<f64> = None;
        // Reweighting passes need solves only as exact as the weights are settled (inexact
        // IRLS).
        let mut solve_tolerance = config.tolerance;
        for pass in 0..passes_allowed {
            let t = Instant::now();
            let sides = if bilateral && (pass > 0 || warm) {
                bilateral::bilateral(
                    self.topology,
                    &state.x,
                    &state.slopes,
                    &self.confidence,
                    self.stiffness,
                )
            } else {
                bilateral::uniform(&self.confidence, &state.slopes, &self.estimated)
            };
            state.profile.add("edge equations", t);
            self.solve(state, &sides, solve_tolerance);
            let t = Instant::now();
            self.two_led.follow_depth(
                &mut state.slopes,
                self.topology,
                &state.x,
                &sides,
                self.step,
                use_albedo,
            );
            if passes_allowed == 1 {
                break;
            }
            let e = bilateral::energy(self.topology, &sides, &state.slopes, self.step, &state.x);
            state.profile.add("coverage", t);
            let relative = previous_energy.map(|p| (p - e).abs() / p.max(f64::MIN_POSITIVE));
            previous_energy = Some(e);
            if let Some(r) = relative {
                solve_tolerance = (r * INEXACT_SOLVE).clamp(config.tolerance, LOOSEST_SOLVE);
            }
            let settled = relative.is_some_and(|r| r < tolerance);
            if !use_albedo && (settled || 2 * state.passes >= passes_allowed) {
                use_albedo = true;
                previous_energy = None;
                self.two_led.take_albedo_side(&mut state.slopes);
                continue;
            }
            if settled {
                break;
            }
        }
    }

    /// The automatic integrator's last solve: least squares with the edges the bilateral
    /// weights found to be discontinuities cut, and bilateral weights kept near them.
    pub fn cut_solve(&self, state: &mut SolveState) -> CutEdges {
        let t = Instant::now();
        let (topology, x, slopes) = (self.topology, &state.x, &state.slopes);
        let decision = &self.config.auto;
        let mut cut =
            bilateral::discontinuities(topology, x, slopes, self.stiffness, DISCONTINUITY_WEIGHT);
        bilateral::decisive_cuts(topology, x, slopes, self.stiffness, decision, &mut cut);
        bilateral::drop_short_cuts(topology, &mut cut, decision.min_cut_chain);
        let near = bilateral::near_discontinuities(topology, x, slopes, self.stiffness, decision);
        let weighted = bilateral::bilateral(topology, x, slopes, &self.confidence, self.stiffness);
        let mut sides = bilateral::uniform(&self.confidence, slopes, &self.estimated);
        for ((side, w), &n) in sides.iter_mut().zip(weighted).zip(&near) {
            if n {
                *side = w;
            }
        }
        bilateral::cut_sides(topology, &cut, &mut sides);
        state.profile.add("discontinuities", t);
        self.solve(state, &sides, self.config.tolerance);
        CutEdges {
            cut,
            near: near.iter().filter(|&&n| n).count(),
        }
    }
}
