//! Pixels without a full normal: those lit by exactly two LEDs, and holes inside the object.
//!
//! Two Lambertian measurements A₁ = ρ·n·L₁ and A₂ = ρ·n·L₂ fix the normal up to one angle:
//! n·m = 0 with m = A₂·L₁ − A₁·L₂, and n·L₁ > 0 picks the lit half of that great circle. The
//! missing angle comes from the integrability of the surface (Onn & Bruckstein, "Integrability
//! disambiguates surface recovery in two-image photometric stereo", IJCV 1990). Since the normal
//! is an affine function of the slopes (\[`super::grid`\]), the circle is a line in slope space, and
//! the integrator alternates between solving for depth and moving each such pixel's slopes to the
//! point of its line that best fits the current depth (\[`slopes_on_line`\]), kept on the lit half
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
//! from their surroundings by push–pull (\[`super::inpaint`\]) and a low weight, so the integrator bridges
//! them instead of cutting the object into islands.

use super::least_squares::Topology;
use super::multigrid::NONE;
pub use meb_core::types::NormalPlane;

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
