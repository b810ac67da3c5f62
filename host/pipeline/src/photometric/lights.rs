//! Light and view vectors per pixel: the distant model L_i = L_i(0) or the near-field L_i(X(p))
//! with X(p) the point of pixel p's ray at the current depth estimate z(p)
//! (docs/maths/photometric-stereo.md#light-vectors, thesis
//! Eq. 3.3; for a perspective camera the ray runs through the camera centre), and checks of the
//! light geometry (three independent directions are needed).

use super::PhotometricError;
use meb_core::rig::{Emitter, PixelRay, Projection, Rig};
use nalgebra::{DMatrix, Vector3};
use ndarray::Array2;

/// Where each pixel's light vectors come from.
#[derive(Debug, Clone)]
pub enum Lights<'a> {
    /// The same vectors for every pixel (distant lights, e.g. DiLiGenT's directions).
    Distant(Vec<Vector3<f64>>),
    /// Per-pixel vectors from the rig's LED positions and a depth estimate (NaN or absent → z = 0).
    NearField {
        /// The rig (camera grid and LEDs).
        rig: &'a Rig,
        /// Current depth estimate z(p) in mm, or `None` for the plane z = 0.
        depth_mm: Option<&'a Array2<f32>>,
        /// Factor applied to every vector (see [`Lights::near_field_scale`]).
        scale: f64,
        /// Every point moved this far towards the camera (see [`moved_depth`]).
        offset_mm: f64,
        /// The camera's projection, computed once.
        projection: Projection,
        /// The rig's LEDs prepared for per-point light vectors, in LED order.
        emitters: Vec<Emitter>,
    },
}

impl<'a> Lights<'a> {
    /// Near-field lights of `rig` at the depth estimate `depth_mm`, scaled so that albedo comes
    /// out in image units.
    pub fn near_field(rig: &'a Rig, depth_mm: Option<&'a Array2<f32>>) -> Self {
        Lights::NearField {
            rig,
            depth_mm,
            scale: Self::near_field_scale(rig),
            offset_mm: 0.0,
            projection: rig.camera.projection(),
            emitters: rig.leds.iter().map(|led| led.emitter()).collect(),
        }
    }

    /// The same lights with every point moved `offset_mm` towards the camera.
    pub fn moved(self, offset_mm: f64) -> Self {
        match self {
            Lights::NearField {
                rig,
                depth_mm,
                scale,
                projection,
                emitters,
                ..
            } => Lights::NearField {
                rig,
                depth_mm,
                scale,
                offset_mm,
                projection,
                emitters,
            },
            distant => distant,
        }
    }
}

