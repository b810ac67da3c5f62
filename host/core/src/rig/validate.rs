//! Range checks of every rig field; an error names the first bad field.

use super::{Intrinsics, Rig, RigError};
use nalgebra::Vector3;

impl Rig {
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
        if c.intrinsics.is_some() && c.axis_px.is_some() {
            return Err(bad(
                "camera.axis_px",
                "a perspective camera's axis is its principal point: remove `axis_px` and set \
                 the intrinsics' cx, cy",
            ));
        }
        match (c.intrinsics, c.pixel_pitch_mm, c.fov_deg) {
            (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
                return Err(bad(
                    "camera.intrinsics",
                    "a perspective camera takes its scale from the intrinsics: remove \
                     `fov_deg` and `pixel_pitch_mm`",
                ));
            }
            (Some(k), None, None) => validate_intrinsics(&k, c.width, c.height)?,
            (None, ..) if c.axis_px.is_some_and(|a| !a.iter().all(|v| v.is_finite())) => {
                return Err(bad(
                    "camera.axis_px",
                    "must be two finite numbers of pixels",
                ));
            }
            (None, Some(h), _) if !(h.is_finite() && h > 0.0) => {
                return Err(bad("camera.pixel_pitch_mm", "must be a positive number"));
            }
            (None, None, Some(f)) if !(f.is_finite() && f > 0.0 && f < 180.0) => {
                return Err(bad("camera.fov_deg", "must be in (0, 180) degrees"));
            }
            (None, None, None) => {
                return Err(bad(
                    "camera",
                    "needs `fov_deg` or `pixel_pitch_mm` (orthographic) or `[camera.intrinsics]`",
                ));
            }
            _ => {}
        }
        if self.leds.is_empty() || self.leds.len() > protocol::carriers::MAX_LEDS {
            return Err(bad("led", "a rig has 1 to 8 LEDs"));
        }
        if let Some(tof) = &self.tof_camera {
            tof.validate()?;
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

/// Checks focal lengths, principal point and that the radial distortion is invertible
/// (r_d = r_u·(1 + k1·r_u² + k2·r_u⁴) increasing) out to the image's farthest corner.
fn validate_intrinsics(k: &Intrinsics, width: usize, height: usize) -> Result<(), RigError> {
    let bad = |field: &str, reason: String| RigError::Invalid {
        field: format!("camera.intrinsics.{field}"),
        reason,
    };
    for (name, v) in [("fx", k.fx), ("fy", k.fy)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(name, "must be a positive number of pixels".into()));
        }
    }
    for (name, v) in [("cx", k.cx), ("cy", k.cy), ("k1", k.k1), ("k2", k.k2)] {
        if !v.is_finite() {
            return Err(bad(name, "must be a finite number".into()));
        }
    }
    // Farthest distorted radius of a pixel centre, in normalised units.
    let corner = [(0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0)]
        .iter()
        .map(|&(a, b)| {
            let col = a * (width as f64 - 1.0);
            let row = b * (height as f64 - 1.0);
            ((col - k.cx) / k.fx).hypot((row - k.cy) / k.fy)
        })
        .fold(0.0, f64::max);
    // Walk r_u outwards until r_d passes the corner; the map must keep increasing.
    let mut r = 0.0;
    let step = corner.max(1e-3) / 2000.0;
    for _ in 0..1_000_000 {
        let (f, df) = k.distortion(r * r);
        if f + 2.0 * r * r * df <= 0.0 {
            return Err(bad(
                "k1",
                format!(
                    "k1 = {}, k2 = {} fold the image over itself before its corner \
                     (radial distortion must increase with the radius)",
                    k.k1, k.k2
                ),
            ));
        }
        if r * f > corner {
            return Ok(());
        }
        r += step;
    }
    Err(bad(
        "k1",
        format!(
            "k1 = {}, k2 = {} barely increase the radius: the image corner is not reached",
            k.k1, k.k2
        ),
    ))
}
