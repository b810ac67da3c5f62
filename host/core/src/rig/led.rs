//! One LED: position, emission axis, relative intensity and Lambert order, and its light
//! vector at a surface point (module docs of [`super`]).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// One LED of the rig.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Led {
    /// Position P_i in mm.
    pub position_mm: [f64; 3],
    /// Emission axis (any length); default: pointing at the origin.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<[f64; 3]>,
    /// Relative intensity Φ_i.
    #[serde(default = "one")]
    pub intensity: f64,
    /// Lambert order m of the emission profile cos^m θ.
    #[serde(default = "one")]
    pub lambert_order: f64,
}

fn one() -> f64 {
    1.0
}

impl Led {
    /// Position as a vector.
    pub fn position(&self) -> Vector3<f64> {
        Vector3::from(self.position_mm)
    }

    /// Unit emission axis.
    pub fn unit_axis(&self) -> Vector3<f64> {
        match self.axis {
            Some(a) => Vector3::from(a).normalize(),
            None => (-self.position()).normalize(),
        }
    }

    /// Light vector L_i(X) at scene point `point` (module docs): direction to the LED scaled
    /// by Φ·cos^m θ / d². Zero behind the LED's emitting hemisphere.
    pub fn light_vector_at(&self, point: &Vector3<f64>) -> Vector3<f64> {
        self.emitter().light_vector_at(point)
    }

    /// The LED's geometry with its emission axis normalised once, for loops that evaluate
    /// light vectors at many points.
    pub fn emitter(&self) -> Emitter {
        Emitter {
            position: self.position(),
            axis: self.unit_axis(),
            intensity: self.intensity,
            lambert_order: self.lambert_order,
        }
    }
}

/// An LED prepared for evaluating light vectors: position, unit emission axis, intensity Φ
/// and Lambert order m (see [`Led`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Emitter {
    /// Position P_i in mm.
    pub position: Vector3<f64>,
    /// Unit emission axis.
    pub axis: Vector3<f64>,
    /// Relative intensity Φ_i.
    pub intensity: f64,
    /// Lambert order m of the emission profile cos^m θ.
    pub lambert_order: f64,
}

impl Emitter {
    /// Light vector L_i(X) at scene point `point` (module docs): direction to the LED scaled
    /// by Φ·cos^m θ / d². Zero behind the LED's emitting hemisphere.
    #[inline]
    pub fn light_vector_at(&self, point: &Vector3<f64>) -> Vector3<f64> {
        let to_led = self.position - point;
        let d2 = to_led.norm_squared();
        // d·cos θ: the distance along the emission axis.
        let along_axis = -self.axis.dot(&to_led);
        if along_axis <= 0.0 {
            return Vector3::zeros();
        }
        // m = 1 (a Lambertian emitter, every preset) is the common case, and the near-field
        // loops call this per pixel and LED: Φ·cos θ/d³ = Φ·(d·cos θ)/d⁴ needs neither the
        // square root nor powf.
        if self.lambert_order == 1.0 {
            return to_led * (self.intensity * along_axis / (d2 * d2));
        }
        let inv_d = 1.0 / d2.sqrt();
        let falloff = (along_axis * inv_d).powf(self.lambert_order);
        to_led * (self.intensity * falloff * inv_d / d2)
    }
}
