//! Two-camera calibration: the homography from ToF pixels to PS-camera pixels fitted to the
//! chequerboard corners both cameras see (thesis §6.4: "scale + alignment" of the SPAD image to
//! the phone's), saved as a small TOML file.
//!
//! A homography is exact only for points on the board's plane. The thesis therefore calibrated
//! "at each object location" and proposed choosing the calibration by range. Here a calibration
//! holds one plane, or several planes with the ToF range at which each board stood; for a point
//! at range s the homography is interpolated linearly in s between the two nearest planes
//! (extrapolated beyond them). For a pinhole ToF camera and boards perpendicular to its axis this
//! is exact: a point at axial depth s on the ray of pixel u lands in the (orthographic) PS image
//! at a + s·M·(u, 1)ᵀ, affine in s.
//!
//! Fitting is the normalised direct linear transform (Hartley, "In defense of the eight-point
//! algorithm", IEEE TPAMI 19(6), 1997; Hartley & Zisserman, *Multiple View Geometry*, 2nd ed.,
//! Alg. 4.2): both point sets are moved to their centroid and scaled to a mean distance of √2,
//! H̃ is the unit null vector of the 2n×9 DLT system (smallest eigenvector of AᵀA), and
//! H = T_dst⁻¹·H̃·T_src; then Gauss–Newton on the reprojection error in camera pixels
//! (Alg. 4.3's geometric cost, one-image form).

use super::TofError;
use super::chequerboard::BoardSize;
use nalgebra::{Matrix3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A plane fit is refused when its RMS reprojection error exceeds this many camera pixels.
pub const MAX_RMS_PX: f64 = 2.0;

/// The corners of one board as both cameras see them.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardView {
    /// Corners in the ToF image, (x, y) = (column, row).
    pub tof_corners: Vec<[f64; 2]>,
    /// The same corners in the PS camera's image.
    pub camera_corners: Vec<[f64; 2]>,
    /// ToF range (axial depth, mm) of the board, when known.
    pub range_mm: Option<f64>,
}

/// The homography of one board position.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationPlane {
    /// ToF range of the board, mm (absent for a single-plane calibration without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub range_mm: Option<f64>,
    /// H (row-major, h₃₃ = 1): camera (x, y, 1) ∝ H·(x_tof, y_tof, 1).
    pub homography: [[f64; 3]; 3],
    /// RMS reprojection error of the corners, camera pixels.
    pub rms_px: f64,
    /// Largest reprojection error, camera pixels.
    pub max_px: f64,
    /// Number of corners used.
    pub corners: usize,
}

/// A saved ToF → PS-camera calibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// ToF image size [width, height].
    pub tof_size: [usize; 2],
    /// PS camera image size [width, height].
    pub camera_size: [usize; 2],
    /// The chequerboard's inner corners, COLSxROWS.
    pub board: String,
    /// Square size in mm, if given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub square_mm: Option<f64>,
    /// One entry per board position, sorted by range.
    #[serde(rename = "plane")]
    pub planes: Vec<CalibrationPlane>,
}

