//! Camera and LED geometry of a capture rig (TOML files and the thesis' rigs as presets).
//!
//! Coordinates (docs/maths/coordinates.md#the-scene-frame): origin at the object centre, x right, y
//! up, z towards the camera,
//! millimetres. The camera looks along −z from (0, 0, `distance_mm`). It is orthographic (the
//! thesis' model and presets: one grid pitch in mm per pixel) or, with `[camera.intrinsics]`, a
//! pinhole camera with focal lengths fx, fy and principal point cx, cy in pixels (OpenCV
//! convention: pixel centres at integer coordinates, u = column, v = row) and optional radial
//! distortion x_d = x_u·(1 + k1·r² + k2·r⁴) of the normalised coordinates (Brown–Conrady, radial
//! terms only). Every pixel has a ray ([`PixelRay`]): the scene points it sees, parametrised by
//! their height z.
//! An LED at P_i with axis a_i, relative intensity Φ_i and Lambert order m lights a surface
//! point X along the light vector (docs/maths/photometric-stereo.md#light-vectors, thesis Eq. 3.3
//! generalised to the near field)
//!
//! ```text
//! L_i(X) = Φ_i · cos^m(θ_i) / |P_i − X|² · (P_i − X)/|P_i − X|,   cos θ_i = a_i · (X − P_i)/|X − P_i|
//! ```
//!
//! and the distant-light model of the thesis is `L_i(0)`.
//!
//! The pieces: [`camera`] (the camera and its pixels' rays, orthographic or pinhole with radial
//! distortion), [`led`] (LED positions, axes, intensities and emission profiles),
//! [`tof_camera`] (the time-of-flight camera of a hybrid rig), [`presets`] (the thesis' rigs) and
//! [`validate`] (every field's range, with the field named in the error).

pub mod camera;
pub mod led;
pub mod presets;
pub mod tof_camera;
pub mod validate;

pub use camera::{Camera, Intrinsics, PixelRay, Projection};
pub use led::{Emitter, Led};
pub use presets::PRESETS;
pub use tof_camera::TofCamera;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;
use thiserror::Error;

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
    #[error("rig file {path}: {source}")]
    Parse {
        /// The file (or preset name).
        path: String,
        /// The parser's error.
        source: toml::de::Error,
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

/// A capture rig: one camera and its LEDs, in LED order, and optionally a time-of-flight camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    /// The camera.
    pub camera: Camera,
    /// LEDs, LED 1 first.
    #[serde(rename = "led")]
    pub leds: Vec<Led>,
    /// The time-of-flight (SPAD) camera of a hybrid rig (thesis Ch. 6), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tof_camera: Option<TofCamera>,
}

impl Rig {
    /// This rig with its camera binned by `factor` ([`Camera::binned`]).
    pub fn binned(&self, factor: usize) -> Rig {
        Rig {
            camera: self.camera.binned(factor),
            ..self.clone()
        }
    }

    /// Parses and validates a rig from TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, RigError> {
        let rig: Rig = toml::from_str(text).map_err(|source| RigError::Parse {
            path: origin.to_string(),
            source,
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

    /// Distant-light vectors L_i = L_i(0) of docs/maths/photometric-stereo.md#light-vectors, one
    /// per LED.
    pub fn distant_light_vectors(&self) -> Vec<Vector3<f64>> {
        self.leds
            .iter()
            .map(|led| led.light_vector_at(&Vector3::zeros()))
            .collect()
    }
}

#[cfg(test)]
mod tests;
