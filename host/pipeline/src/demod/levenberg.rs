//! A small Levenberg–Marquardt least-squares solver (Marquardt, SIAM J. Appl. Math. 1963) with
//! forward-difference Jacobians, parameters that can be held fixed and box bounds.
//!
//! The timing fit has at most eleven parameters and a residual whose Jacobian is cheapest by
//! finite differences (each column is one template rebuild); the `levenberg-marquardt` crate
//! targets another nalgebra major version and has no bounds, so this is written out here.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Largest number of iterations.
const MAX_ITERATIONS: usize = 40;
/// Forward-difference step of the Jacobian.
const DIFFERENCE_STEP: f64 = 1e-6;
/// Initial damping.
const INITIAL_DAMPING: f64 = 1e-3;
/// Damping increases tried per iteration before giving up.
const MAX_DAMPING_STEPS: usize = 12;
/// Relative cost decrease below which an accepted step ends the search.
const MIN_RELATIVE_DECREASE: f64 = 1e-12;

/// A least-squares problem: residuals of a parameter vector (evaluated from several threads
/// at once: the Jacobian's columns are independent).
pub trait Residuals: Sync {
    /// Writes the residual vector of `params` into `out` (resized as needed).
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>);
}

/// Which parameters move and within which bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct Freedom {
    /// `free[k]`: parameter k is fitted.
    pub free: Vec<bool>,
    /// Lower and upper bound of each parameter.
    pub bounds: Vec<(f64, f64)>,
}

/// The solution.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The parameters.
    pub params: Vec<f64>,
    /// Sum of squared residuals.
    pub cost: f64,
    /// JᵀJ over the free parameters at the solution (Gauss–Newton information matrix).
    pub information: DMatrix<f64>,
    /// Indices of the free parameters (rows and columns of `information`).
    pub free: Vec<usize>,
}

/// Minimises the sum of squared residuals from `start`.
pub fn minimise(problem: &impl Residuals, start: &[f64], freedom: &Freedom) -> Solution {
    minimise_within(problem, start, freedom, MAX_ITERATIONS)
}

/// [`minimise`] with at most `iterations` accepted steps.
pub fn minimise_within(
    problem: &impl Residuals,
    start: &[f64],
    freedom: &Freedom,
    iterations: usize,
) -> Solution {
    let free: Vec<usize> = (0..start.len())
        .filter(|&k| freedom.free.get(k).copied().unwrap_or(false))
        .collect();
    let clamp = |params: &mut [f64]| {
        for (p, (lo, hi)) in params.iter_mut().zip(&freedom.bounds) {
            *p = p.clamp(*lo, *hi);
        }
    };
    let mut params = start.to_vec();
    clamp(&mut params);
    let mut residual = Vec::new();
    problem.residuals(&params, &mut residual);
    let mut cost = sum_of_squares(&residual);
    let mut jacobian = jacobian(problem, &params, &residual, &free);
    let mut damping = INITIAL_DAMPING;
    let mut trial = Vec::new();
    for _ in 0..iterations {
        if free.is_empty() {
            break;
        }
        let information = jacobian.tr_mul(&jacobian);
        let gradient = jacobian.tr_mul(&DVector::from_column_slice(&residual));
        let mut accepted = false;
        let mut converged = false;
        for _ in 0..MAX_DAMPING_STEPS {
            let mut damped = information.clone();
            for k in 0..free.len() {
                damped[(k, k)] += damping * information[(k, k)] + 1e-12;
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&(-&gradient))) else {
                damping *= 10.0;
                continue;
            };
            let mut candidate = params.clone();
            for (a, &k) in free.iter().enumerate() {
                candidate[k] += step[a];
            }
            clamp(&mut candidate);
            problem.residuals(&candidate, &mut trial);
            let trial_cost = sum_of_squares(&trial);
            if trial_cost < cost {
                converged = cost - trial_cost <= MIN_RELATIVE_DECREASE * cost;
                params = candidate;
                std::mem::swap(&mut residual, &mut trial);
                cost = trial_cost;
                damping = (damping / 3.0).max(1e-12);
                accepted = true;
                break;
            }
            damping *= 10.0;
        }
        if !accepted {
            break;
        }
        jacobian = self::jacobian(problem, &params, &residual, &free);
        if converged {
            break;
        }
    }
    Solution {
        information: jacobian.tr_mul(&jacobian),
        params,
        cost,
        free,
    }
}

/// Forward-difference Jacobian over the free parameters, its columns (one residual
/// evaluation each) in parallel.
fn jacobian(
    problem: &impl Residuals,
    params: &[f64],
    residual: &[f64],
    free: &[usize],
) -> DMatrix<f64> {
    let columns: Vec<Vec<f64>> = free
        .par_iter()
        .map(|&k| {
            let mut shifted = params.to_vec();
            shifted[k] = params[k] + DIFFERENCE_STEP;
            let mut out = Vec::new();
            problem.residuals(&shifted, &mut out);
            out.iter()
                .zip(residual)
                .map(|(x, r)| (x - r) / DIFFERENCE_STEP)
                .collect()
        })
        .collect();
    let mut jacobian = DMatrix::zeros(residual.len(), free.len());
    for (mut target, column) in jacobian.column_iter_mut().zip(&columns) {
        for (t, &v) in target.iter_mut().zip(column) {
            *t = v;
        }
    }
    jacobian
}

/// Σ r².
fn sum_of_squares(values: &[f64]) -> f64 {
    values.iter().map(|r| r * r).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fit y = a·exp(−b·x) to exact data.
    struct Decay {
        x: Vec<f64>,
        y: Vec<f64>,
    }

    impl Residuals for Decay {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) {
            out.clear();
            out.extend(
                self.x
                    .iter()
                    .zip(&self.y)
                    .map(|(x, y)| p[0] * (-p[1] * x).exp() - y),
            );
        }
    }

    #[test]
    fn fits_an_exponential_and_respects_fixed_parameters_and_bounds() {
        let x: Vec<f64> = (0..20).map(|k| k as f64 * 0.25).collect();
        let y = x.iter().map(|x| 2.5 * (-0.7 * x).exp()).collect();
        let problem = Decay { x, y };
        let free = Freedom {
            free: vec![true, true],
            bounds: vec![(0.0, 10.0), (0.0, 10.0)],
        };
        let solution = minimise(&problem, &[1.0, 0.2], &free);
        assert!((solution.params[0] - 2.5).abs() < 1e-6, "{solution:?}");
        assert!((solution.params[1] - 0.7).abs() < 1e-6, "{solution:?}");
        assert_eq!(solution.information.nrows(), 2);
        let fixed = Freedom {
            free: vec![true, false],
            bounds: vec![(0.0, 2.0), (0.0, 10.0)],
        };
        let solution = minimise(&problem, &[1.0, 0.7], &fixed);
        assert_eq!(solution.params[1], 0.7);
        assert!(
            solution.params[0] <= 2.0 && solution.params[0] > 1.9,
            "{solution:?}"
        );
    }
}
