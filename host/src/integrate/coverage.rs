//! Pixels without a full normal: those lit by exactly two LEDs, and holes inside the object.
//!
//! Two Lambertian measurements A₁ = ρ·n·L₁ and A₂ = ρ·n·L₂ fix the normal up to one angle:
//! n·m = 0 with m = A₂·L₁ − A₁·L₂, and n·L₁ > 0 picks the lit half of that great circle. The
//! missing angle comes from the integrability of the surface (Onn & Bruckstein, "Integrability
//! disambiguates surface recovery in two-image photometric stereo", IJCV 1990). Since the normal
//! is an affine function of the slopes ([`super::grid`]), the circle is a line in slope space, and
//! the integrator alternates between solving for depth and moving each such pixel's slopes to the
//! point of its line that best fits the current depth ([`slopes_on_line`]), kept on the lit half
//! of the circle and within a tilt limit ([`NormalPlane::project`]). The albedo then fixes the
//! angle up to a mirror choice: ρn = g₀ ± √(ρ² − |g₀|²)·ĉ, with g₀ the least-norm solution of
//! both readings (in the plane of L₁ and L₂) and ĉ the circle's direction perpendicular to it.
//! Albedo varies slowly, so the integrator interpolates it from the measured pixels around and
//! lets integrability pick the side: after each depth solve a two-LED pixel takes the normal of
//! its circle with that albedo on the side of the point that fits the depth
//! ([`NormalPlane::with_albedo`]; Hernández, Vogiatzis & Cipolla, "Shadows in three-source
//! photometric stereo", ECCV 2008). The albedo step starts only once the alternation without it
//! has settled (or used half its passes): a flat face fits either mirror image equally well, so a
//! side picked from slopes filled in from the neighbouring faces would never change. On the ToF
//! hybrid scene's cube, whose third face is 43 % two-LED, picking the side at the start left
//! 41–57 % of that face's two-LED pixels on the wrong side (placed RMSE 16.5 / 22.1 mm on the
//! two test seeds); from the settled depth 5–8 % are (6.5 / 4.2 mm; 6.7 / 7.5 mm without the
//! albedo). On Suzanne (out-of-plane rig, bilateral integrator) the albedo takes the depth RMSE
//! of simulator seeds 1–4 from 5.24 / 4.53 / 5.69 / 5.23 mm to 3.97 / 4.02 / 4.78 / 3.46 mm.
//!
//! Holes (pixels lit by fewer than two LEDs that the object surrounds) get slopes interpolated
//! from their surroundings by push–pull ([`super::inpaint`]) and a low weight, so the integrator bridges
//! them instead of cutting the object into islands.

use super::least_squares::Topology;
use super::multigrid::NONE;
pub use crate::types::NormalPlane;
use nalgebra::Vector3;

/// Largest angle between a two-LED pixel's normal and the middle of its lit half-circle.
const MAX_TILT_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

impl NormalPlane {
    /// The normal on the circle nearest `n` in angle, within [`MAX_TILT_RAD`] of the direction
    /// of `towards` in the plane; `None` when the constraint is degenerate or `n` is not finite.
    ///
    /// With e₁ the direction of `towards` in the circle's plane and e₂ = m̂ × e₁, `n` lies at the
    /// angle θ = atan2(n·e₂, n·e₁) of the circle; the answer is at θ clamped to ±α. Within the
    /// limit (cos θ ≥ cos α) that is the in-plane part of `n` normalised, beyond it the limit on
    /// the side of n·e₂, so no angle is computed (atan2 and sin/cos were 1.5 % of `meb video`'s
    /// CPU).
    pub fn project(&self, n: &Vector3<f64>) -> Option<Vector3<f64>> {
        let m = self.across.try_normalize(0.0)?;
        let e1 = (self.towards - m * m.dot(&self.towards)).try_normalize(1e-12)?;
        let e2 = m.cross(&e1);
        let (along, aside) = (n.dot(&e1), n.dot(&e2));
        let radius = (along * along + aside * aside).sqrt();
        if !radius.is_finite() {
            return None;
        }
        if radius == 0.0 {
            // θ = atan2(0, 0) = 0: the middle of the half-circle.
            return Some(e1);
        }
        let (cos_limit, sin_limit) = (MAX_TILT_RAD.cos(), MAX_TILT_RAD.sin());
        if along >= radius * cos_limit {
            return Some((e1 * along + e2 * aside) / radius);
        }
        Some(e1 * cos_limit + e2 * sin_limit.copysign(aside))
    }

