//! Camera and LED geometry of a capture rig (TOML files and the thesis' rigs as presets).
//!
//! Coordinates (SPEC §5): origin at the object centre, x right, y up, z towards the camera,
//! millimetres. The camera is orthographic and looks along −z from `distance_mm`.
//! An LED at P_i with axis a_i, relative intensity Φ_i and Lambert order m lights a surface
//! point X along the light vector (SPEC §5, thesis Eq. 3.3 generalised to the near field)
//!
//! ```text
//! L_i(X) = Φ_i · cos^m(θ_i) / |P_i − X|² · (P_i − X)/|P_i − X|,   cos θ_i = a_i · (X − P_i)/|X − P_i|
//! ```
//!
//! and the distant-light model of the thesis is `L_i(0)`.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;
use thiserror::Error;

/// Names of the built-in rigs (SPEC §7).
pub const PRESETS: [&str; 4] = [
    "thesis-in-plane",
    "thesis-out-of-plane",
    "thesis-dynamic",
    "thesis-hybrid",
];

/// Errors loading or validating a rig.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum RigError {
    /// The rig file could not be read.
    #[error("cannot read rig file {path}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The TOML does not parse into a rig.
    #[error("rig file {path}: {message}")]
    Parse {
        /// The file (or preset name).
        path: String,
        /// The parser's message.
        message: String,
    },
    /// A value is out of range; names the field.
    #[error("rig field `{field}`: {reason}")]
    Invalid {
        /// Dotted path of the field, e.g. `led[2].position_mm`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// Neither a file nor a preset of that name exists.
    #[error("no rig file or preset named `{0}` (presets: {presets})", presets = PRESETS.join(", "))]
    UnknownPreset(String),
}

/// Orthographic camera looking along −z.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Frame rate in frames per second.
    pub fps: f64,
    /// Distance from the object centre along +z, mm.
    pub distance_mm: f64,
    /// Horizontal field of view in degrees (used when `pixel_pitch_mm` is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    /// Grid pitch on the object plane, mm per pixel (overrides `fov_deg`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_pitch_mm: Option<f64>,
}

impl Camera {
    /// Grid pitch h in mm per pixel: `pixel_pitch_mm`, else h = 2·d·tan(FOV/2)/width (SPEC §6).
    pub fn pitch_mm(&self) -> f64 {
        match (self.pixel_pitch_mm, self.fov_deg) {
            (Some(h), _) => h,
            (None, Some(fov)) => {
                2.0 * self.distance_mm * (fov.to_radians() / 2.0).tan() / self.width as f64
            }
            (None, None) => f64::NAN,
        }
    }

    /// Scene (x, y) in mm of the centre of pixel (row, col).
    pub fn pixel_centre_xy(&self, row: f64, col: f64) -> (f64, f64) {
        let h = self.pitch_mm();
        let x = (col + 0.5 - self.width as f64 / 2.0) * h;
        let y = (self.height as f64 / 2.0 - row - 0.5) * h;
        (x, y)
    }

    /// Continuous (row, col) of scene point (x, y); inverse of [`Self::pixel_centre_xy`].
    pub fn xy_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let h = self.pitch_mm();
        let col = x / h + self.width as f64 / 2.0 - 0.5;
        let row = self.height as f64 / 2.0 - y / h - 0.5;
        (row, col)
    }
}

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
        let to_led = self.position() - point;
        let d2 = to_led.norm_squared();
        let dir = to_led / d2.sqrt();
        let cos_theta = self.unit_axis().dot(&(-dir));
        if cos_theta <= 0.0 {
            return Vector3::zeros();
        }
        // m = 1 (a Lambertian emitter, every preset) is the common case: powf costs more than
        // the rest of this function and the near-field loops call it per pixel and LED.
        let falloff = if self.lambert_order == 1.0 {
            cos_theta
        } else {
            cos_theta.powf(self.lambert_order)
        };
        dir * (self.intensity * falloff / d2)
    }
}

/// A capture rig: one camera and its LEDs, in LED order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    /// The camera.
    pub camera: Camera,
    /// LEDs, LED 1 first.
    #[serde(rename = "led")]
    pub leds: Vec<Led>,
}

