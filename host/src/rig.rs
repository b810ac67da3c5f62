//! Camera and LED geometry of a capture rig (TOML files and the thesis' rigs as presets).
//!
//! Coordinates (SPEC §5): origin at the object centre, x right, y up, z towards the camera,
//! millimetres. The camera looks along −z from (0, 0, `distance_mm`). It is orthographic (the
//! thesis' model and presets: one grid pitch in mm per pixel) or, with `[camera.intrinsics]`, a
//! pinhole camera with focal lengths fx, fy and principal point cx, cy in pixels (OpenCV
//! convention: pixel centres at integer coordinates, u = column, v = row) and optional radial
//! distortion x_d = x_u·(1 + k1·r² + k2·r⁴) of the normalised coordinates (Brown–Conrady, radial
//! terms only). Every pixel has a ray ([`PixelRay`]): the scene points it sees, parametrised by
//! their height z.
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

/// The camera: orthographic, or perspective when `intrinsics` are given (module docs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Frame rate in frames per second.
    pub fps: f64,
    /// Distance from the object centre along +z, mm (the perspective camera's centre).
    pub distance_mm: f64,
    /// Horizontal field of view in degrees (orthographic; used when `pixel_pitch_mm` is absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
    /// Grid pitch on the object plane, mm per pixel (orthographic; overrides `fov_deg`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_pitch_mm: Option<f64>,
    /// Pinhole intrinsics: makes the camera perspective.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intrinsics: Option<Intrinsics>,
    /// Orthographic cameras: where the optical axis (x = y = 0) meets the image, as [column,
    /// row] in pixels from the image's top-left corner (pixel centres at +0.5); the image
    /// centre when absent. A region of interest cut from a larger image keeps the larger
    /// image's axis ([`Camera::cropped`]). Perspective cameras take theirs from the intrinsics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis_px: Option<[f64; 2]>,
}

/// Pinhole intrinsics in pixels with radial distortion (OpenCV convention, module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Intrinsics {
    /// Focal length along the columns, pixels.
    pub fx: f64,
    /// Focal length along the rows, pixels.
    pub fy: f64,
    /// Principal point column.
    pub cx: f64,
    /// Principal point row.
    pub cy: f64,
    /// Radial distortion coefficient of r².
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k1: f64,
    /// Radial distortion coefficient of r⁴.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub k2: f64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// The scene points a pixel sees: X(z) = `base` + z·`slope`, parametrised by their height z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelRay {
    /// Where the ray crosses the plane z = 0.
    pub base: Vector3<f64>,
    /// dX/dz along the ray (z component 1).
    pub slope: Vector3<f64>,
}

impl PixelRay {
    /// The scene point of height `z` on the ray.
    pub fn at(&self, z: f64) -> Vector3<f64> {
        self.base + self.slope * z
    }

    /// Unit vector from the scene towards the camera along the ray (the view vector).
    pub fn towards_camera(&self) -> Vector3<f64> {
        self.slope.normalize()
    }
}

/// How scene points map to pixels (the part of [`Camera`] geometry needs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Projection {
    /// Parallel rays along −z, `pitch_mm` apart.
    Orthographic {
        /// Grid pitch h, mm per pixel.
        pitch_mm: f64,
        /// Where the optical axis meets the image, (column, row) in pixels from the top-left
        /// corner: (width/2, height/2) for a camera centred on its image
        /// ([`Projection::centred`]).
        axis: (f64, f64),
    },
    /// Rays through the camera centre (0, 0, `distance_mm`).
    Perspective {
        /// The intrinsics.
        intrinsics: Intrinsics,
        /// Height of the camera centre above the object centre, mm.
        distance_mm: f64,
    },
}

impl Intrinsics {
    /// Radial distortion factor 1 + k1·s + k2·s² at s = r² and its derivative in s.
    fn distortion(&self, s: f64) -> (f64, f64) {
        (
            1.0 + self.k1 * s + self.k2 * s * s,
            self.k1 + 2.0 * self.k2 * s,
        )
    }

