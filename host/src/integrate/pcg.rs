//! Preconditioned conjugate gradients for the symmetric positive (semi-)definite systems of
//! normal integration and position–normal fusion (Hestenes & Stiefel, "Methods of conjugate
//! gradients for solving linear systems", 1952; Saad, "Iterative methods for sparse linear
//! systems", 2nd ed. 2003, Algorithm 9.1). The operator, the preconditioner and the stopping
//! rule are parameters, so the masked Poisson solve ([`super::least_squares`]) and the Nehab
//! fusion ([`super::fusion`]) share one loop.

/// When conjugate gradients stops (checked before every iteration, including the first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Stop {
    /// ‖r‖₂ ≤ tolerance · ‖b‖₂.
    ResidualNorm(f64),
    /// rᵀM⁻¹r ≤ tolerance² · bᵀM⁻¹b (the preconditioned residual in the energy of M⁻¹; costs
    /// one extra preconditioner application for bᵀM⁻¹b).
    PreconditionedResidual(f64),
}

/// Solves A x = b from the given `x` (warm start) with the operator `apply` (y = A x) and
/// the preconditioner `precondition` (z = M⁻¹ r); returns the iterations run (`max_iterations`
/// when the stopping rule was not met). Stops early, without a step, when the curvature pᵀAp is
/// not positive (A singular along p: the system is solved as far as it can be).
pub(crate) fn preconditioned_cg(
    apply: impl Fn(&[f64], &mut [f64]),
    mut precondition: impl FnMut(&[f64], &mut [f64]),
    b: &[f64],
    x: &mut [f64],
    stop: Stop,
    max_iterations: usize,
) -> usize {
    let n = b.len();
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(p, q)| p * q).sum::<f64>();
    let mut z = vec![0.0; n];
    let threshold = match stop {
        Stop::ResidualNorm(t) => t * dot(b, b).sqrt().max(f64::MIN_POSITIVE),
        Stop::PreconditionedResidual(t) => {
            precondition(b, &mut z);
            t * t * dot(b, &z).max(f64::MIN_POSITIVE)
        }
    };
    let mut r = vec![0.0; n];
    apply(x, &mut r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    for iteration in 0..max_iterations {
        let converged = match stop {
            Stop::ResidualNorm(_) => dot(&r, &r).sqrt() <= threshold,
            Stop::PreconditionedResidual(_) => rz <= threshold,
        };
        if converged {
            return iteration;
        }
        apply(&p, &mut ap);
        let curvature = dot(&p, &ap);
        if curvature.is_nan() || curvature <= 0.0 {
            return iteration;
        }
        let alpha = rz / curvature;
        for k in 0..n {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        precondition(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        p.iter_mut()
            .zip(&z)
            .for_each(|(pk, zk)| *pk = zk + beta * *pk);
    }
    max_iterations
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 1-D Dirichlet Laplacian tridiag(−1, 2, −1) of size n.
    fn laplacian_1d(x: &[f64], y: &mut [f64]) {
        let n = x.len();
        for i in 0..n {
            let left = if i > 0 { x[i - 1] } else { 0.0 };
            let right = if i + 1 < n { x[i + 1] } else { 0.0 };
            y[i] = 2.0 * x[i] - left - right;
        }
    }

    /// Both stopping rules reach the exact solution of a small SPD system; without a
    /// preconditioner CG needs at most n iterations (exact arithmetic: n/2 here by symmetry of
    /// the right-hand side), and a Jacobi preconditioner (exact for a diagonal) changes nothing
    /// but the scaling.
    #[test]
    fn solves_a_1d_poisson_problem_with_either_stopping_rule() {
        let n = 40;
        let truth: Vec<f64> = (0..n)
            .map(|i| (i as f64 * 0.3).sin() + 0.01 * i as f64)
            .collect();
        let mut b = vec![0.0; n];
        laplacian_1d(&truth, &mut b);
        for stop in [
            Stop::ResidualNorm(1e-12),
            Stop::PreconditionedResidual(1e-12),
        ] {
            let mut x = vec![0.0; n];
            let iterations = preconditioned_cg(
                laplacian_1d,
                |r: &[f64], z: &mut [f64]| z.iter_mut().zip(r).for_each(|(z, r)| *z = r / 2.0),
                &b,
                &mut x,
                stop,
                1000,
            );
            assert!(iterations <= n + 1, "{stop:?}: {iterations}");
            let worst = x
                .iter()
                .zip(&truth)
                .map(|(a, t)| (a - t).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-8, "{stop:?}: {worst}");
        }
        // A warm start at the solution stops at once; an iteration cap is reported as such.
        let mut x = truth.clone();
        let none = |r: &[f64], z: &mut [f64]| z.copy_from_slice(r);
        assert_eq!(
            preconditioned_cg(laplacian_1d, none, &b, &mut x, Stop::ResidualNorm(1e-9), 50),
            0
        );
        let mut x = vec![0.0; n];
        assert_eq!(
            preconditioned_cg(laplacian_1d, none, &b, &mut x, Stop::ResidualNorm(1e-15), 3),
            3
        );
    }
}
