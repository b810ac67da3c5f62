//! Typed values passed between pipeline stages: per-LED images, normal fields, depth maps.
//!
//! Images are `ndarray` arrays indexed `[row, column]`, row 0 at the top of the picture.
//! Scene coordinates follow docs/maths/coordinates.md#the-scene-frame: x to the right, y up
//! (towards row 0), z towards the
//! camera, millimetres, origin at the object centre.

use ndarray::{Array2, Array3};

/// One image per LED, each the on-level A_i as a fraction of full scale
/// (docs/maths/demodulation.md#the-received-signal), as if that
/// LED alone were lit and the background removed.
#[derive(Debug, Clone, PartialEq)]
pub struct LedImages {
    /// `images[i]` is LED i+1's image, all of the same shape.
    pub images: Vec<Array2<f32>>,
}

impl LedImages {
    /// Image height and width, or `None` when empty.
    pub fn shape(&self) -> Option<(usize, usize)> {
        self.images.first().map(|im| im.dim())
    }

    /// The brightest LED's value at each pixel of row `r`, written to `out` (one value per
    /// column): the maximum over the LED images, NaN values ignored (−∞ where every image
    /// is NaN or there is none). Contiguous rows are read as slices, which the compiler
    /// vectorises.
    pub fn brightest_in_row(&self, r: usize, out: &mut [f32]) {
        out.fill(f32::NEG_INFINITY);
        for image in &self.images {
            let row = image.row(r);
            match row.as_slice() {
                Some(values) => out.iter_mut().zip(values).for_each(|(b, &v)| *b = b.max(v)),
                None => out.iter_mut().zip(&row).for_each(|(b, &v)| *b = b.max(v)),
            }
        }
    }
}

/// Unit surface normals and albedo per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalField {
    /// H×W×3 unit normals (x, y, z) in scene coordinates; NaN where not estimated.
    pub normals: Array3<f32>,
    /// H×W albedo ρ (relative units); NaN where not estimated.
    pub albedo: Array2<f32>,
    /// Pixels where the normal was estimated.
    pub mask: Array2<bool>,
}

/// A depth map on the camera's pixel grid.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthMap {
    /// H×W depth z in mm towards the camera; NaN where not reconstructed.
    pub depth_mm: Array2<f32>,
    /// Grid pitch h in mm per pixel (for a perspective camera: on the plane z = 0).
    pub pitch_mm: f64,
    /// The pinhole camera that saw it, `None` for the orthographic grid.
    pub perspective: Option<crate::rig::Projection>,
}

impl DepthMap {
    /// The 3-D point of pixel (row, col) in mm, `None` where there is no depth: on the
    /// orthographic grid (x right, y up, z towards the camera, origin at the image centre), or
    /// for a perspective camera in metric camera coordinates (origin at the camera centre, x
    /// right, y down, z along the optical axis, as OpenCV's).
    pub fn point(&self, row: usize, col: usize) -> Option<[f32; 3]> {
        let z = *self.depth_mm.get((row, col))?;
        if !z.is_finite() {
            return None;
        }
        match &self.perspective {
            Some(projection @ crate::rig::Projection::Perspective { distance_mm, .. }) => {
                let p = projection.ray(row as f64, col as f64).at(f64::from(z));
                Some([p.x as f32, -p.y as f32, (distance_mm - p.z) as f32])
            }
            _ => {
                let (rows, cols) = self.depth_mm.dim();
                let h = self.pitch_mm as f32;
                let x = (col as f32 + 0.5 - cols as f32 / 2.0) * h;
                let y = (rows as f32 / 2.0 - row as f32 - 0.5) * h;
                Some([x, y, z])
            }
        }
    }
}

/// A pixel lit by exactly two LEDs: its normal n lies on the great circle n·`across` = 0
/// (across = A₂·L₁ − A₁·L₂ for values A and light vectors L) on the side n·`towards` > 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalPlane {
    /// Pixel (row, column).
    pub pixel: (usize, usize),
    /// The normal is perpendicular to it.
    pub across: nalgebra::Vector3<f64>,
    /// The normal has a positive component along it (e.g. L₁/|L₁| + L₂/|L₂|).
    pub towards: nalgebra::Vector3<f64>,
    /// g₀: the albedo-scaled normal ρn of least norm that fits both readings (in the plane of
    /// L₁ and L₂, on the circle); with albedo ρ ≥ |g₀| the normal is g₀/ρ ± √(1 − |g₀|²/ρ²)·ĉ
    /// for the unit ĉ on the circle perpendicular to g₀ (zero when unknown).
    pub least_albedo: nalgebra::Vector3<f64>,
}