    /// Undistorted normalised coordinates (x right, y down) of pixel (row, col); Newton
    /// iterations invert the radial model r_d = r_u·(1 + k1·r_u² + k2·r_u⁴).
    pub fn normalised(&self, row: f64, col: f64) -> (f64, f64) {
        let (xd, yd) = ((col - self.cx) / self.fx, (row - self.cy) / self.fy);
        if self.k1 == 0.0 && self.k2 == 0.0 {
            return (xd, yd);
        }
        let rd = xd.hypot(yd);
        if rd == 0.0 {
            return (0.0, 0.0);
        }
        let mut r = rd;
        for _ in 0..30 {
            let (f, df) = self.distortion(r * r);
            let g = r * f - rd;
            let dg = f + 2.0 * r * r * df;
            if dg <= 0.0 {
                break;
            }
            let step = g / dg;
            r -= step;
            if step.abs() < 1e-15 * rd.max(1e-300) {
                break;
            }
        }
        (xd * r / rd, yd * r / rd)
    }

    /// Pixel (row, col) of undistorted normalised coordinates.
    pub fn pixel(&self, x: f64, y: f64) -> (f64, f64) {
        let (f, _) = self.distortion(x * x + y * y);
        (self.fy * y * f + self.cy, self.fx * x * f + self.cx)
    }

    /// ∂(x, y)/∂(col, row) of [`Self::normalised`] at a pixel, as [[∂x/∂col, ∂x/∂row],
    /// [∂y/∂col, ∂y/∂row]] (the inverse of the distortion Jacobian, scaled by 1/fx, 1/fy).
    pub fn jacobian(&self, row: f64, col: f64) -> [[f64; 2]; 2] {
        let (x, y) = self.normalised(row, col);
        let (f, df) = self.distortion(x * x + y * y);
        // Distortion Jacobian ∂(x_d, y_d)/∂(x, y).
        let (a, b) = (f + 2.0 * x * x * df, 2.0 * x * y * df);
        let (c, d) = (2.0 * x * y * df, f + 2.0 * y * y * df);
        let det = a * d - b * c;
        [
            [d / det / self.fx, -b / det / self.fy],
            [-c / det / self.fx, a / det / self.fy],
        ]
    }
}

impl Projection {
    /// The orthographic projection of pitch `pitch_mm` centred on an image of `size` (width,
    /// height) pixels.
    pub fn centred(pitch_mm: f64, size: (usize, usize)) -> Self {
        Projection::Orthographic {
            pitch_mm,
            axis: (size.0 as f64 / 2.0, size.1 as f64 / 2.0),
        }
    }

    /// The projection of every `step`-th row and column (pixel (r, c) of the result is pixel
    /// (r·step, c·step) here): focal lengths and principal point divided by `step`, or the
    /// pitch multiplied by it and the axis moved so that each pixel keeps its ray.
    pub fn every(&self, step: usize) -> Self {
        let k = step.max(1) as f64;
        match *self {
            Projection::Orthographic { pitch_mm, axis } => Projection::Orthographic {
                pitch_mm: pitch_mm * k,
                axis: ((axis.0 - 0.5) / k + 0.5, (axis.1 - 0.5) / k + 0.5),
            },
            Projection::Perspective {
                intrinsics,
                distance_mm,
            } => Projection::Perspective {
                intrinsics: Intrinsics {
                    fx: intrinsics.fx / k,
                    fy: intrinsics.fy / k,
                    cx: intrinsics.cx / k,
                    cy: intrinsics.cy / k,
                    ..intrinsics
                },
                distance_mm,
            },
        }
    }

    /// The ray of the (continuous) pixel position (row, col).
    pub fn ray(&self, row: f64, col: f64) -> PixelRay {
        match *self {
            Projection::Orthographic { pitch_mm, axis } => {
                let x = (col + 0.5 - axis.0) * pitch_mm;
                let y = (axis.1 - row - 0.5) * pitch_mm;
                PixelRay {
                    base: Vector3::new(x, y, 0.0),
                    slope: Vector3::z(),
                }
            }
            Projection::Perspective {
                intrinsics,
                distance_mm,
            } => {
                // Camera frame x right, y down; scene y up. X(z) = C + (D − z)·(x, −y, −1).
                let (x, y) = intrinsics.normalised(row, col);
                PixelRay {
                    base: Vector3::new(distance_mm * x, -distance_mm * y, 0.0),
                    slope: Vector3::new(-x, y, 1.0),
                }
            }
        }
    }

