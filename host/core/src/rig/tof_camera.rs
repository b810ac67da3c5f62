//! The time-of-flight (SPAD) camera of a hybrid rig, at its own pose.

use super::RigError;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// A pinhole time-of-flight camera (a SPAD array with a co-located pulsed emitter) at its own
/// pose: at `position_mm`, looking at `look_at_mm`, image rows running down the scene's −y as
/// far as the pose allows (its x axis is `forward × ŷ`, normalised). A pixel (row, col) sees
/// along `d = R·((col + 0.5 − W/2)/f, (row + 0.5 − H/2)/f, 1)` with f = (W/2)/tan(FOV/2), so a
/// point at axial depth s (distance along the optical axis) is `X = C + s·d`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TofCamera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Horizontal field of view in degrees.
    pub fov_deg: f64,
    /// Optical centre C in mm (scene coordinates).
    pub position_mm: [f64; 3],
    /// The point the optical axis passes through, mm (default: the origin).
    #[serde(default = "origin")]
    pub look_at_mm: [f64; 3],
}

fn origin() -> [f64; 3] {
    [0.0; 3]
}

impl TofCamera {
    /// Focal length f in pixels.
    pub fn focal_px(&self) -> f64 {
        self.width as f64 / 2.0 / (self.fov_deg.to_radians() / 2.0).tan()
    }

    /// Camera axes in scene coordinates as the columns (right, down, forward).
    pub fn axes(&self) -> nalgebra::Matrix3<f64> {
        let forward = (Vector3::from(self.look_at_mm) - Vector3::from(self.position_mm))
            .try_normalize(1e-12)
            .unwrap_or(-Vector3::z());
        let right = forward
            .cross(&Vector3::y())
            .try_normalize(1e-9)
            .unwrap_or(Vector3::x());
        let down = forward.cross(&right);
        nalgebra::Matrix3::from_columns(&[right, down, forward])
    }

    /// Ray through continuous pixel position (row, col) (integers are pixel centres) in scene
    /// coordinates, scaled to unit axial depth.
    pub fn ray(&self, row: f64, col: f64) -> Vector3<f64> {
        let f = self.focal_px();
        let local = Vector3::new(
            (col + 0.5 - self.width as f64 / 2.0) / f,
            (row + 0.5 - self.height as f64 / 2.0) / f,
            1.0,
        );
        self.axes() * local
    }

    /// Continuous (row, col) and axial depth of scene point `x` (`None` behind the camera).
    pub fn project(&self, x: &Vector3<f64>) -> Option<(f64, f64, f64)> {
        let local = self.axes().transpose() * (x - Vector3::from(self.position_mm));
        if local.z <= 0.0 {
            return None;
        }
        let f = self.focal_px();
        let col = local.x / local.z * f + self.width as f64 / 2.0 - 0.5;
        let row = local.y / local.z * f + self.height as f64 / 2.0 - 0.5;
        Some((row, col, local.z))
    }

    /// Checks every field; the error names the first bad one.
    pub(super) fn validate(&self) -> Result<(), RigError> {
        let bad = |field: &str, reason: &str| RigError::Invalid {
            field: format!("tof_camera.{field}"),
            reason: reason.to_string(),
        };
        if self.width == 0 || self.height == 0 {
            return Err(bad("width/height", "must be positive"));
        }
        if !(self.fov_deg.is_finite() && self.fov_deg > 0.0 && self.fov_deg < 170.0) {
            return Err(bad("fov_deg", "must be in (0, 170) degrees"));
        }
        let c = Vector3::from(self.position_mm);
        let t = Vector3::from(self.look_at_mm);
        if !c.iter().chain(t.iter()).all(|v| v.is_finite()) {
            return Err(bad("position_mm/look_at_mm", "must be finite"));
        }
        let forward = t - c;
        if forward.norm() < 1e-6 {
            return Err(bad("look_at_mm", "must differ from position_mm"));
        }
        if forward.normalize().cross(&Vector3::y()).norm() < 1e-6 {
            return Err(bad(
                "look_at_mm",
                "the camera must not look straight along ±y",
            ));
        }
        Ok(())
    }
}