/// Largest angle between a two-LED pixel's normal and the middle of its lit half-circle.
const MAX_TILT_RAD: f64 = 80.0 * std::f64::consts::PI / 180.0;

impl NormalPlane {
    /// The normal on the circle nearest `n` in angle, within \[`MAX_TILT_RAD`\] of the direction
    /// of `towards` in the plane; `None` when the constraint is degenerate or `n` is not finite.
    ///
    /// With e₁ the direction of `towards` in the circle's plane and e₂ = m̂ × e₁, `n` lies at the
    /// angle θ = atan2(n·e₂, n·e₁) of the circle; the answer is at θ clamped to ±α. Within the
    /// limit (cos θ ≥ cos α) that is the in-plane part of `n` normalised, beyond it the limit on
    /// the side of n·e₂, so no angle is computed (atan2 and sin/cos were 1.5 % of `meb video`'s
    /// CPU).
    pub fn project(&self, n: &nalgebra::Vector3<f64>) -> Option<nalgebra::Vector3<f64>> {
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
    pub fn with_albedo(
        &self,
        albedo: f64,
        n: &nalgebra::Vector3<f64>,
    ) -> Option<nalgebra::Vector3<f64>> {
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

/// How a reconstructed pixel's depth is known (written as `confidence.npy`, one byte a pixel).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
#[repr(u8)]
pub enum Confidence {
    /// 0: not reconstructed.
    #[default]
    None = 0,
    /// 1: filled by the integrator (a hole inside the object, lit by fewer than two LEDs).
    Filled = 1,
    /// 2: lit by two LEDs; normal from the two measurements and the surface's integrability.
    TwoLeds = 2,
    /// 3: full photometric-stereo normal from three or more LEDs.
    Measured = 3,
}

/// Reconstructed pixels by how their depth is known (`confidence.npy`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ConfidenceCounts {
    /// Full photometric-stereo normal from three or more LEDs.
    pub measured: usize,
    /// Lit by two LEDs: normal from the two measurements and the surface's integrability.
    pub two_leds: usize,
    /// Holes inside the object filled by the integrator.
    pub filled: usize,
}

impl ConfidenceCounts {
    /// Counts the pixels of each reconstructed class.
    pub fn of(confidence: &Array2<Confidence>) -> Self {
        let count = |k: Confidence| confidence.iter().filter(|&&c| c == k).count();
        Self {
            measured: count(Confidence::Measured),
            two_leds: count(Confidence::TwoLeds),
            filled: count(Confidence::Filled),
        }
    }

    /// Share of the reconstructed pixels measured by three or more LEDs (0 when none is).
    pub fn measured_share(&self) -> f64 {
        let reconstructed = self.measured + self.two_leds + self.filled;
        if reconstructed == 0 {
            0.0
        } else {
            self.measured as f64 / reconstructed as f64
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The brightest value ignores NaN images, is −∞ where all are NaN, and reads a
    /// column-major image (rows not contiguous) as a row-major one.
    #[test]
    fn the_brightest_led_of_a_row_ignores_nan_and_any_layout() {
        let a =
            Array2::from_shape_vec((2, 3), vec![0.1, f32::NAN, 0.5, 0.2, f32::NAN, 0.0]).unwrap();
        let b = Array2::from_shape_vec((2, 3), vec![0.3, f32::NAN, 0.4, 0.1, 0.7, -1.0]).unwrap();
        let column_major = crate::layouts::column_major(&b);
        let mut out = [0.0f32; 3];
        for second in [b, column_major] {
            let images = LedImages {
                images: vec![a.clone(), second],
            };
            images.brightest_in_row(0, &mut out);
            assert_eq!(out[0], 0.3);
            assert_eq!(out[1], f32::NEG_INFINITY);
            assert_eq!(out[2], 0.5);
            images.brightest_in_row(1, &mut out);
            assert_eq!(out, [0.2, 0.7, 0.0]);
        }
        LedImages { images: Vec::new() }.brightest_in_row(0, &mut out);
        assert_eq!(out, [f32::NEG_INFINITY; 3]);
    }
}

#[cfg(test)]
mod normal_plane_tests {
    use super::*;
    use nalgebra::Vector3;

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
