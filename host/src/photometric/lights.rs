//! Light vectors per pixel: the distant model L_i = L_i(0) or the near-field L_i(X(p)) with
//! X(p) = (x, y, z(p)) from the current depth estimate (SPEC §5, thesis Eq. 3.3).

use crate::rig::Rig;
use nalgebra::Vector3;
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
            Lights::NearField {
                rig,
                depth_mm,
                scale,
            } => {
                let (x, y) = rig.camera.pixel_centre_xy(row as f64, col as f64);
                let z = depth_mm
                    .and_then(|d| d.get((row, col)).copied())
                    .filter(|z| z.is_finite())
                    .map_or(0.0, f64::from);
                let point = Vector3::new(x, y, z);
                for (slot, led) in out.iter_mut().zip(&rig.leds) {
                    *slot = led.light_vector_at(&point) * *scale;
                }
            }
        }
    }
}
