//! Finding a sphere of known size in a decoded capture: its lit pixels, their silhouette and
//! the sphere's centre in the scene.
//!
//! The object is the largest 4-connected region of pixels whose brightest LED image reads
//! above [`LIT_SIGMAS`] of the level noise. The LEDs light only part of it (the rest is in
//! attached shadow), so its boundary is the silhouette on the lit side and the shadow's edge
//! (the terminator) inside the disc on the other. The centre is fitted with the radius the
//! camera model gives the known diameter: on the plane z = 0 for an orthographic camera
//! (R/h pixels), at the distance where the silhouette's half-angle is arcsin(R/d) for a
//! pinhole camera. The fit minimises the boundary points' distances from the circle with
//! points well inside it (the terminator) trimmed: a few rounds of least squares over the
//! points within [`RIM_TOLERANCE_PX`] of the circle, started from the algebraic circle fit
//! of all boundary points (I. Kåsa, "A circle fitting procedure and its error analysis",
//! IEEE Transactions on Instrumentation and Measurement, 1976).

use super::CalibrateError;
use meb_core::rig::{Projection, Rig};
use nalgebra::{DMatrix, DVector, Vector3};
use ndarray::Array2;

/// A pixel belongs to the sphere when its brightest LED reads above this many noise σ.
pub const LIT_SIGMAS: f64 = 8.0;

/// Boundary points further inside the fitted circle than this are the terminator, not the rim.
pub const RIM_TOLERANCE_PX: f64 = 1.5;

/// Fewest pixels a sphere must cover.
pub const MIN_SPHERE_PIXELS: usize = 300;

/// A sphere found in one capture.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SphereFit {
    /// Centre in the scene, mm.
    pub centre_mm: [f64; 3],
    /// Radius, mm (the known one).
    pub radius_mm: f64,
    /// Centre in the image (column, row), pixels.
    pub centre_px: [f64; 2],
    /// Radius in the image, pixels.
    pub radius_px: f64,
    /// The radius a free circle fit of the rim gives, pixels (a check of the known size).
    pub free_radius_px: f64,
    /// RMS distance of the rim points from the circle, pixels.
    pub rim_rms_px: f64,
    /// Rim points used.
    pub rim_points: usize,
    /// Lit pixels of the sphere.
    pub pixels: usize,
}

/// Finds the sphere of `radius_mm` in LED `images` with level `noise` σ(p) seen by `rig`'s
/// camera (module docs). Returns the fit and the sphere's lit pixels.
pub fn find_sphere(
    images: &[Array2<f32>],
    noise: &Array2<f32>,
    rig: &Rig,
    radius_mm: f64,
) -> Result<(SphereFit, Array2<bool>), CalibrateError> {
    let (rows, cols) = noise.dim();
    let lit = Array2::from_shape_fn((rows, cols), |p| {
        let brightest = images.iter().map(|im| im[p]).fold(f32::MIN, f32::max);
        f64::from(brightest) > LIT_SIGMAS * f64::from(noise[p]).max(1e-6)
    });
    let region = largest_region(&lit);
    let pixels = region.iter().filter(|&&m| m).count();
    if pixels < MIN_SPHERE_PIXELS {
        return Err(CalibrateError::NoSphere(format!(
            "the largest lit region has {pixels} pixels (at least {MIN_SPHERE_PIXELS} needed)"
        )));
    }
    let mut boundary = Vec::new();
    let mut touches_edge = false;
    for ((r, c), &m) in region.indexed_iter() {
        if !m {
            continue;
        }
        let edge = r == 0 || c == 0 || r + 1 == rows || c + 1 == cols;
        touches_edge |= edge;
        let outside = edge
            || !region[(r - 1, c)]
            || !region[(r + 1, c)]
            || !region[(r, c - 1)]
            || !region[(r, c + 1)];
        if outside {
            boundary.push((c as f64, r as f64));
        }
    }
    if touches_edge {
        return Err(CalibrateError::NoSphere(
            "the sphere reaches the image's edge (clipped): place it wholly in view".into(),
        ));
    }
    let projection = rig.camera.projection();
    let (cx0, cy0, r0) = kasa(&boundary)
        .ok_or_else(|| CalibrateError::NoSphere("the lit region's boundary is not round".into()))?;
    // The radius in pixels the known size gives, at the distance of the free fit's centre.
    let radius_px_at = |cx: f64, cy: f64| -> (f64, Vector3<f64>) {
        match projection {
            Projection::Orthographic { pitch_mm, .. } => {
                let base = projection.ray(cy, cx).base;
                (radius_mm / pitch_mm, base)
            }
            Projection::Perspective {
                intrinsics,
                distance_mm,
            } => {
                // The silhouette's half-angle α: tan α = r·/f; the centre lies R/sin α away.
                let f = 0.5 * (intrinsics.fx + intrinsics.fy);
                let (x, y) = intrinsics.normalised(cy, cx);
                let direction = Vector3::new(x, -y, -1.0).normalize();
                let d = radius_mm / (r0 / f).atan().sin();
                let centre = Vector3::new(0.0, 0.0, distance_mm) + direction * d;
                (r0, centre)
            }
        }
    };
    let (mut cx, mut cy) = (cx0, cy0);
    let (mut radius_px, _) = radius_px_at(cx, cy);
    if matches!(projection, Projection::Perspective { .. }) {
        radius_px = r0;
    }
    let mut rim: Vec<(f64, f64)> = boundary.clone();
    for _ in 0..6 {
        rim = boundary
            .iter()
            .copied()
            .filter(|&(x, y)| (x - cx).hypot(y - cy) - radius_px > -RIM_TOLERANCE_PX)
            .collect();
        if rim.len() < 20 {
            return Err(CalibrateError::NoSphere(format!(
                "only {} boundary points lie on a circle of the sphere's size ({radius_px:.1} px): \
                 is --sphere-mm right, and the sphere the largest lit object?",
                rim.len()
            )));
        }
        (cx, cy) = centre_with_radius(&rim, cx, cy, radius_px);
        if matches!(projection, Projection::Perspective { .. }) {
            radius_px = kasa(&rim).map_or(radius_px, |k| k.2 + 0.5);
        }
    }
    let rim_rms_px = (rim
        .iter()
        .map(|&(x, y)| ((x - cx).hypot(y - cy) - radius_px).powi(2))
        .sum::<f64>()
        / rim.len() as f64)
        .sqrt();
    let free_radius_px = kasa(&rim).map_or(f64::NAN, |k| k.2 + 0.5);
    let (_, mut centre) = radius_px_at(cx, cy);
    if matches!(projection, Projection::Orthographic { .. }) {
        centre.z = 0.0;
    }
    Ok((
        SphereFit {
            centre_mm: [centre.x, centre.y, centre.z],
            radius_mm,
            centre_px: [cx, cy],
            radius_px,
            free_radius_px,
            rim_rms_px,
            rim_points: rim.len(),
            pixels,
        },
        region,
    ))
}