    /// The normal of the circle whose albedo is `albedo` on the side of `n` (module docs):
    /// g₀/ρ ± √(1 − |g₀|²/ρ²)·ĉ, or g₀/|g₀| when ρ ≤ |g₀|; `None` when g₀ is unknown.
    pub fn with_albedo(&self, albedo: f64, n: &Vector3<f64>) -> Option<Vector3<f64>> {
        let least = self.least_albedo.norm();
        if !(albedo.is_finite() && albedo > 0.0 && least > 0.0) {
            return None;
        }
        let e1 = self.least_albedo / least;
        let e2 = self.across.cross(&e1).try_normalize(1e-12)?;
        let cos = (least / albedo).min(1.0);
        let sin = (1.0 - cos * cos).sqrt();
        Some(e1 * cos + e2 * sin.copysign(n.dot(&e2)))
    }
}

/// The slopes on the line a·s_x + b·s_y = c that minimise node `k`'s one-sided equations at
/// the solution `x`: Σ w·(Δz − h·s)² over its sides is W_x(s_x − ŝ_x)² + W_y(s_y − ŝ_y)² + const,
/// so the answer is the (W_x, W_y)-weighted projection of (ŝ_x, ŝ_y) onto the line. This is
/// the exact minimiser of the integrator's energy over the pixel's circle (the albedo step that
/// follows it, [`NormalPlane::with_albedo`], keeps only the side it chose).
pub(crate) fn slopes_on_line(
    topology: &Topology,
    x: &[f64],
    k: usize,
    sides: &[f64; 4],
    step: f64,
    (a, b, c): (f64, f64, f64),
) -> Option<(f64, f64)> {
    let nb = topology.neighbours[k];
    let side = |d: usize| {
        let j = nb[d];
        (j != NONE).then(|| {
            let j = j as usize;
            let delta = if d < 2 { x[j] - x[k] } else { x[k] - x[j] };
            (sides[d], delta)
        })
    };
    // Right/left measure h·s_x, down/up measure −h·s_y.
    let mean = |forward: usize, backward: usize, sign: f64| {
        let (mut w, mut sum) = (0.0, 0.0);
        for (wd, delta) in [side(forward), side(backward)].into_iter().flatten() {
            w += wd;
            sum += wd * delta;
        }
        (
            w * step * step,
            if w > 0.0 {
                sign * sum / (w * step)
            } else {
                0.0
            },
        )
    };
    let (wx, sx) = mean(0, 2, 1.0);
    let (wy, sy) = mean(1, 3, -1.0);
    // Keep both slopes in play when a pixel has no neighbour along an axis.
    let floor = 1e-9 * (wx + wy).max(f64::MIN_POSITIVE);
    let (wx, wy) = (wx.max(floor), wy.max(floor));
    let denominator = a * a / wx + b * b / wy;
    if !denominator.is_finite() || denominator <= 0.0 {
        return None;
    }
    let lambda = (a * sx + b * sy - c) / denominator;
    Some((sx - lambda * a / wx, sy - lambda * b / wy))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_stays_on_the_lit_half_circle() {
        let plane = NormalPlane {
            pixel: (0, 0),
            across: Vector3::x(),
            towards: Vector3::z(),
            least_albedo: Vector3::zeros(),
        };
        // Nearest point of the y–z circle to a normal leaning towards +x and +y.
        let n = plane.project(&Vector3::new(0.7, 0.3, 0.5)).unwrap();
        assert!(n.x.abs() < 1e-12);
        assert!((n - Vector3::new(0.0, 0.3, 0.5).normalize()).norm() < 1e-12);
        // A normal pointing away from `towards` is clamped to the tilt limit.
        let n = plane.project(&Vector3::new(0.0, 0.1, -1.0)).unwrap();
        assert!((n.z - MAX_TILT_RAD.cos()).abs() < 1e-12 && n.y > 0.0);
        let degenerate = NormalPlane {
            across: Vector3::z(),
            ..plane
        };
        assert!(degenerate.project(&Vector3::z()).is_none());
    }

    /// The projection equals the angle clamped on the circle, θ = atan2(n·e₂, n·e₁) within
    /// ±[`MAX_TILT_RAD`], over random planes and normals (fixed seed), both sides of the limit.
    #[test]
    fn projection_is_the_clamped_angle_on_the_circle() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut random_vector = || {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let (mut clamped, mut inside) = (0, 0);
        for _ in 0..2000 {
            let plane = NormalPlane {
                pixel: (0, 0),
                across: random_vector(),
                towards: random_vector(),
                least_albedo: Vector3::zeros(),
            };
            let n = random_vector();
            let m = plane.across.normalize();
            let e1 = (plane.towards - m * m.dot(&plane.towards)).normalize();
            let e2 = m.cross(&e1);
            let theta = n.dot(&e2).atan2(n.dot(&e1));
            let expected = theta.clamp(-MAX_TILT_RAD, MAX_TILT_RAD);
            if expected == theta {
                inside += 1;
            } else {
                clamped += 1;
            }
            let want = e1 * expected.cos() + e2 * expected.sin();
            let got = plane.project(&n).unwrap();
            assert!(
                (got - want).norm() < 1e-12,
                "{got} vs {want} at θ = {theta}"
            );
        }
        assert!(
            clamped > 100 && inside > 100,
            "{clamped} clamped, {inside} inside"
        );
        let plane = NormalPlane {
            pixel: (0, 0),
            across: Vector3::x(),
            towards: Vector3::z(),
            least_albedo: Vector3::zeros(),
        };
        assert_eq!(plane.project(&Vector3::x()), Some(Vector3::z()));
        assert!(plane.project(&Vector3::new(0.0, f64::NAN, 1.0)).is_none());
    }

    /// Two lights and a known normal: the circle with the true albedo holds the normal and its
    /// mirror image across g₀; the side of the hint picks one.
    #[test]
    fn albedo_picks_the_normal_on_the_circle() {
        let (l1, l2) = (Vector3::new(0.6, 0.2, 0.8), Vector3::new(-0.5, 0.4, 0.77));
        let n = Vector3::new(0.3, -0.2, 0.9).normalize();
        let rho = 0.7;
        let (a1, a2) = (rho * n.dot(&l1), rho * n.dot(&l2));
        let (ii, ij, jj) = (l1.dot(&l1), l1.dot(&l2), l2.dot(&l2));
        let det = ii * jj - ij * ij;
        let plane = NormalPlane {
            pixel: (0, 0),
            across: l1 * a2 - l2 * a1,
            towards: l1 + l2,
            least_albedo: l1 * ((jj * a1 - ij * a2) / det) + l2 * ((ii * a2 - ij * a1) / det),
        };
        let found = plane.with_albedo(rho, &n).unwrap();
        assert!((found - n).norm() < 1e-9, "{found} vs {n}");
        let other = plane.with_albedo(rho, &-n).unwrap();
        assert!((other - n).norm() > 0.1);
        assert!((rho * other.dot(&l1) - a1).abs() < 1e-9);
        assert!((rho * other.dot(&l2) - a2).abs() < 1e-9);
        assert!(plane.with_albedo(f64::NAN, &n).is_none());
    }
}