impl Calibration {
    /// Fits one homography per board view (module docs).
    pub fn fit(
        views: &[BoardView],
        tof_size: [usize; 2],
        camera_size: [usize; 2],
        board: BoardSize,
        square_mm: Option<f64>,
    ) -> Result<Self, TofError> {
        if views.is_empty() {
            return Err(TofError::Calibration("no board views given".into()));
        }
        if views.len() > 1 && views.iter().any(|v| v.range_mm.is_none()) {
            return Err(TofError::Calibration(
                "with several board positions every one needs its ToF range (mm)".into(),
            ));
        }
        let mut planes = Vec::with_capacity(views.len());
        for (i, view) in views.iter().enumerate() {
            if view.tof_corners.len() != view.camera_corners.len() || view.tof_corners.len() < 4 {
                return Err(TofError::Calibration(format!(
                    "board {}: {} ToF corners and {} camera corners (need the same number, at least 4)",
                    i + 1,
                    view.tof_corners.len(),
                    view.camera_corners.len()
                )));
            }
            if let Some(r) = view.range_mm
                && !(r.is_finite() && r > 0.0)
            {
                return Err(TofError::Calibration(format!(
                    "board {}: range {r} mm is not a positive number",
                    i + 1
                )));
            }
            let h = fit_homography(&view.tof_corners, &view.camera_corners)
                .map_err(|e| TofError::Calibration(format!("board {}: {e}", i + 1)))?;
            let errors: Vec<f64> = view
                .tof_corners
                .iter()
                .zip(&view.camera_corners)
                .map(|(t, c)| {
                    let p = apply(&h, *t);
                    (p[0] - c[0]).hypot(p[1] - c[1])
                })
                .collect();
            let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
            let max = errors.iter().copied().fold(0.0, f64::max);
            if rms.is_nan() || rms > MAX_RMS_PX {
                return Err(TofError::Calibration(format!(
                    "board {}: corners do not fit one homography (RMS {rms:.2} camera px > {MAX_RMS_PX}); are both images of the same board position, and is the board flat?",
                    i + 1
                )));
            }
            planes.push(CalibrationPlane {
                range_mm: view.range_mm,
                homography: to_rows(&h),
                rms_px: rms,
                max_px: max,
                corners: errors.len(),
            });
        }
        planes.sort_by(|a, b| {
            a.range_mm
                .unwrap_or(0.0)
                .total_cmp(&b.range_mm.unwrap_or(0.0))
        });
        for pair in planes.windows(2) {
            if let (Some(a), Some(b)) = (pair[0].range_mm, pair[1].range_mm)
                && (b - a).abs() < 1.0
            {
                return Err(TofError::Calibration(format!(
                    "two boards at nearly the same range ({a} and {b} mm): interpolating between them is ill-posed"
                )));
            }
        }
        Ok(Self {
            tof_size,
            camera_size,
            board: board.to_string(),
            square_mm,
            planes,
        })
    }

    /// The homography for points at ToF range `range_mm` (module docs); the single plane's when
    /// there is one or the range is unknown.
    pub fn homography_at(&self, range_mm: Option<f64>) -> Matrix3<f64> {
        let matrix = |p: &CalibrationPlane| from_rows(&p.homography);
        match (self.planes.len(), range_mm) {
            (0, _) => Matrix3::identity(),
            (1, _) | (_, None) => matrix(&self.planes[self.planes.len() / 2]),
            (n, Some(s)) => {
                let ranges: Vec<f64> = self
                    .planes
                    .iter()
                    .map(|p| p.range_mm.unwrap_or(0.0))
                    .collect();
                let i = ranges.iter().rposition(|&r| r <= s).unwrap_or(0).min(n - 2);
                let t = (s - ranges[i]) / (ranges[i + 1] - ranges[i]);
                matrix(&self.planes[i]) * (1.0 - t) + matrix(&self.planes[i + 1]) * t
            }
        }
    }

    /// Camera (x, y) of ToF pixel position (x, y) at range `range_mm`.
    pub fn tof_to_camera(&self, tof: [f64; 2], range_mm: Option<f64>) -> [f64; 2] {
        apply(&self.homography_at(range_mm), tof)
    }

    /// ToF (x, y) seen at camera pixel (x, y) by a point at range `range_mm`.
    pub fn camera_to_tof(&self, camera: [f64; 2], range_mm: Option<f64>) -> [f64; 2] {
        let h = self.homography_at(range_mm);
        match h.try_inverse() {
            Some(inv) => apply(&inv, camera),
            None => [f64::NAN; 2],
        }
    }

    /// Checks that this calibration was made for these image sizes ([width, height]).
    pub fn check_sizes(
        &self,
        tof_size: [usize; 2],
        camera_size: [usize; 2],
    ) -> Result<(), TofError> {
        if self.tof_size != tof_size {
            return Err(TofError::CalibrationMismatch(format!(
                "it was made for {}x{} ToF images but the range map is {}x{}",
                self.tof_size[0], self.tof_size[1], tof_size[0], tof_size[1]
            )));
        }
        if self.camera_size != camera_size {
            return Err(TofError::CalibrationMismatch(format!(
                "it was made for {}x{} camera images but the camera is {}x{}",
                self.camera_size[0], self.camera_size[1], camera_size[0], camera_size[1]
            )));
        }
        Ok(())
    }