impl Lights<'_> {
    /// Number of lights.
    pub fn count(&self) -> usize {
        match self {
            Lights::Distant(v) => v.len(),
            Lights::NearField { rig, .. } => rig.leds.len(),
        }
    }

    /// Whether every pixel has the same light vectors.
    pub fn is_distant(&self) -> bool {
        matches!(self, Lights::Distant(_))
    }

    /// Scale applied to near-field vectors so that albedo comes out in image units
    /// (1 / mean |L_i(0)|); 1 for distant lights.
    pub fn near_field_scale(rig: &Rig) -> f64 {
        let norms: Vec<f64> = rig
            .distant_light_vectors()
            .iter()
            .map(|l| l.norm())
            .collect();
        let mean = norms.iter().sum::<f64>() / norms.len().max(1) as f64;
        if mean > 0.0 && mean.is_finite() {
            1.0 / mean
        } else {
            1.0
        }
    }

    /// Writes the light vectors at pixel (row, col) into `out` (length [`Self::count`]).
    pub fn at(&self, row: usize, col: usize, out: &mut [Vector3<f64>]) {
        match self {
            Lights::Distant(v) => out.copy_from_slice(v),
            Lights::NearField { projection, .. } => {
                let z = self.depth_at(row, col);
                self.at_point(&projection.ray(row as f64, col as f64).at(z), out);
            }
        }
    }

    /// Height z in mm of pixel (row, col)'s surface point: the depth estimate (0 where it is
    /// absent or NaN) moved by the lights' offset; 0 for distant lights.
    pub fn depth_at(&self, row: usize, col: usize) -> f64 {
        match self {
            Lights::Distant(_) => 0.0,
            Lights::NearField {
                depth_mm,
                offset_mm,
                projection,
                ..
            } => {
                let z = depth_mm
                    .and_then(|d| d.get((row, col)).copied())
                    .filter(|z| z.is_finite())
                    .map_or(0.0, f64::from);
                moved_depth(z, *offset_mm, projection)
            }
        }
    }

    /// The camera's projection of near-field lights (`None` for distant ones).
    pub fn projection(&self) -> Option<&Projection> {
        match self {
            Lights::Distant(_) => None,
            Lights::NearField { projection, .. } => Some(projection),
        }
    }

    /// Writes the near-field light vectors at scene point `point` into `out` (length
    /// [`Self::count`]); distant lights ignore the point.
    pub fn at_point(&self, point: &Vector3<f64>, out: &mut [Vector3<f64>]) {
        match self {
            Lights::Distant(v) => out.copy_from_slice(v),
            Lights::NearField {
                scale, emitters, ..
            } => {
                for (slot, emitter) in out.iter_mut().zip(emitters) {
                    *slot = emitter.light_vector_at(point) * *scale;
                }
            }
        }
    }

    /// The ray of pixel (row, col): the scene points it sees (a vertical ray for distant
    /// lights, whose vectors do not depend on the point).
    pub fn ray(&self, row: usize, col: usize) -> PixelRay {
        match self {
            Lights::Distant(_) => PixelRay {
                base: Vector3::zeros(),
                slope: Vector3::z(),
            },
            Lights::NearField { projection, .. } => projection.ray(row as f64, col as f64),
        }
    }

    /// Unit vector from pixel (row, col)'s surface point towards the camera.
    pub fn view_at(&self, row: usize, col: usize) -> Vector3<f64> {
        match self {
            Lights::Distant(_) => Vector3::z(),
            Lights::NearField { projection, .. } => {
                projection.ray(row as f64, col as f64).towards_camera()
            }
        }
    }

    /// One light vector per LED for geometry checks: the distant vectors, or L_i at the origin.
    fn representative(&self) -> Vec<Vector3<f64>> {
        match self {
            Lights::Distant(v) => v.clone(),
            Lights::NearField { rig, .. } => rig.distant_light_vectors(),
        }
    }

    /// Checks the vectors are finite and non-zero and that a near-field rig and depth fit
    /// images of `shape`.
    pub fn check(&self, shape: (usize, usize)) -> Result<(), PhotometricError> {
        match self {
            Lights::Distant(v) => {
                for (i, l) in v.iter().enumerate() {
                    if !l.iter().all(|c| c.is_finite()) || l.norm() == 0.0 {
                        return Err(PhotometricError::BadLight(i + 1));
                    }
                }
            }
            Lights::NearField { rig, depth_mm, .. } => {
                let cam = (rig.camera.height, rig.camera.width);
                if cam != shape {
                    return Err(PhotometricError::SizeMismatch {
                        what: "LED images vs the rig's camera".into(),
                        got_rows: shape.0,
                        got_cols: shape.1,
                        rows: cam.0,
                        cols: cam.1,
                    });
                }
                if let Some(d) = depth_mm {
                    super::check_shape("depth estimate", d, shape)?;
                }
            }
        }
        Ok(())
    }
}

/// Depth `z` moved `offset` mm towards the camera: a shift for an orthographic camera, a scale
/// about the camera centre for a perspective one (the plane z = 0 moves by `offset`), so that
/// a surface integrated from normals keeps its shape.
pub fn moved_depth(z: f64, offset: f64, projection: &Projection) -> f64 {
    match projection {
        Projection::Orthographic { .. } => z + offset,
        Projection::Perspective { distance_mm, .. } => {
            distance_mm - (distance_mm - z) * (1.0 - offset / distance_mm)
        }
    }
}

/// Numerical rank of the light vectors (singular values above 10⁻⁶ of the largest).
pub(crate) fn light_rank(lights: &Lights) -> usize {
    let v = lights.representative();
    if v.is_empty() {
        return 0;
    }
    let m = DMatrix::from_fn(v.len(), 3, |i, j| {
        v[i][j] / v[i].norm().max(f64::MIN_POSITIVE)
    });
    let singular = m.singular_values();
    let largest = singular.max();
    singular.iter().filter(|&&s| s > 1e-6 * largest).count()
}

/// What is wrong with the light geometry, in words: its rank, parallel (duplicated) pairs and
/// vectors pointing away from the camera.
pub(crate) fn describe_geometry(lights: &Lights) -> String {
    let v = lights.representative();
    let mut parts = vec![match light_rank(lights) {
        0 | 1 => "all light vectors point the same way".to_string(),
        2 => "the light vectors span only a plane (coplanar or collinear LEDs)".to_string(),
        _ => "the light vectors span space".to_string(),
    }];
    for i in 0..v.len() {
        for j in i + 1..v.len() {
            let (a, b) = (v[i].normalize(), v[j].normalize());
            if a.cross(&b).norm() < 1e-6 {
                let how = if a.dot(&b) > 0.0 {
                    "parallel (duplicated?)"
                } else {
                    "opposite"
                };
                parts.push(format!("LEDs {} and {} are {how}", i + 1, j + 1));
            }
        }
    }
    let away: Vec<String> = v
        .iter()
        .enumerate()
        .filter(|(_, l)| l.z < 0.0)
        .map(|(i, _)| (i + 1).to_string())
        .collect();
    if !away.is_empty() {
        parts.push(format!(
            "LED {} points away from the camera (negative intensity?)",
            away.join(", ")
        ));
    }
    parts.join("; ")
}
