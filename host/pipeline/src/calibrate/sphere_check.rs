//! A rig checked against a capture of a matte sphere of known size: the reconstruction should
//! give back the sphere's radius and normals.
//!
//! The sphere is found from its silhouette ([`super::sphere::find_sphere`], with the rig's
//! camera and the known radius). Over its pixels within [`INNER_SHARE`] of the silhouette's
//! radius that the reconstruction kept:
//!
//! * the **radius** is that of the sphere fitted to the reconstructed 3-D points (algebraic
//!   least squares, |X|² = 2 c·X + d, R² = d + |c|²: V. Pratt, "Direct least-squares fitting
//!   of algebraic surfaces", SIGGRAPH 1987), compared with the known one;
//! * the **normal error** is the angle between each reconstructed normal and the sphere's
//!   normal (X − C)/R where the pixel's ray meets the sphere found from the silhouette.
//!
//! A wrong LED position or intensity bends the normals (a tilt that varies over the sphere) and,
//! integrated, flattens or bulges the surface: the radius moves. The verdict compares both
//! with what a correct rig gives ([`MAX_NORMAL_ERROR_DEG`], [`MAX_RADIUS_ERROR`]).

use super::CalibrateError;
use super::sphere::{SphereFit, find_sphere};
use meb_core::rig::{Projection, Rig};
use meb_core::types::{DepthMap, NormalField};
use nalgebra::{DMatrix, DVector, Vector3};
use ndarray::Array2;

/// Sphere pixels used lie within this share of the silhouette's radius.
pub const INNER_SHARE: f64 = 0.9;

/// Largest mean normal error of a sphere reconstructed with a consistent rig, degrees. On a
/// Ø50 mm sphere (out-of-plane rig, 640×360, 64 frames, noise 1 %, gamma 2.2, noise seed 41)
/// the true rig gives 2.34°, LEDs 10 mm off 2.99°, 25 mm off 5.51°.
pub const MAX_NORMAL_ERROR_DEG: f64 = 4.0;

/// Largest relative radius error of a sphere reconstructed with a consistent rig (the same
/// captures: true rig +0.2 %, LEDs 10 mm off −0.9 %, 25 mm off −3.9 %).
pub const MAX_RADIUS_ERROR: f64 = 0.03;

/// Fewest reconstructed sphere pixels to judge by.
const MIN_PIXELS: usize = 200;

/// What [`check_sphere`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SphereCheck {
    /// The sphere's silhouette fit.
    pub sphere: SphereFit,
    /// The known radius, mm.
    pub radius_mm: f64,
    /// The radius of the sphere fitted to the reconstructed points, mm.
    pub recovered_radius_mm: f64,
    /// Mean angle between reconstructed and true normals, degrees.
    pub mean_normal_error_deg: f64,
    /// 95th percentile of that angle, degrees.
    pub p95_normal_error_deg: f64,
    /// Pixels compared.
    pub pixels: usize,
    /// Whether both figures are within what a consistent rig gives.
    pub consistent: bool,
}

impl SphereCheck {
    /// Relative error of the recovered radius.
    pub fn radius_error(&self) -> f64 {
        self.recovered_radius_mm / self.radius_mm - 1.0
    }
}

/// Checks a reconstruction (`normals`, `depth`) of a capture (LED `images`, level `noise`) of a
/// matte sphere of `diameter_mm` made with `rig` (module docs).
pub fn check_sphere(
    images: &[Array2<f32>],
    noise: &Array2<f32>,
    rig: &Rig,
    normals: &NormalField,
    depth: &DepthMap,
    diameter_mm: f64,
) -> Result<SphereCheck, CalibrateError> {
    if !(diameter_mm.is_finite() && diameter_mm > 0.0) {
        return Err(CalibrateError::Input(format!(
            "the sphere's diameter must be a positive length, got {diameter_mm} mm"
        )));
    }
    let radius = diameter_mm / 2.0;
    let (sphere, region) = find_sphere(images, noise, rig, radius)?;
    let projection = rig.camera.projection();
    let centre = Vector3::from(sphere.centre_mm);
    let [cx, cy] = sphere.centre_px;
    let inner = INNER_SHARE * sphere.radius_px;
    let mut angles = Vec::new();
    let mut points = Vec::new();
    for ((r, c), &m) in region.indexed_iter() {
        if !m || (c as f64 - cx).hypot(r as f64 - cy) >= inner {
            continue;
        }
        let n = normals.normals.slice(ndarray::s![r, c, ..]);
        let n = Vector3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]));
        let Some(point) = depth.point(r, c) else {
            continue;
        };
        if !(normals.mask[(r, c)] && n.iter().all(|v| v.is_finite())) {
            continue;
        }
        let Some(truth) = sphere_normal(&projection, r as f64, c as f64, &centre, radius) else {
            continue;
        };
        let cos = (n.normalize().dot(&truth)).clamp(-1.0, 1.0);
        angles.push(cos.acos().to_degrees());
        points.push(Vector3::new(
            f64::from(point[0]),
            f64::from(point[1]),
            f64::from(point[2]),
        ));
    }
    if angles.len() < MIN_PIXELS {
        return Err(CalibrateError::NoSphere(format!(
            "only {} of the sphere's pixels were reconstructed (at least {MIN_PIXELS} needed)",
            angles.len()
        )));
    }
    let recovered_radius_mm = fitted_radius(&points).ok_or_else(|| {
        CalibrateError::NoSphere("the reconstructed points do not fit a sphere".into())
    })?;
    let mean_normal_error_deg = angles.iter().sum::<f64>() / angles.len() as f64;
    let k = ((angles.len() - 1) as f64 * 0.95).round() as usize;
    let p95_normal_error_deg = *angles.select_nth_unstable_by(k, f64::total_cmp).1;
    let consistent = mean_normal_error_deg <= MAX_NORMAL_ERROR_DEG
        && (recovered_radius_mm / radius - 1.0).abs() <= MAX_RADIUS_ERROR;
    Ok(SphereCheck {
        sphere,
        radius_mm: radius,
        recovered_radius_mm,
        mean_normal_error_deg,
        p95_normal_error_deg,
        pixels: angles.len(),
        consistent,
    })
}

/// The unit normal of the sphere (`centre`, `radius`) where the ray of pixel (row, col) meets
/// it nearest the camera; `None` if it misses.
fn sphere_normal(
    projection: &Projection,
    row: f64,
    col: f64,
    centre: &Vector3<f64>,
    radius: f64,
) -> Option<Vector3<f64>> {
    let ray = projection.ray(row, col);
    let o = ray.base - centre;
    let (a, b, c) = (
        ray.slope.norm_squared(),
        2.0 * o.dot(&ray.slope),
        o.norm_squared() - radius * radius,
    );
    let disc = b * b - 4.0 * a * c;
    (disc >= 0.0).then(|| (ray.at((-b + disc.sqrt()) / (2.0 * a)) - centre) / radius)
}

/// The radius of the sphere fitted to `points` in algebraic least squares (module docs).
fn fitted_radius(points: &[Vector3<f64>]) -> Option<f64> {
    // Centred for conditioning.
    let mean = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let a = DMatrix::from_fn(points.len(), 4, |i, j| {
        let p = points[i] - mean;
        if j < 3 { 2.0 * p[j] } else { 1.0 }
    });
    let b = DVector::from_fn(points.len(), |i, _| (points[i] - mean).norm_squared());
    let x = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let r2 = x[3] + x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
    (r2 > 0.0).then(|| r2.sqrt())
}
