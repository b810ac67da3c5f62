//! A camera's pinhole intrinsics (fx, fy, cx, cy) and radial distortion (k1, k2) from photos of
//! a flat chequerboard at several poses.
//!
//! Each photo's inner corners are found with the corner detector of [`crate::tof::chequerboard`]
//! (OpenCV, sub-pixel refined); OpenCV's `calibrateCamera` then fits the intrinsics and every
//! view's pose by minimising the corners' reprojection error (Z. Zhang, "A flexible new
//! technique for camera calibration", IEEE Transactions on Pattern Analysis and Machine
//! Intelligence, 2000), with the tangential terms and k3 held at zero: the rig's camera model
//! ([`meb_core::rig::Intrinsics`]) has radial terms r² and r⁴ only. Pixel coordinates follow
//! the rig's convention (integer values at pixel centres), as the detector returns them.
//!
//! A fit is accepted when at least [`MIN_VIEWS`] photos show the whole board and the RMS
//! reprojection error is at most [`MAX_RMS_PX`]: a larger one means a board that is not flat,
//! wrong corner correspondences or a lens the model does not describe.

use super::CalibrateError;
use crate::tof::chequerboard::{BoardSize, find_corners};
use meb_core::rig::Intrinsics;
use ndarray::Array2;

/// Fewest photos with the whole board found: Zhang's method needs three for the pinhole
/// intrinsics; the distortion terms and a check of the fit need more.
pub const MIN_VIEWS: usize = 5;

/// Largest accepted RMS reprojection error, pixels.
pub const MAX_RMS_PX: f64 = 1.0;

/// The result of [`calibrate_camera`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CameraCalibration {
    /// The fitted intrinsics.
    pub intrinsics: Intrinsics,
    /// Standard deviations of fx, fy, cx, cy, k1, k2 as OpenCV estimates them.
    pub standard_errors: [f64; 6],
    /// RMS reprojection error over every corner of every view, pixels.
    pub rms_px: f64,
    /// RMS reprojection error of each view, pixels.
    pub view_rms_px: Vec<f64>,
    /// Image size (width, height), pixels.
    pub size: [usize; 2],
}

/// Calibrates a camera from grey `images` of a chequerboard of `board` inner corners and
/// `square_mm` squares (module docs); `names` name the images in errors.
pub fn calibrate_camera(
    images: &[Array2<f32>],
    names: &[String],
    board: BoardSize,
    square_mm: f64,
) -> Result<CameraCalibration, CalibrateError> {
    if !(square_mm.is_finite() && square_mm > 0.0) {
        return Err(CalibrateError::Input(format!(
            "the square's edge must be a positive length, got {square_mm} mm"
        )));
    }
    if images.len() < MIN_VIEWS {
        return Err(CalibrateError::Input(format!(
            "{} photos of the board given; at least {MIN_VIEWS} are needed, at different \
             tilts and across the whole image",
            images.len()
        )));
    }
    let size = images[0].dim();
    let mut views = Vec::with_capacity(images.len());
    for (k, image) in images.iter().enumerate() {
        let name = names
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("photo {}", k + 1));
        if image.dim() != size {
            return Err(CalibrateError::Input(format!(
                "{name} is {}x{} but the first photo {}x{}: one camera, one image size",
                image.dim().1,
                image.dim().0,
                size.1,
                size.0
            )));
        }
        let corners = find_corners(image, board, &name)
            .map_err(|e| CalibrateError::NoBoard(e.to_string()))?;
        views.push(corners);
    }
    let fit = opencv_fit::fit(&views, board, square_mm, (size.1, size.0))
        .map_err(CalibrateError::Input)?;
    if !(fit.rms_px.is_finite() && fit.rms_px <= MAX_RMS_PX) {
        return Err(CalibrateError::NoFit(format!(
            "the corners are reprojected with an RMS error of {:.2} px (at most {MAX_RMS_PX} px \
             for a flat board and a lens the r², r⁴ model describes): check COLSxROWS, that \
             the board is flat and rigid, and drop blurred photos (worst: {})",
            fit.rms_px,
            worst_view(&fit.view_rms_px, names)
        )));
    }
    Ok(CameraCalibration {
        size: [size.1, size.0],
        ..fit
    })
}