    /// Parses a calibration from TOML text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Self, TofError> {
        let calibration: Self = toml::from_str(text).map_err(|e| TofError::File {
            path: origin.to_path_buf(),
            reason: format!("not a meb ToF calibration: {e}"),
        })?;
        calibration.validate().map_err(|reason| TofError::File {
            path: origin.to_path_buf(),
            reason,
        })?;
        Ok(calibration)
    }

    /// Reads a calibration file.
    pub fn load(path: &Path) -> Result<Self, TofError> {
        let text = std::fs::read_to_string(path).map_err(|e| TofError::File {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Self::from_toml_str(&text, path)
    }

    /// The calibration as TOML text.
    pub fn to_toml_string(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks sizes, plane count and finite, invertible homographies.
    fn validate(&self) -> Result<(), String> {
        if self.tof_size.contains(&0) || self.camera_size.contains(&0) {
            return Err("image sizes must be positive".into());
        }
        if self.planes.is_empty() {
            return Err("no [[plane]] entry".into());
        }
        if self.planes.len() > 1 && self.planes.iter().any(|p| p.range_mm.is_none()) {
            return Err("with several planes every one needs range_mm".into());
        }
        for (i, p) in self.planes.iter().enumerate() {
            let h = from_rows(&p.homography);
            if !h.iter().all(|v| v.is_finite()) || h.determinant().abs() < 1e-12 {
                return Err(format!(
                    "plane {}: the homography is not finite and invertible",
                    i + 1
                ));
            }
        }
        Ok(())
    }
}

/// H·(x, y, 1) dehomogenised.
pub fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let v = h * Vector3::new(p[0], p[1], 1.0);
    [v.x / v.z, v.y / v.z]
}

fn to_rows(h: &Matrix3<f64>) -> [[f64; 3]; 3] {
    let s = if h[(2, 2)].abs() > 1e-12 {
        h[(2, 2)]
    } else {
        1.0
    };
    [0, 1, 2].map(|r| [0, 1, 2].map(|c| h[(r, c)] / s))
}

fn from_rows(rows: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| rows[r][c])
}

/// Hartley's normalising similarity of `points`: centroid to the origin, mean distance √2;
/// `None` when the points coincide.
fn normalising_transform(points: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = points.len() as f64;
    let cx = points.iter().map(|p| p[0]).sum::<f64>() / n;
    let cy = points.iter().map(|p| p[1]).sum::<f64>() / n;
    let mean = points
        .iter()
        .map(|p| (p[0] - cx).hypot(p[1] - cy))
        .sum::<f64>()
        / n;
    if !(mean.is_finite() && mean > 1e-12) {
        return None;
    }
    let k = std::f64::consts::SQRT_2 / mean;
    Some(Matrix3::new(
        k,
        0.0,
        -k * cx,
        0.0,
        k,
        -k * cy,
        0.0,
        0.0,
        1.0,
    ))
}

