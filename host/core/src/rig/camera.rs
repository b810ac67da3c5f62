//! The camera: orthographic (one grid pitch in mm per pixel) or a pinhole with radial
//! distortion, and the ray each pixel sees.

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

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
    pub(super) fn distortion(&self, s: f64) -> (f64, f64) {
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
    #[cfg(any(test, feature = "testing"))]
    pub fn test_64x48(pixel_pitch_mm: Option<f64>, intrinsics: Option<Intrinsics>) -> Self {
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

    /// Grid pitch h in mm per pixel: `pixel_pitch_mm`, else h = 2·d·tan(FOV/2)/width
    /// (docs/maths/coordinates.md#grid-pitch);
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