impl Rig {
    /// Parses and validates a rig from TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, RigError> {
        let rig: Rig = toml::from_str(text).map_err(|e| RigError::Parse {
            path: origin.to_string(),
            message: e.to_string(),
        })?;
        rig.validate()?;
        Ok(rig)
    }

    /// Loads a rig from a TOML file, or a built-in preset when `spec` names one.
    pub fn load(spec: &str) -> Result<Self, RigError> {
        if let Some(rig) = Self::preset(spec) {
            return Ok(rig);
        }
        let path = Path::new(spec);
        if !path.exists() {
            return Err(RigError::UnknownPreset(spec.to_string()));
        }
        let text = std::fs::read_to_string(path).map_err(|source| RigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, spec)
    }

    /// The rig as TOML text (round-trips through [`Self::from_toml_str`]).
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }

    /// A built-in thesis rig by name (SPEC §7), or `None`.
    pub fn preset(name: &str) -> Option<Self> {
        let out_of_plane_leds = [
            [-270.0, 420.0, 100.0],
            [-140.0, 420.0, 350.0],
            [140.0, 420.0, 350.0],
            [270.0, 420.0, 100.0],
        ];
        let phone = |distance_mm: f64, fov_deg: f64, fps: f64| Camera {
            width: 1280,
            height: 720,
            fps,
            distance_mm,
            fov_deg: Some(fov_deg),
            pixel_pitch_mm: None,
        };
        let (camera, positions): (Camera, Vec<[f64; 3]>) = match name {
            // Four LEDs 100 mm left/right/top/bottom of a camera looking down from 460 mm.
            // The thesis does not give this rig's FOV; the out-of-plane phone's 43° is assumed.
            "thesis-in-plane" => (
                phone(460.0, 43.0, 960.0),
                vec![
                    [-100.0, 0.0, 460.0],
                    [100.0, 0.0, 460.0],
                    [0.0, 100.0, 460.0],
                    [0.0, -100.0, 460.0],
                ],
            ),
            "thesis-out-of-plane" => (phone(420.0, 43.0, 960.0), out_of_plane_leds.to_vec()),
            "thesis-dynamic" => (phone(420.0, 43.0, 1000.0), out_of_plane_leds.to_vec()),
            "thesis-hybrid" => (
                phone(500.0, 32.0, 960.0),
                vec![
                    [-145.0, 90.0, 250.0],
                    [-145.0, -50.0, 250.0],
                    [145.0, 90.0, 250.0],
                    [145.0, -50.0, 250.0],
                ],
            ),
            _ => return None,
        };
        let leds = positions
            .into_iter()
            .map(|position_mm| Led {
                position_mm,
                axis: None,
                intensity: 1.0,
                lambert_order: 1.0,
            })
            .collect();
        Some(Self { camera, leds })
    }

    /// Distant-light vectors L_i = L_i(0) of SPEC §5, one per LED.
    pub fn distant_light_vectors(&self) -> Vec<Vector3<f64>> {
        self.leds
            .iter()
            .map(|led| led.light_vector_at(&Vector3::zeros()))
            .collect()
    }

    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), RigError> {
        let bad = |field: &str, reason: &str| RigError::Invalid {
            field: field.to_string(),
            reason: reason.to_string(),
        };
        let c = &self.camera;
        if c.width == 0 || c.height == 0 {
            return Err(bad("camera.width/height", "must be positive"));
        }
        if !(c.fps.is_finite() && c.fps > 0.0) {
            return Err(bad("camera.fps", "must be a positive number"));
        }
        if !(c.distance_mm.is_finite() && c.distance_mm > 0.0) {
            return Err(bad("camera.distance_mm", "must be a positive number"));
        }
        match (c.pixel_pitch_mm, c.fov_deg) {
            (Some(h), _) if !(h.is_finite() && h > 0.0) => {
                return Err(bad("camera.pixel_pitch_mm", "must be a positive number"));
            }
            (None, Some(f)) if !(f.is_finite() && f > 0.0 && f < 180.0) => {
                return Err(bad("camera.fov_deg", "must be in (0, 180) degrees"));
            }
            (None, None) => {
                return Err(bad("camera", "needs `fov_deg` or `pixel_pitch_mm`"));
            }
            _ => {}
        }
        if self.leds.is_empty() || self.leds.len() > protocol::carriers::MAX_LEDS {
            return Err(bad("led", "a rig has 1 to 8 LEDs"));
        }
        for (i, led) in self.leds.iter().enumerate() {
            let name = |f: &str| format!("led[{}].{f}", i + 1);
            let p = led.position();
            if !p.iter().all(|v| v.is_finite()) || p.norm() < 1e-9 {
                return Err(bad(
                    &name("position_mm"),
                    "must be finite and not at the origin",
                ));
            }
            if let Some(a) = led.axis {
                let a = Vector3::from(a);
                if !a.iter().all(|v| v.is_finite()) || a.norm() < 1e-12 {
                    return Err(bad(&name("axis"), "must be a finite non-zero vector"));
                }
            }
            if !(led.intensity.is_finite() && led.intensity > 0.0) {
                return Err(bad(&name("intensity"), "must be a positive number"));
            }
            if !(led.lambert_order.is_finite() && led.lambert_order >= 0.0) {
                return Err(bad(&name("lambert_order"), "must be a number ≥ 0"));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate_and_round_trip() {
        for name in PRESETS {
            let rig = Rig::preset(name).expect("preset exists");
            rig.validate().expect("preset is valid");
            let text = rig.to_toml_string();
            assert_eq!(Rig::from_toml_str(&text, name).unwrap(), rig);
        }
    }

    #[test]
    fn issue_format_parses() {
        let text = r#"
            [camera]
            width = 1280
            height = 720
            fps = 960.0
            distance_mm = 420.0
            fov_deg = 43.0
            [[led]]
            position_mm = [-270.0, 420.0, 100.0]
            [[led]]
            position_mm = [270.0, 420.0, 100.0]
            intensity = 2.0
        "#;
        let rig = Rig::from_toml_str(text, "test").unwrap();
        assert_eq!(rig.leds.len(), 2);
        assert_eq!(rig.leds[1].intensity, 2.0);
        // h = 2 · 420 · tan(21.5°) / 1280 = 0.2585 mm
        assert!((rig.camera.pitch_mm() - 0.25849).abs() < 1e-4);
    }

    #[test]
    fn invalid_fields_are_named() {
        let mut rig = Rig::preset("thesis-out-of-plane").unwrap();
        rig.leds[2].intensity = -1.0;
        let err = rig.validate().unwrap_err().to_string();
        assert!(err.contains("led[3].intensity"), "{err}");
        let err = Rig::from_toml_str("[camera]\nwidth = 1", "x.toml").unwrap_err();
        assert!(matches!(err, RigError::Parse { .. }));
        assert!(matches!(
            Rig::load("no-such-rig"),
            Err(RigError::UnknownPreset(_))
        ));
    }

    #[test]
    fn pixel_mapping_inverts_and_puts_y_up() {
        let cam = Rig::preset("thesis-out-of-plane").unwrap().camera;
        let (x, y) = cam.pixel_centre_xy(0.0, 0.0);
        assert!(x < 0.0 && y > 0.0, "row 0, col 0 is top-left");
        let (r, c) = cam.xy_to_pixel(x, y);
        assert!(r.abs() < 1e-9 && c.abs() < 1e-9);
    }

    #[test]
    fn light_vector_follows_inverse_square_and_cosine() {
        let led = Led {
            position_mm: [0.0, 0.0, 100.0],
            axis: None,
            intensity: 1.0,
            lambert_order: 1.0,
        };
        let l0 = led.light_vector_at(&Vector3::zeros());
        assert!((l0 - Vector3::new(0.0, 0.0, 1e-4)).norm() < 1e-12);
        // A point 100 mm to the side: d² = 2e4, cos θ = 1/√2, direction (−1, 0, 1)/√2.
        let l1 = led.light_vector_at(&Vector3::new(100.0, 0.0, 0.0));
        let expected = Vector3::new(-1.0, 0.0, 1.0) / 2f64.sqrt() * (0.5f64.sqrt() / 2e4);
        assert!((l1 - expected).norm() < 1e-12);
    }
}