    /// Continuous pixel (row, col) of a scene point; `None` at or behind a perspective camera.
    pub fn project(&self, point: &Vector3<f64>) -> Option<(f64, f64)> {
        match *self {
            Projection::Orthographic { pitch_mm, axis } => Some((
                axis.1 - point.y / pitch_mm - 0.5,
                point.x / pitch_mm + axis.0 - 0.5,
            )),
            Projection::Perspective {
                intrinsics,
                distance_mm,
            } => {
                let d = distance_mm - point.z;
                (d > 0.0).then(|| intrinsics.pixel(point.x / d, -point.y / d))
            }
        }
    }
}

impl Camera {
    /// A small 64×48, 960 fps test camera 400 mm from the origin with pitch `pixel_pitch_mm`
    /// or pinhole `intrinsics`.
    #[cfg(test)]
    pub(crate) fn test_64x48(pixel_pitch_mm: Option<f64>, intrinsics: Option<Intrinsics>) -> Self {
        Self {
            width: 64,
            height: 48,
            fps: 960.0,
            distance_mm: 400.0,
            fov_deg: None,
            pixel_pitch_mm,
            intrinsics,
            axis_px: None,
        }
    }

    /// Grid pitch h in mm per pixel: `pixel_pitch_mm`, else h = 2·d·tan(FOV/2)/width (SPEC §6);
    /// for a perspective camera the pitch on the object plane z = 0, d/fx.
    pub fn pitch_mm(&self) -> f64 {
        match (self.intrinsics, self.pixel_pitch_mm, self.fov_deg) {
            (Some(k), _, _) => self.distance_mm / k.fx,
            (None, Some(h), _) => h,
            (None, None, Some(fov)) => {
                2.0 * self.distance_mm * (fov.to_radians() / 2.0).tan() / self.width as f64
            }
            (None, None, None) => f64::NAN,
        }
    }

    /// The camera's projection.
    pub fn projection(&self) -> Projection {
        match self.intrinsics {
            Some(intrinsics) => Projection::Perspective {
                intrinsics,
                distance_mm: self.distance_mm,
            },
            None => Projection::Orthographic {
                pitch_mm: self.pitch_mm(),
                axis: match self.axis_px {
                    Some([col, row]) => (col, row),
                    None => (self.width as f64 / 2.0, self.height as f64 / 2.0),
                },
            },
        }
    }

