//! Preconditioned conjugate gradients for the symmetric positive (semi-)definite systems of
//! normal integration and position–normal fusion (Hestenes & Stiefel, "Methods of conjugate
//! gradients for solving linear systems", 1952; Saad, "Iterative methods for sparse linear
//! systems", 2nd ed. 2003, Algorithm 9.1). The operator, the preconditioner and the stopping
//! rule are parameters, so the masked Poisson solve ([`super::least_squares`]) and the Nehab
//! fusion ([`super::fusion`]) share one loop.

use rayon::prelude::*;

/// When conjugate gradients stops (checked before every iteration, including the first).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Stop {
    /// ‖r‖₂ ≤ tolerance · ‖b‖₂.
    ResidualNorm(f64),
    /// rᵀM⁻¹r ≤ tolerance² · bᵀM⁻¹b (the preconditioned residual in the energy of M⁻¹; costs
    /// one extra preconditioner application for bᵀM⁻¹b).
    PreconditionedResidual(f64),
}

/// The vectors of a conjugate-gradient solve (residual r, preconditioned residual z, search
/// direction p and its image Ap), kept between solves so that a sequence of solves allocates
/// them once. Every entry is written before it is read, so what a previous solve left in them
/// does not matter.
#[derive(Debug, Default)]
pub(crate) struct CgVectors {
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    ap: Vec<f64>,
}

/// Solves A x = b from the given `x` (warm start) with the operator `apply` (y = A x) and
/// the preconditioner `precondition` (z = M⁻¹ r; both must set every entry of their output)
/// in the scratch `vectors`; returns the iterations run (`max_iterations` when the stopping
/// rule was not met). Stops early, without a step, when the curvature pᵀAp is not positive (A
/// singular along p: the system is solved as far as it can be).
pub(crate) fn preconditioned_cg(
    apply: impl Fn(&[f64], &mut [f64]),
    mut precondition: impl FnMut(&[f64], &mut [f64]),
    b: &[f64],
    x: &mut [f64],
    stop: Stop,
    max_iterations: usize,
    vectors: &mut CgVectors,
) -> usize {
    let n = b.len();
    assert!(x.len() == n, "x and b must have the same length");
    let CgVectors { r, z, p, ap } = vectors;
    for v in [&mut *r, &mut *z, &mut *p, &mut *ap] {
        v.resize(n, 0.0);
    }
    let threshold = match stop {
        Stop::ResidualNorm(t) => t * dot(b, b).sqrt().max(f64::MIN_POSITIVE),
        Stop::PreconditionedResidual(t) => {
            precondition(b, z);
            t * t * dot(b, z).max(f64::MIN_POSITIVE)
        }
    };
    apply(x, r);
    r.iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
    precondition(r, z);
    p.copy_from_slice(z);
    let mut rz = dot(r, z);
    // ‖r‖², summed in the same order as `dot` (here and in the update below).
    let mut rr = dot(r, r);
    for iteration in 0..max_iterations {
        let converged = match stop {
            Stop::ResidualNorm(_) => rr.sqrt() <= threshold,
            Stop::PreconditionedResidual(_) => rz <= threshold,
        };
        if converged {
            return iteration;
        }
        apply(p, ap);
        let curvature = dot(p, ap);
        if curvature.is_nan() || curvature <= 0.0 {
            return iteration;
        }
        let alpha = rz / curvature;
        rr = step(x, r, p, ap, alpha);
        precondition(r, z);
        let rz_next = dot(r, z);
        let beta = rz_next / rz;
        rz = rz_next;
        next_direction(p, z, beta);
    }
    max_iterations
}

/// Vectors shorter than this are updated on the calling thread.
const PARALLEL_LENGTH: usize = 16_384;
/// Entries per parallel task. Sums are taken per band and the bands' sums added in order, so
/// the result does not depend on how the thread pool splits the work.
const BAND: usize = 4_096;

/// uᵀv.
fn dot(u: &[f64], v: &[f64]) -> f64 {
    let band = |(u, v): (&[f64], &[f64])| u.iter().zip(v).map(|(p, q)| p * q).sum::<f64>();
    if u.len() < PARALLEL_LENGTH {
        return band((u, v));
    }
    let sums: Vec<f64> = u
        .par_chunks(BAND)
        .zip(v.par_chunks(BAND))
        .map(band)
        .collect();
    sums.iter().sum()
}