/// The homography from `src` to `dst` points: normalised DLT, then Gauss–Newton on the
/// reprojection error (module docs).
fn fit_homography(src: &[[f64; 2]], dst: &[[f64; 2]]) -> Result<Matrix3<f64>, String> {
    let collinear =
        || "the corners do not determine a homography (are they collinear?)".to_string();
    let (Some(ts), Some(td)) = (normalising_transform(src), normalising_transform(dst)) else {
        return Err(collinear());
    };
    // Σ aᵀa over the two DLT rows of every correspondence (x, y) → (u, v), normalised:
    //   [−x −y −1  0  0  0  u·x  u·y  u]
    //   [ 0  0  0 −x −y −1  v·x  v·y  v]
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (s, d) in src.iter().zip(dst) {
        let p = ts * Vector3::new(s[0], s[1], 1.0);
        let q = td * Vector3::new(d[0], d[1], 1.0);
        let (x, y, u, v) = (p.x, p.y, q.x, q.y);
        let rows = [
            [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u],
            [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v],
        ];
        for a in rows {
            let a = SMatrix::<f64, 9, 1>::from(a);
            ata += a * a.transpose();
        }
    }
    let eigen = ata.symmetric_eigen();
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    // A unique solution needs a one-dimensional null space: the second-smallest eigenvalue
    // clearly above zero (collinear corners leave several).
    let largest = eigen.eigenvalues[order[8]];
    let second = eigen.eigenvalues[order[1]];
    if second.is_nan() || second <= 1e-9 * largest {
        return Err(collinear());
    }
    let h = eigen.eigenvectors.column(order[0]);
    let normalised = Matrix3::from_fn(|r, c| h[3 * r + c]);
    let h = td.try_inverse().ok_or_else(collinear)? * normalised * ts;
    // A rank-deficient H maps the board onto a line or a point: no homography.
    let scale = h.norm();
    if !(scale.is_finite() && scale > 0.0) || (h / scale).determinant().abs() < 1e-12 {
        return Err(collinear());
    }
    Ok(refine(h, src, dst))
}