    /// The camera of the region `rows` × `cols` of this camera's image (a region of interest):
    /// every pixel keeps its ray. The grid pitch is fixed (`pixel_pitch_mm`, since a field of
    /// view would scale with the width), and the optical axis (`axis_px`, or the intrinsics'
    /// principal point) moves by the region's top-left corner. The region must lie inside the
    /// image.
    pub fn cropped(&self, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> Camera {
        let (top, left) = (rows.start as f64, cols.start as f64);
        let mut camera = Camera {
            width: cols.len(),
            height: rows.len(),
            ..self.clone()
        };
        match (&mut camera.intrinsics, self.projection()) {
            (Some(k), _) => {
                k.cx -= left;
                k.cy -= top;
            }
            (None, Projection::Orthographic { pitch_mm, axis }) => {
                camera.pixel_pitch_mm = Some(pitch_mm);
                camera.fov_deg = None;
                camera.axis_px = Some([axis.0 - left, axis.1 - top]);
            }
            (None, Projection::Perspective { .. }) => {}
        }
        camera
    }

    /// The camera of this camera's image binned into `factor`×`factor` blocks
    /// ([`crate::capture::binning`]): pixel (r, c) is the block of rows r·k .. r·k + k and
    /// columns c·k .. c·k + k, and its ray is the one through the block's centre, the
    /// continuous position (r·k + (k − 1)/2, c·k + (k − 1)/2) here. Rows and columns that do
    /// not fill a block are dropped. A pinhole camera's focal lengths are divided by k and its
    /// principal point moved to the binned grid (radial distortion is in normalised
    /// coordinates, so it is kept); an orthographic camera's pitch is multiplied by k and its
    /// optical axis divided by k. A factor of 0 or 1 returns the camera unchanged.
    pub fn binned(&self, factor: usize) -> Camera {
        if factor <= 1 {
            return self.clone();
        }
        let k = factor as f64;
        let mut camera = Camera {
            width: self.width / factor,
            height: self.height / factor,
            ..self.clone()
        };
        match (&mut camera.intrinsics, self.projection()) {
            (Some(intrinsics), _) => {
                let centre = (k - 1.0) / 2.0;
                intrinsics.fx /= k;
                intrinsics.fy /= k;
                intrinsics.cx = (intrinsics.cx - centre) / k;
                intrinsics.cy = (intrinsics.cy - centre) / k;
            }
            (None, Projection::Orthographic { pitch_mm, axis }) => {
                camera.pixel_pitch_mm = Some(pitch_mm * k);
                camera.fov_deg = None;
                camera.axis_px = Some([axis.0 / k, axis.1 / k]);
            }
            (None, Projection::Perspective { .. }) => {}
        }
        camera
    }

    /// Whether the camera is a pinhole (perspective) camera.
    pub fn is_perspective(&self) -> bool {
        self.intrinsics.is_some()
    }

    /// The ray of pixel (row, col).
    pub fn ray(&self, row: f64, col: f64) -> PixelRay {
        self.projection().ray(row, col)
    }

    /// Continuous pixel (row, col) of a scene point (`None` behind a perspective camera).
    pub fn project(&self, point: &Vector3<f64>) -> Option<(f64, f64)> {
        self.projection().project(point)
    }

    /// Scene (x, y) in mm where the ray of pixel (row, col) crosses the plane z = 0.
    pub fn pixel_centre_xy(&self, row: f64, col: f64) -> (f64, f64) {
        let base = self.ray(row, col).base;
        (base.x, base.y)
    }

    /// Continuous (row, col) of the scene point (x, y, 0); inverse of [`Self::pixel_centre_xy`].
    pub fn xy_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        self.project(&Vector3::new(x, y, 0.0))
            .unwrap_or((f64::NAN, f64::NAN))
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
    fn validate(&self) -> Result<(), RigError> {
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
            intrinsics: None,
            axis_px: None,
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
        // Thesis Ch. 6: a 192×128 SPAD with a 16° lens, 80 cm from the sphere (which stands
        // 100 mm in front of the scene centre); placed 40 mm beside the phone, aimed at the centre.
        let tof_camera = (name == "thesis-hybrid").then_some(TofCamera {
            width: 192,
            height: 128,
            fov_deg: 16.0,
            position_mm: [40.0, 0.0, 900.0],
            look_at_mm: [0.0; 3],
        });
        let leds = positions
            .into_iter()
            .map(|position_mm| Led {
                position_mm,
                axis: None,
                intensity: 1.0,
                lambert_order: 1.0,
            })
            .collect();
        Some(Self {
            camera,
            leds,
            tof_camera,
        })
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
    fn documented_format_parses() {
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
        // A narrower emitter (m = 2) falls off as cos² θ; the general path agrees with the
        // Lambertian one's as m → 1; nothing is emitted behind the LED.
        let narrow = Led {
            lambert_order: 2.0,
            ..led.clone()
        };
        let l2 = narrow.light_vector_at(&Vector3::new(100.0, 0.0, 0.0));
        assert!((l2 - expected * 0.5f64.sqrt()).norm() < 1e-12);
        let almost = Led {
            lambert_order: 1.0 + 1e-12,
            ..led.clone()
        };
        for point in [
            Vector3::new(100.0, 0.0, 0.0),
            Vector3::new(-30.0, 55.0, 20.0),
        ] {
            let (a, b) = (led.light_vector_at(&point), almost.light_vector_at(&point));
            assert!((a - b).norm() < 1e-9 * a.norm(), "{a} {b}");
        }
        assert_eq!(
            led.light_vector_at(&Vector3::new(0.0, 0.0, 150.0)),
            Vector3::zeros()
        );
        assert_eq!(
            narrow.light_vector_at(&Vector3::new(0.0, 0.0, 150.0)),
            Vector3::zeros()
        );
    }

    fn perspective() -> Camera {
        Camera::test_64x48(
            None,
            Some(Intrinsics {
                fx: 900.0,
                fy: 880.0,
                cx: 30.5,
                cy: 25.0,
                k1: -0.2,
                k2: 0.05,
            }),
        )
    }

    #[test]
    fn perspective_rays_project_back_to_their_pixel() {
        let cam = perspective();
        for (row, col) in [(0.0, 0.0), (25.0, 30.5), (47.0, 63.0), (10.3, 50.7)] {
            let ray = cam.ray(row, col);
            for z in [-30.0, 0.0, 25.0] {
                let (r, c) = cam.project(&ray.at(z)).unwrap();
                assert!((r - row).abs() < 1e-9 && (c - col).abs() < 1e-9, "{r} {c}");
            }
            // The ray passes through the camera centre (0, 0, D).
            let centre = ray.at(cam.distance_mm);
            assert!((centre.z - cam.distance_mm).abs() < 1e-9 && centre.xy().norm() < 1e-9);
        }
        // Principal point looks straight down; a pixel to the right sees +x, one below sees −y.
        let (x, y) = cam.pixel_centre_xy(25.0, 30.5);
        assert!(x.abs() < 1e-12 && y.abs() < 1e-12);
        let (x, y) = cam.pixel_centre_xy(40.0, 60.0);
        assert!(x > 0.0 && y < 0.0);
        assert!((cam.pitch_mm() - 400.0 / 900.0).abs() < 1e-12);
        assert!(cam.project(&Vector3::new(0.0, 0.0, 400.0)).is_none());
    }

    /// Every third pixel of a distorted camera sees along the ray of its full-grid pixel.
    #[test]
    fn sub_sampled_projection_keeps_each_pixels_ray() {
        let full = perspective().projection();
        let coarse = full.every(3);
        for (row, col) in [(0.0, 0.0), (4.0, 7.0), (15.0, 20.0)] {
            let (a, b) = (coarse.ray(row, col), full.ray(3.0 * row, 3.0 * col));
            let (pa, pb) = (a.at(10.0), b.at(10.0));
            assert!((pa - pb).norm() < 1e-9, "{pa} vs {pb}");
        }
    }

    /// Each pixel of a camera cut to a region of interest sees along the ray of its pixel in
    /// the full image, for a field-of-view, a pitch and a pinhole camera.
    #[test]
    fn a_cropped_camera_keeps_each_pixels_ray() {
        let mut by_fov = Camera::test_64x48(None, None);
        by_fov.fov_deg = Some(40.0);
        for full in [by_fov, Camera::test_64x48(Some(0.7), None), perspective()] {
            let region = full.cropped(10..30, 25..60);
            assert_eq!((region.width, region.height), (35, 20));
            let rig = |camera: &Camera| Rig {
                camera: camera.clone(),
                ..Rig::preset("thesis-dynamic").expect("preset")
            };
            let region_rig = rig(&region);
            region_rig.validate().expect("a valid region camera");
            let text = region_rig.to_toml_string();
            assert_eq!(Rig::from_toml_str(&text, "region").unwrap(), region_rig);
            for (row, col) in [(0.0, 0.0), (4.5, 7.0), (19.0, 34.0)] {
                let (a, b) = (region.ray(row, col), full.ray(row + 10.0, col + 25.0));
                assert!(
                    (a.at(7.0) - b.at(7.0)).norm() < 1e-9,
                    "{full:?} at {row}, {col}"
                );
                let (r, c) = region.project(&b.at(-3.0)).expect("in front of the camera");
                assert!((r - row).abs() < 1e-6 && (c - col).abs() < 1e-6, "{r}, {c}");
            }
        }
        // An axis is for orthographic cameras, in finite pixels.
        let mut rig = Rig::preset("thesis-dynamic").expect("preset");
        rig.camera.axis_px = Some([f64::NAN, 3.0]);
        assert!(rig.validate().is_err());
        rig.camera = Camera {
            axis_px: Some([1.0, 2.0]),
            ..perspective()
        };
        assert!(rig.validate().is_err());
    }

    /// Each pixel of a binned camera sees along the ray through the centre of its block, for
    /// a field-of-view, a pitch and a distorted pinhole camera, and a binned rig is valid and
    /// round-trips through TOML.
    #[test]
    fn a_binned_camera_sees_through_each_blocks_centre() {
        let mut by_fov = Camera::test_64x48(None, None);
        by_fov.fov_deg = Some(40.0);
        for full in [by_fov, Camera::test_64x48(Some(0.7), None), perspective()] {
            for k in [2usize, 3] {
                let binned = full.binned(k);
                assert_eq!(
                    (binned.width, binned.height),
                    (full.width / k, full.height / k)
                );
                let rig = Rig {
                    camera: full.clone(),
                    ..Rig::preset("thesis-dynamic").expect("preset")
                }
                .binned(k);
                rig.validate().expect("a valid binned camera");
                assert_eq!(rig.camera, binned);
                let text = rig.to_toml_string();
                assert_eq!(Rig::from_toml_str(&text, "binned").unwrap(), rig);
                let centre = (k as f64 - 1.0) / 2.0;
                for (row, col) in [(0.0, 0.0), (4.0, 7.0), (12.0, 17.0)] {
                    let (r, c) = (row * k as f64 + centre, col * k as f64 + centre);
                    let (a, b) = (binned.ray(row, col), full.ray(r, c));
                    assert!(
                        (a.at(7.0) - b.at(7.0)).norm() < 1e-9
                            && (a.at(-5.0) - b.at(-5.0)).norm() < 1e-9,
                        "{full:?} by {k} at {row}, {col}"
                    );
                }
            }
            assert_eq!(full.binned(1), full);
        }
    }

    /// Every third pixel of an orthographic camera sees along the ray of its full-grid pixel.
    #[test]
    fn sub_sampled_orthographic_projection_keeps_each_pixels_ray() {
        let full = Camera::test_64x48(Some(0.5), None).projection();
        let coarse = full.every(3);
        for (row, col) in [(0.0, 0.0), (4.0, 7.0), (15.0, 20.0)] {
            let (a, b) = (coarse.ray(row, col), full.ray(3.0 * row, 3.0 * col));
            assert!((a.at(10.0) - b.at(10.0)).norm() < 1e-9);
        }
    }

    #[test]
    fn distortion_jacobian_matches_finite_differences() {
        let k = perspective().intrinsics.unwrap();
        let (row, col) = (3.0, 60.0);
        let j = k.jacobian(row, col);
        let e = 1e-4;
        let (xp, yp) = k.normalised(row, col + e);
        let (xm, ym) = k.normalised(row, col - e);
        let (xr, yr) = k.normalised(row + e, col);
        let (xs, ys) = k.normalised(row - e, col);
        let numeric = [
            [(xp - xm) / (2.0 * e), (xr - xs) / (2.0 * e)],
            [(yp - ym) / (2.0 * e), (yr - ys) / (2.0 * e)],
        ];
        for a in 0..2 {
            for b in 0..2 {
                assert!((j[a][b] - numeric[a][b]).abs() < 1e-9, "{j:?} {numeric:?}");
            }
        }
    }

    #[test]
    fn perspective_rig_parses_and_bad_intrinsics_are_named() {
        let text = r#"
            [camera]
            width = 640
            height = 480
            fps = 960.0
            distance_mm = 420.0
            [camera.intrinsics]
            fx = 1500.0
            fy = 1500.0
            cx = 319.5
            cy = 239.5
            k1 = -0.1
            [[led]]
            position_mm = [-270.0, 420.0, 100.0]
        "#;
        let rig = Rig::from_toml_str(text, "test").unwrap();
        assert!(rig.camera.is_perspective());
        assert_eq!(rig.camera.intrinsics.unwrap().k2, 0.0);
        assert_eq!(Rig::from_toml_str(&rig.to_toml_string(), "x").unwrap(), rig);
        let with_fov = text.replace("fps = 960.0", "fps = 960.0\nfov_deg = 40.0");
        let err = Rig::from_toml_str(&with_fov, "x").unwrap_err().to_string();
        assert!(
            err.contains("camera.intrinsics") && err.contains("fov_deg"),
            "{err}"
        );
        let folded = text.replace("k1 = -0.1", "k1 = -4.0");
        let err = Rig::from_toml_str(&folded, "x").unwrap_err().to_string();
        assert!(err.contains("camera.intrinsics.k1"), "{err}");
        let zero = text.replace("fy = 1500.0", "fy = 0.0");
        let err = Rig::from_toml_str(&zero, "x").unwrap_err().to_string();
        assert!(err.contains("camera.intrinsics.fy"), "{err}");
    }
}