/// x += α p, r −= α Ap; returns ‖r‖².
fn step(x: &mut [f64], r: &mut [f64], p: &[f64], ap: &[f64], alpha: f64) -> f64 {
    let band = |x: &mut [f64], r: &mut [f64], p: &[f64], ap: &[f64]| {
        let mut rr = 0.0;
        for ((xk, rk), (pk, apk)) in x.iter_mut().zip(r.iter_mut()).zip(p.iter().zip(ap)) {
            *xk += alpha * pk;
            *rk -= alpha * apk;
            rr += *rk * *rk;
        }
        rr
    };
    if x.len() < PARALLEL_LENGTH {
        return band(x, r, p, ap);
    }
    let sums: Vec<f64> = x
        .par_chunks_mut(BAND)
        .zip(r.par_chunks_mut(BAND))
        .zip(p.par_chunks(BAND).zip(ap.par_chunks(BAND)))
        .map(|((x, r), (p, ap))| band(x, r, p, ap))
        .collect();
    sums.iter().sum()
}

/// p = z + β p.
fn next_direction(p: &mut [f64], z: &[f64], beta: f64) {
    let band = |(p, z): (&mut [f64], &[f64])| {
        p.iter_mut()
            .zip(z)
            .for_each(|(pk, zk)| *pk = zk + beta * *pk);
    };
    if p.len() < PARALLEL_LENGTH {
        band((p, z));
    } else {
        p.par_chunks_mut(BAND)
            .zip(z.par_chunks(BAND))
            .for_each(band);
    }
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
                &mut CgVectors::default(),
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
            preconditioned_cg(
                laplacian_1d,
                none,
                &b,
                &mut x,
                Stop::ResidualNorm(1e-9),
                50,
                &mut CgVectors::default()
            ),
            0
        );
        let mut x = vec![0.0; n];
        assert_eq!(
            preconditioned_cg(
                laplacian_1d,
                none,
                &b,
                &mut x,
                Stop::ResidualNorm(1e-15),
                3,
                &mut CgVectors::default()
            ),
            3
        );
    }

    /// The vector updates of a long solve, in parallel bands, equal the serial formulas: the
    /// element-wise ones exactly, the sums to rounding and the same on every call.
    #[test]
    fn long_vectors_are_updated_in_bands_as_short_ones_are() {
        let n = 3 * PARALLEL_LENGTH + 123;
        let wave =
            |phase: f64| -> Vec<f64> { (0..n).map(|i| (i as f64 * 0.37 + phase).sin()).collect() };
        let (u, v) = (wave(0.0), wave(1.0));
        let serial: f64 = u.iter().zip(&v).map(|(a, b)| a * b).sum();
        let banded = dot(&u, &v);
        assert!(
            (banded - serial).abs() <= 1e-12 * n as f64,
            "{banded} {serial}"
        );
        // The same bands every time, whatever the thread pool does.
        assert_eq!(dot(&u, &v).to_bits(), banded.to_bits());
        let (mut x, mut r, p, ap) = (wave(2.0), wave(3.0), wave(4.0), wave(5.0));
        let (x0, r0) = (x.clone(), r.clone());
        let rr = step(&mut x, &mut r, &p, &ap, 0.3);
        for k in 0..n {
            assert_eq!(x[k], x0[k] + 0.3 * p[k]);
            assert_eq!(r[k], r0[k] - 0.3 * ap[k]);
        }
        let serial: f64 = r.iter().map(|v| v * v).sum();
        assert!((rr - serial).abs() <= 1e-12 * n as f64, "{rr} {serial}");
        let (mut p, z) = (wave(6.0), wave(7.0));
        let p0 = p.clone();
        next_direction(&mut p, &z, 0.7);
        for k in 0..n {
            assert_eq!(p[k], z[k] + 0.7 * p0[k]);
        }
    }

    /// Vectors kept from a solve of another size (and left full of its values) give the same
    /// solution, bit for bit, as fresh ones.
    #[test]
    fn kept_vectors_give_the_same_solution_as_fresh_ones() {
        let jacobi = |r: &[f64], z: &mut [f64]| z.iter_mut().zip(r).for_each(|(z, r)| *z = r / 2.0);
        let b_of = |n: usize| -> Vec<f64> { (0..n).map(|i| (i as f64 * 0.7).cos()).collect() };
        let mut kept = CgVectors::default();
        let mut other = vec![0.0; 57];
        let used = preconditioned_cg(
            laplacian_1d,
            jacobi,
            &b_of(57),
            &mut other,
            Stop::ResidualNorm(1e-10),
            1000,
            &mut kept,
        );
        assert!(used > 0 && kept.r.len() == 57);
        for n in [30, 80] {
            let b = b_of(n);
            let (mut x_kept, mut x_fresh) = (vec![0.0; n], vec![0.0; n]);
            let stop = Stop::PreconditionedResidual(1e-10);
            let a = preconditioned_cg(laplacian_1d, jacobi, &b, &mut x_kept, stop, 1000, &mut kept);
            let f = preconditioned_cg(
                laplacian_1d,
                jacobi,
                &b,
                &mut x_fresh,
                stop,
                1000,
                &mut CgVectors::default(),
            );
            assert_eq!((a, &x_kept), (f, &x_fresh));
            assert!(a > 0);
        }
    }
}