/// The name and error of the view with the largest reprojection error.
fn worst_view(errors: &[f64], names: &[String]) -> String {
    errors
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or_else(String::new, |(k, e)| {
            let name = names
                .get(k)
                .cloned()
                .unwrap_or_else(|| format!("photo {}", k + 1));
            format!("{name}, {e:.2} px")
        })
}

/// OpenCV's `calibrateCamera` (module docs).
#[cfg(feature = "opencv")]
mod opencv_fit {
    use super::{BoardSize, CameraCalibration, Intrinsics};
    use opencv::calib3d;
    use opencv::core::{
        Mat, Point2f, Point3f, Size, TermCriteria, TermCriteria_COUNT, TermCriteria_EPS, Vector,
    };
    use opencv::prelude::*;

    /// Fits the intrinsics to the corners of every view; `size` is (width, height).
    pub fn fit(
        views: &[Vec<[f64; 2]>],
        board: BoardSize,
        square_mm: f64,
        size: (usize, usize),
    ) -> Result<CameraCalibration, String> {
        let cv = |e: opencv::Error| format!("OpenCV: {e}");
        let mut object = Vector::<Point3f>::new();
        for j in 0..board.rows {
            for i in 0..board.cols {
                object.push(Point3f::new(
                    (i as f64 * square_mm) as f32,
                    (j as f64 * square_mm) as f32,
                    0.0,
                ));
            }
        }
        let mut objects = Vector::<Vector<Point3f>>::new();
        let mut images = Vector::<Vector<Point2f>>::new();
        for corners in views {
            objects.push(object.clone());
            images.push(
                corners
                    .iter()
                    .map(|&[x, y]| Point2f::new(x as f32, y as f32))
                    .collect(),
            );
        }
        let mut camera = Mat::default();
        let mut distortion = Mat::default();
        let (mut rvecs, mut tvecs) = (Vector::<Mat>::new(), Vector::<Mat>::new());
        let (mut sd_intrinsics, mut sd_extrinsics, mut per_view) =
            (Mat::default(), Mat::default(), Mat::default());
        let criteria =
            TermCriteria::new(TermCriteria_COUNT + TermCriteria_EPS, 100, 1e-12).map_err(cv)?;
        let rms = calib3d::calibrate_camera_extended(
            &objects,
            &images,
            Size::new(size.0 as i32, size.1 as i32),
            &mut camera,
            &mut distortion,
            &mut rvecs,
            &mut tvecs,
            &mut sd_intrinsics,
            &mut sd_extrinsics,
            &mut per_view,
            calib3d::CALIB_ZERO_TANGENT_DIST | calib3d::CALIB_FIX_K3,
            criteria,
        )
        .map_err(cv)?;
        let at = |m: &Mat, r: i32, c: i32| m.at_2d::<f64>(r, c).copied().map_err(cv);
        let flat = |m: &Mat, k: i32| m.at::<f64>(k).copied().map_err(cv);
        let intrinsics = Intrinsics {
            fx: at(&camera, 0, 0)?,
            fy: at(&camera, 1, 1)?,
            cx: at(&camera, 0, 2)?,
            cy: at(&camera, 1, 2)?,
            k1: flat(&distortion, 0)?,
            k2: flat(&distortion, 1)?,
        };
        // OpenCV's order: fx, fy, cx, cy, k1, k2, p1, p2, k3, …
        let mut standard_errors = [f64::NAN; 6];
        for (k, se) in standard_errors.iter_mut().enumerate() {
            *se = flat(&sd_intrinsics, k as i32)?;
        }
        let view_rms_px = (0..views.len() as i32)
            .map(|k| flat(&per_view, k))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(CameraCalibration {
            intrinsics,
            standard_errors,
            rms_px: rms,
            view_rms_px,
            size: [size.0, size.1],
        })
    }
}

/// Stands in for OpenCV in a build without it: never reached, the corner detector refuses
/// first.
#[cfg(not(feature = "opencv"))]
mod opencv_fit {
    use super::{BoardSize, CameraCalibration};

    /// Always refuses (module docs).
    pub fn fit(
        _views: &[Vec<[f64; 2]>],
        _board: BoardSize,
        _square_mm: f64,
        _size: (usize, usize),
    ) -> Result<CameraCalibration, String> {
        Err("this build has no OpenCV (rebuild with --features opencv)".into())
    }
}