/// The largest 4-connected region of `mask`.
fn largest_region(mask: &Array2<bool>) -> Array2<bool> {
    let (rows, cols) = mask.dim();
    let mut label = Array2::from_elem((rows, cols), 0u32);
    let (mut best, mut best_size, mut next) = (0u32, 0usize, 0u32);
    let mut stack = Vec::new();
    for start in 0..rows * cols {
        let p = (start / cols, start % cols);
        if !mask[p] || label[p] != 0 {
            continue;
        }
        next += 1;
        let mut size = 0;
        label[p] = next;
        stack.push(p);
        while let Some((r, c)) = stack.pop() {
            size += 1;
            let neighbours = [
                (r.wrapping_sub(1), c),
                (r + 1, c),
                (r, c.wrapping_sub(1)),
                (r, c + 1),
            ];
            for q in neighbours {
                if q.0 < rows && q.1 < cols && mask[q] && label[q] == 0 {
                    label[q] = next;
                    stack.push(q);
                }
            }
        }
        if size > best_size {
            (best, best_size) = (next, size);
        }
    }
    label.mapv(|l| l != 0 && l == best)
}

/// The algebraic circle fit (Kåsa) of `points` (x, y): centre and radius, pixels.
fn kasa(points: &[(f64, f64)]) -> Option<(f64, f64, f64)> {
    if points.len() < 3 {
        return None;
    }
    let a = DMatrix::from_fn(points.len(), 3, |i, j| match j {
        0 => points[i].0,
        1 => points[i].1,
        _ => 1.0,
    });
    let b = DVector::from_fn(points.len(), |i, _| {
        -(points[i].0.powi(2) + points[i].1.powi(2))
    });
    let solution = a.svd(true, true).solve(&b, 1e-12).ok()?;
    let (cx, cy) = (-solution[0] / 2.0, -solution[1] / 2.0);
    let r2 = cx * cx + cy * cy - solution[2];
    (r2 > 0.0).then(|| (cx, cy, r2.sqrt()))
}

/// The centre (x, y) of the circle of `radius` nearest `points` in least squares (Gauss–Newton
/// from `cx`, `cy`). Boundary pixel centres lie half a pixel inside the silhouette.
fn centre_with_radius(points: &[(f64, f64)], mut cx: f64, mut cy: f64, radius: f64) -> (f64, f64) {
    let r = radius - 0.5;
    for _ in 0..20 {
        let (mut jtj, mut jtr) = (nalgebra::Matrix2::zeros(), nalgebra::Vector2::zeros());
        for &(x, y) in points {
            let d = (x - cx).hypot(y - cy).max(1e-9);
            let residual = d - r;
            let j = nalgebra::Vector2::new(-(x - cx) / d, -(y - cy) / d);
            jtj += j * j.transpose();
            jtr += j * residual;
        }
        let Some(step) = jtj.try_inverse().map(|inv| -(inv * jtr)) else {
            break;
        };
        cx += step.x;
        cy += step.y;
        if step.norm() < 1e-6 {
            break;
        }
    }
    (cx, cy)
}