/// Gauss–Newton refinement of H (h₃₃ = 1) on the reprojection error Σ|H(src) − dst|².
fn refine(mut h: Matrix3<f64>, src: &[[f64; 2]], dst: &[[f64; 2]]) -> Matrix3<f64> {
    if h[(2, 2)].abs() > 1e-12 {
        h /= h[(2, 2)];
    }
    let cost = |h: &Matrix3<f64>| {
        src.iter()
            .zip(dst)
            .map(|(s, d)| {
                let p = apply(h, *s);
                (p[0] - d[0]).powi(2) + (p[1] - d[1]).powi(2)
            })
            .sum::<f64>()
    };
    for _ in 0..10 {
        let mut jtj = nalgebra::SMatrix::<f64, 8, 8>::zeros();
        let mut jtr = nalgebra::SVector::<f64, 8>::zeros();
        for (s, d) in src.iter().zip(dst) {
            let v = h * Vector3::new(s[0], s[1], 1.0);
            let (x, y, w) = (v.x, v.y, v.z);
            let (u, vv) = (x / w, y / w);
            let basis = [s[0], s[1], 1.0];
            let mut jx = nalgebra::SVector::<f64, 8>::zeros();
            let mut jy = nalgebra::SVector::<f64, 8>::zeros();
            for k in 0..3 {
                jx[k] = basis[k] / w;
                jy[3 + k] = basis[k] / w;
            }
            for k in 0..2 {
                jx[6 + k] = -u * basis[k] / w;
                jy[6 + k] = -vv * basis[k] / w;
            }
            jtj += jx * jx.transpose() + jy * jy.transpose();
            jtr += jx * (u - d[0]) + jy * (vv - d[1]);
        }
        let Some(step) = jtj.lu().solve(&jtr) else {
            break;
        };
        let mut next = h;
        for k in 0..8 {
            next[(k / 3, k % 3)] -= step[k];
        }
        if cost(&next) >= cost(&h) {
            break;
        }
        h = next;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(cols: usize, rows: usize) -> Vec<[f64; 2]> {
        (0..rows)
            .flat_map(|r| (0..cols).map(move |c| [20.0 + 9.5 * c as f64, 15.0 + 9.1 * r as f64]))
            .collect()
    }

    #[test]
    fn recovers_a_projective_homography_and_round_trips_through_toml() {
        let truth = Matrix3::new(4.1, 0.2, 30.0, -0.15, 3.9, 12.0, 2e-4, -1e-4, 1.0);
        let tof = grid(9, 6);
        let cam: Vec<[f64; 2]> = tof.iter().map(|p| apply(&truth, *p)).collect();
        let view = BoardView {
            tof_corners: tof.clone(),
            camera_corners: cam,
            range_mm: None,
        };
        let board = BoardSize { cols: 9, rows: 6 };
        let c = Calibration::fit(&[view], [192, 128], [1280, 720], board, Some(20.0)).unwrap();
        assert!(c.planes[0].rms_px < 1e-6, "{}", c.planes[0].rms_px);
        let back = Calibration::from_toml_str(&c.to_toml_string(), Path::new("t.toml")).unwrap();
        assert_eq!(back, c);
        let p = back.tof_to_camera([100.0, 60.0], None);
        let q = back.camera_to_tof(p, None);
        assert!((q[0] - 100.0).abs() < 1e-9 && (q[1] - 60.0).abs() < 1e-9);
        assert!(c.check_sizes([192, 128], [640, 360]).is_err());
    }

    #[test]
    fn two_planes_interpolate_in_range_and_bad_views_are_refused() {
        let board = BoardSize { cols: 9, rows: 6 };
        let near = Matrix3::new(5.0, 0.0, 10.0, 0.0, 5.0, 20.0, 0.0, 0.0, 1.0);
        let far = Matrix3::new(4.0, 0.0, 60.0, 0.0, 4.0, 50.0, 0.0, 0.0, 1.0);
        let view = |h: &Matrix3<f64>, r: f64| BoardView {
            tof_corners: grid(9, 6),
            camera_corners: grid(9, 6).iter().map(|p| apply(h, *p)).collect(),
            range_mm: Some(r),
        };
        let c = Calibration::fit(
            &[view(&far, 1000.0), view(&near, 800.0)],
            [192, 128],
            [1280, 720],
            board,
            None,
        )
        .unwrap();
        assert_eq!(c.planes[0].range_mm, Some(800.0));
        let mid = c.tof_to_camera([10.0, 10.0], Some(900.0));
        assert!((mid[0] - 0.5 * (60.0 + 100.0)).abs() < 1e-6, "{mid:?}");

        let mut shuffled = view(&near, 800.0);
        shuffled.camera_corners.swap(0, 30);
        shuffled.camera_corners.swap(5, 40);
        let err = Calibration::fit(&[shuffled], [192, 128], [1280, 720], board, None).unwrap_err();
        assert!(err.to_string().contains("RMS"), "{err}");
        let mut unranged = view(&far, 1000.0);
        unranged.range_mm = None;
        assert!(
            Calibration::fit(
                &[view(&near, 800.0), unranged],
                [192, 128],
                [1280, 720],
                board,
                None
            )
            .is_err()
        );
        assert!(Calibration::from_toml_str("tof_size = [1, 1]", Path::new("x.toml")).is_err());
    }

    /// Noisy corners: the DLT + Gauss–Newton fit is as close to the truth as the noise allows
    /// (σ = 0.1 px on each coordinate of 54 corners: measured 0.128 px at the worst grid point,
    /// about σ·√(8/54)·3 of a least-squares fit of 8 parameters), with no OpenCV in the loop.
    #[test]
    fn noisy_corners_fit_within_the_noise_and_collinear_ones_are_refused() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let truth = Matrix3::new(6.2, 0.3, 120.0, -0.2, 5.8, 40.0, 3e-4, 2e-4, 1.0);
        let tof = grid(9, 6);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise = Normal::new(0.0, 0.1).unwrap();
        let cam: Vec<[f64; 2]> = tof
            .iter()
            .map(|p| {
                let q = apply(&truth, *p);
                [q[0] + noise.sample(&mut rng), q[1] + noise.sample(&mut rng)]
            })
            .collect();
        let h = fit_homography(&tof, &cam).unwrap();
        let worst = tof
            .iter()
            .map(|p| {
                let (a, b) = (apply(&h, *p), apply(&truth, *p));
                (a[0] - b[0]).hypot(a[1] - b[1])
            })
            .fold(0.0, f64::max);
        assert!(worst < 0.2, "worst deviation from the true H: {worst} px");

        let line: Vec<[f64; 2]> = (0..8).map(|k| [k as f64, 2.0 * k as f64]).collect();
        let err = fit_homography(&line, &line).unwrap_err();
        assert!(err.contains("collinear"), "{err}");
        assert!(fit_homography(&[[1.0, 1.0]; 5], &[[2.0, 2.0]; 5]).is_err());
    }
}
