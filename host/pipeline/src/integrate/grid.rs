//! The unknown the integrators solve for, and how surface normals turn into its slopes.
//!
//! Orthographic camera (docs/maths/integration.md#slopes-from-normals): the unknown is the height z
//! in mm on a grid of pitch h;
//! slopes s_x = ∂z/∂x = −n_x/n_z and s_y = ∂z/∂y = −n_y/n_z (y up) are dimensionless.
//!
//! Perspective camera (Quéau, Durou & Aujol, "Normal integration: a survey", 2018, §2.2, the
//! log-depth change of variable): a pixel with undistorted normalised coordinates (x, y) (camera
//! frame x right, y down, z forward) sees P = d·(x, y, 1) at distance d along the optical axis.
//! With p̃ = ∂ln d/∂x and q̃ = ∂ln d/∂y the camera-frame normal is n ∝ (−p̃, −q̃, 1 + x·p̃ + y·q̃),
//! hence p̃ = −n₁/(n·(x, y, 1)), q̃ = −n₂/(n·(x, y, 1)). The unknown is ẑ = f̄·ln(d/D)
//! (f̄ = √(fx·fy), D the camera distance), a pixel-unit log depth whose slopes along the grid,
//! through the Jacobian of the (distorted) pixel → (x, y) map, are about the orthographic slopes
//! of the surface; the grid step is one pixel. Depth in mm is z = D − D·exp(ẑ/f̄), so ẑ = 0 is the
//! plane of the object centre.
//!
//! In both cases the normal is an affine function of the two slopes, n ∝ a₀ + s_x·a₁ + s_y·a₂,
//! which is what lets a pixel lit by two LEDs constrain its slopes to a line.

use meb_core::rig::{Intrinsics, Projection};
use nalgebra::Vector3;

/// Smallest n·v (cosine between normal and view direction) a usable normal may have.
const GRAZING_COSINE: f64 = 1e-6;

/// The integration grid of one camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum DepthGrid {
    /// Height z in mm, grid pitch `pitch_mm`.
    Orthographic {
        /// Grid pitch h in mm per pixel.
        pitch_mm: f64,
    },
    /// Pixel-unit log depth ẑ (module docs).
    Perspective {
        /// The intrinsics.
        intrinsics: Intrinsics,
        /// Camera distance D in mm.
        distance_mm: f64,
    },
}

impl DepthGrid {
    /// The grid of a camera projection.
    pub fn new(projection: &Projection) -> Self {
        match *projection {
            Projection::Orthographic { pitch_mm, .. } => DepthGrid::Orthographic { pitch_mm },
            Projection::Perspective {
                intrinsics,
                distance_mm,
            } => DepthGrid::Perspective {
                intrinsics,
                distance_mm,
            },
        }
    }

    /// Grid step of the edge equations: h in mm, or one pixel.
    pub fn step(&self) -> f64 {
        match self {
            DepthGrid::Orthographic { pitch_mm } => *pitch_mm,
            DepthGrid::Perspective { .. } => 1.0,
        }
    }

    /// Factor that turns a difference of the unknown into pixel units.
    pub fn pixel_units(&self) -> f64 {
        1.0 / self.step()
    }

    /// f̄ = √(fx·fy) of a perspective grid.
    fn focal(k: &Intrinsics) -> f64 {
        (k.fx * k.fy).sqrt()
    }

    /// Slopes (s_x, s_y) of a unit normal (scene frame) at pixel (row, col), or `None` when the
    /// normal is not finite or does not face the camera.
    pub fn slopes(&self, row: usize, col: usize, n: &Vector3<f64>) -> Option<(f64, f64)> {
        if !n.iter().all(|v| v.is_finite()) {
            return None;
        }
        match self {
            DepthGrid::Orthographic { .. } => {
                (n.z > GRAZING_COSINE * n.norm()).then(|| (-n.x / n.z, -n.y / n.z))
            }
            DepthGrid::Perspective { intrinsics, .. } => {
                let (x, y) = intrinsics.normalised(row as f64, col as f64);
                // Camera frame: y down, z forward.
                let nc = Vector3::new(n.x, -n.y, -n.z);
                let ray = Vector3::new(x, y, 1.0);
                let denom = nc.dot(&ray);
                // Visible: the normal faces back along the ray.
                if -denom <= GRAZING_COSINE * nc.norm() * ray.norm() {
                    return None;
                }
                let (p, q) = (-nc.x / denom, -nc.y / denom);
                let j = intrinsics.jacobian(row as f64, col as f64);
                let f = Self::focal(intrinsics);
                let d_col = f * (p * j[0][0] + q * j[1][0]);
                let d_row = f * (p * j[0][1] + q * j[1][1]);
                Some((d_col, -d_row))
            }
        }
    }

    /// The unit normal (scene frame, facing the camera) of slopes (s_x, s_y) at (row, col).
    pub fn normal(&self, row: usize, col: usize, sx: f64, sy: f64) -> Vector3<f64> {
        let [a0, a1, a2] = self.normal_affine(row, col);
        let n = a0 + a1 * sx + a2 * sy;
        n.try_normalize(0.0).unwrap_or_else(Vector3::z)
    }

