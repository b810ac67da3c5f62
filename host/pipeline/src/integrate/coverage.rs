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

use super::bilateral::SideWeights;
use super::grid::DepthGrid;
use super::least_squares::Topology;
use super::multigrid::NONE;
pub use meb_core::types::NormalPlane;
use ndarray::Array2;
use rayon::prelude::*;

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

/// Two-LED pixels per parallel task of [`TwoLedPixels::update`].
const PLANES_PER_TASK: usize = 1024;

/// A window's two-LED pixels, the nodes of the integration graph whose slopes the integrator
/// moves along their circles.
pub(super) struct TwoLedPixels<'a> {
    /// Each pixel's node and circle (window coordinates).
    planes: Vec<(usize, NormalPlane)>,
    /// Each circle as the line a·s_x + b·s_y = c in slope space.
    lines: Vec<(f64, f64, f64)>,
    grid: &'a DepthGrid,
    /// The window's origin in the grid (row, column).
    origin: (usize, usize),
    /// Largest |slope| a pixel may take.
    max_slope: f64,
    /// Albedo interpolated over the window (NaN where unknown).
    albedo: &'a Array2<f64>,
}

impl<'a> TwoLedPixels<'a> {
    /// The pixels of `planes` that are nodes of `topology`.
    pub fn new(
        planes: &[NormalPlane],
        topology: &Topology,
        grid: &'a DepthGrid,
        origin: (usize, usize),
        max_slope: f64,
        albedo: &'a Array2<f64>,
    ) -> Self {
        let planes: Vec<(usize, NormalPlane)> = planes
            .iter()
            .filter_map(|p| topology.node(p.pixel).map(|k| (k, *p)))
            .collect();
        let lines = planes
            .iter()
            .map(|(_, plane)| {
                let [a0, a1, a2] =
                    grid.normal_affine(plane.pixel.0 + origin.0, plane.pixel.1 + origin.1);
                let m = plane.across;
                (m.dot(&a1), m.dot(&a2), -m.dot(&a0))
            })
            .collect();
        Self {
            planes,
            lines,
            grid,
            origin,
            max_slope,
            albedo,
        }
    }

    /// Whether the window has none.
    pub fn is_empty(&self) -> bool {
        self.planes.is_empty()
    }

    /// Moves every pixel's slopes onto the lit half of its circle, within the tilt limit.
    pub fn onto_circles(&self, slopes: &mut [(f64, f64)]) {
        self.update(slopes, |before, k, plane, _| {
            self.on_circle(plane, before[k])
        });
    }

    /// Moves every pixel's slopes to the point of its circle that best fits the depth `x`
    /// under the edge weights `sides` ([`slopes_on_line`]), on the side the interpolated
    /// albedo gives when `use_albedo`.
    pub fn follow_depth(
        &self,
        slopes: &mut [(f64, f64)],
        topology: &Topology,
        x: &[f64],
        sides: &[SideWeights],
        step: f64,
        use_albedo: bool,
    ) {
        self.update(slopes, |_, k, plane, line| {
            slopes_on_line(topology, x, k, &sides[k], step, line)
                .and_then(|s| self.on_circle(plane, s))
                .map(|s| {
                    if use_albedo {
                        self.with_albedo(plane, s)
                    } else {
                        s
                    }
                })
        });
    }

    /// Moves every pixel's slopes to the point of its circle with the interpolated albedo, on
    /// the side of its present slopes.
    pub fn take_albedo_side(&self, slopes: &mut [(f64, f64)]) {
        self.update(slopes, |before, k, plane, _| {
            Some(self.with_albedo(plane, before[k]))
        });
    }

    /// Sets the slopes of every pixel that `new(slopes, node, circle, line)` gives a value
    /// for. Each pixel's new value depends on the slopes before the update and its own data
    /// only, so they are found in parallel and then stored.
    fn update(
        &self,
        slopes: &mut [(f64, f64)],
        new: impl Fn(&[(f64, f64)], usize, &NormalPlane, (f64, f64, f64)) -> Option<(f64, f64)> + Sync,
    ) {
        let before: &[(f64, f64)] = slopes;
        let updated: Vec<Option<(f64, f64)>> = self
            .planes
            .par_iter()
            .zip(&self.lines)
            .with_min_len(PLANES_PER_TASK)
            .map(|((k, plane), &line)| new(before, *k, plane, line))
            .collect();
        for ((k, _), s) in self.planes.iter().zip(updated) {
            if let Some(s) = s {
                slopes[*k] = s;
            }
        }
    }

    /// Both slopes clamped to ±`max_slope`.
    fn clip(&self, s: (f64, f64)) -> (f64, f64) {
        (
            s.0.clamp(-self.max_slope, self.max_slope),
            s.1.clamp(-self.max_slope, self.max_slope),
        )
    }

    /// The slopes `s` moved onto the lit half of the pixel's circle, within the tilt limit.
    fn on_circle(&self, plane: &NormalPlane, s: (f64, f64)) -> Option<(f64, f64)> {
        let (r, c) = self.grid_pixel(plane);
        plane
            .project(&self.grid.normal(r, c, s.0, s.1))
            .and_then(|n| self.grid.slopes(r, c, &n))
            .map(|s| self.clip(s))
    }

    /// The point of the pixel's circle with the interpolated albedo on the side of slopes `s`
    /// (`s` itself when the albedo or the circle's g₀ is unknown).
    fn with_albedo(&self, plane: &NormalPlane, s: (f64, f64)) -> (f64, f64) {
        let (r, c) = self.grid_pixel(plane);
        plane
            .with_albedo(self.albedo[plane.pixel], &self.grid.normal(r, c, s.0, s.1))
            .and_then(|m| self.grid.slopes(r, c, &m))
            .map_or(s, |s| self.clip(s))
    }

    /// The pixel's position in the grid.
    fn grid_pixel(&self, plane: &NormalPlane) -> (usize, usize) {
        (plane.pixel.0 + self.origin.0, plane.pixel.1 + self.origin.1)
    }
}