    /// a₀, a₁, a₂ with n ∝ a₀ + s_x·a₁ + s_y·a₂ facing the camera (module docs).
    pub fn normal_affine(&self, row: usize, col: usize) -> [Vector3<f64>; 3] {
        match self {
            DepthGrid::Orthographic { .. } => [Vector3::z(), -Vector3::x(), -Vector3::y()],
            DepthGrid::Perspective { intrinsics, .. } => {
                let (x, y) = intrinsics.normalised(row as f64, col as f64);
                let j = intrinsics.jacobian(row as f64, col as f64);
                let f = Self::focal(intrinsics);
                // (∂ẑ/∂col, ∂ẑ/∂row) = f·Jᵀ(p̃, q̃)  ⇒  (p̃, q̃) = J⁻ᵀ(s_x, −s_y)/f.
                let (a, b, c, d) = (j[0][0], j[1][0], j[0][1], j[1][1]); // Jᵀ = [[a, b], [c, d]]
                let det = a * d - b * c;
                let pq = |sx: f64, sy: f64| {
                    let (u, v) = (sx / f, -sy / f);
                    ((d * u - b * v) / det, (-c * u + a * v) / det)
                };
                // Camera-frame normal facing the camera: −(−p̃, −q̃, 1 + x·p̃ + y·q̃); scene frame
                // flips y and z.
                let scene = |(p, q): (f64, f64)| Vector3::new(p, -q, 1.0 + x * p + y * q);
                let n0 = scene(pq(0.0, 0.0));
                [n0, scene(pq(1.0, 0.0)) - n0, scene(pq(0.0, 1.0)) - n0]
            }
        }
    }

    /// Depth z in mm of the unknown's value `u`.
    pub fn depth_mm(&self, u: f64) -> f64 {
        match self {
            DepthGrid::Orthographic { .. } => u,
            DepthGrid::Perspective {
                intrinsics,
                distance_mm,
            } => distance_mm - distance_mm * (u / Self::focal(intrinsics)).exp(),
        }
    }

    /// The unknown's value of depth z in mm (NaN at or behind a perspective camera).
    pub fn unknown_of(&self, z: f64) -> f64 {
        match self {
            DepthGrid::Orthographic { .. } => z,
            DepthGrid::Perspective {
                intrinsics,
                distance_mm,
            } => {
                let d = distance_mm - z;
                if d > 0.0 {
                    Self::focal(intrinsics) * (d / distance_mm).ln()
                } else {
                    f64::NAN
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::rig::{Camera, Intrinsics};

    fn perspective() -> (Camera, DepthGrid) {
        let camera = Camera {
            width: 80,
            height: 60,
            fps: 960.0,
            distance_mm: 300.0,
            fov_deg: None,
            pixel_pitch_mm: None,
            intrinsics: Some(Intrinsics {
                fx: 500.0,
                fy: 520.0,
                cx: 41.0,
                cy: 28.5,
                k1: -0.3,
                k2: 0.1,
            }),
            axis_px: None,
        };
        let grid = DepthGrid::new(&camera.projection());
        (camera, grid)
    }

    /// A tilted plane seen in perspective: finite differences of ẑ along the grid equal the
    /// slopes computed from its normal, and slopes → normal → slopes round-trips.
    #[test]
    fn perspective_slopes_match_the_log_depth_of_a_plane() {
        let (camera, grid) = perspective();
        let n = Vector3::new(0.3, -0.4, 0.8).normalize();
        let point_on_plane = Vector3::new(5.0, 2.0, 10.0);
        // ẑ at pixel (row, col): intersect the pixel's ray with the plane n·(X − P0) = 0.
        let zhat = |row: f64, col: f64| {
            let ray = camera.ray(row, col);
            let z = n.dot(&(point_on_plane - ray.base)) / n.dot(&ray.slope);
            grid.unknown_of(z)
        };
        for (row, col) in [(5usize, 7usize), (30, 40), (55, 75)] {
            let (sx, sy) = grid.slopes(row, col, &n).unwrap();
            let (r, c) = (row as f64, col as f64);
            let e = 1e-3;
            let d_col = (zhat(r, c + e) - zhat(r, c - e)) / (2.0 * e);
            let d_row = (zhat(r + e, c) - zhat(r - e, c)) / (2.0 * e);
            assert!((sx - d_col).abs() < 1e-6, "{sx} vs {d_col}");
            assert!((sy + d_row).abs() < 1e-6, "{sy} vs {}", -d_row);
            let back = grid.normal(row, col, sx, sy);
            assert!((back - n).norm() < 1e-9, "{back} vs {n}");
        }
        let z = 12.5;
        assert!((grid.depth_mm(grid.unknown_of(z)) - z).abs() < 1e-9);
        assert!(grid.unknown_of(400.0).is_nan());
    }

    #[test]
    fn orthographic_slopes_and_back() {
        let grid = DepthGrid::Orthographic { pitch_mm: 0.5 };
        let n = Vector3::new(-0.2, 0.1, 0.9).normalize();
        let (sx, sy) = grid.slopes(0, 0, &n).unwrap();
        assert!((sx - 0.2 / 0.9).abs() < 1e-12 && (sy + 0.1 / 0.9).abs() < 1e-12);
        assert!((grid.normal(3, 4, sx, sy) - n).norm() < 1e-12);
        assert!(grid.slopes(0, 0, &Vector3::new(1.0, 0.0, -0.1)).is_none());
    }
}
