//! Normal maps with a camera: 8-bit RGB normal-map images, 3×3 intrinsics files (`K.txt`), and
//! the normal-integration benchmark layout of Cao, Lin, Matsushita & Tao, "Bilateral Normal
//! Integration" (ECCV 2022) over DiLiGenT (Shi et al., CVPR 2016): per object `normal_map.png`,
//! `mask.png`, `K.txt` and `depth_gt.npz` (`depth_gt`, distance from the camera along the
//! optical axis in mm, NaN outside the object).
//!
//! The benchmark's score, mean absolute depth error (MADE, [`mean_absolute_depth_error`]),
//! compares depth up to scale: the estimate is multiplied by median(d_gt / d) over the mask,
//! then MADE = mean |s·d − d_gt| over the mask.

use super::{DatasetError, diligent::read_rows};
use crate::rig::Intrinsics;
use ndarray::{Array2, Array3};
use std::path::Path;

/// One object of the normal-integration benchmark.
#[derive(Debug, Clone)]
pub struct NormalIntegrationObject {
    /// Unit normals H×W×3 (x right, y up, z towards the camera), NaN outside the mask.
    pub normals: Array3<f32>,
    /// The integration domain.
    pub mask: Array2<bool>,
    /// The pinhole intrinsics (no distortion).
    pub intrinsics: Intrinsics,
    /// Ground-truth distance along the optical axis in mm (NaN outside the object).
    pub depth_gt: Array2<f32>,
}

/// Reads an 8- or 16-bit RGB normal-map image: n = rgb·2 − 1 with rgb in [0, 1], normalised to
/// unit length (x right, y up, z towards the camera). Pixels with a zero normal become NaN.
pub fn read_normal_map(path: &Path) -> Result<Array3<f32>, DatasetError> {
    let img = image::open(path)
        .map_err(|e| DatasetError::format(path, format!("cannot decode image: {e}")))?
        .into_rgb32f();
    let (w, h) = img.dimensions();
    let mut normals = Array3::from_elem((h as usize, w as usize, 3), f32::NAN);
    for (c, r, p) in img.enumerate_pixels() {
        let n = p.0.map(|v| 2.0 * v - 1.0);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len > 0.0 {
            for (j, v) in n.iter().enumerate() {
                normals[(r as usize, c as usize, j)] = v / len;
            }
        }
    }
    Ok(normals)
}

/// Reads pinhole intrinsics from a 3×3 matrix file (`K.txt`: rows "fx 0 cx", "0 fy cy",
/// "0 0 1", whitespace- or comma-separated; OpenCV convention, pixel centres at integer
/// coordinates, rows down).
pub fn read_intrinsics_matrix(path: &Path) -> Result<Intrinsics, DatasetError> {
    let rows = read_rows(path, 3)?;
    if rows.len() != 3 {
        return Err(DatasetError::format(
            path,
            format!("expected 3 rows of a 3×3 matrix, found {}", rows.len()),
        ));
    }
    let (fx, fy, cx, cy) = (rows[0][0], rows[1][1], rows[0][2], rows[1][2]);
    let skew_free = rows[1][0] == 0.0 && rows[0][1].abs() <= 1e-9 * fx.abs();
    let last_row = rows[2] == [0.0, 0.0, 1.0];
    if !(fx > 0.0 && fy > 0.0 && skew_free && last_row) {
        return Err(DatasetError::format(
            path,
            "expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
        ));
    }
    Ok(Intrinsics {
        fx,
        fy,
        cx,
        cy,
        k1: 0.0,
        k2: 0.0,
    })
}

/// Loads one benchmark object folder (module docs); checks that every file has the normal
/// map's size.
pub fn load_normal_integration_object(dir: &Path) -> Result<NormalIntegrationObject, DatasetError> {
    let normals = read_normal_map(&dir.join("normal_map.png"))?;
    let shape = (normals.dim().0, normals.dim().1);
    let mask = crate::io::read_mask(&dir.join("mask.png"))?;
    let intrinsics = read_intrinsics_matrix(&dir.join("K.txt"))?;
    let depth_path = dir.join("depth_gt.npz");
    let bytes = std::fs::read(&depth_path).map_err(|source| DatasetError::Io {
        path: depth_path.clone(),
        source,
    })?;
    // float32 in the benchmark; float64 accepted too.
    let read = |as_f64: bool| -> Result<Array2<f32>, ndarray_npy::ReadNpzError> {
        let mut npz = ndarray_npy::NpzReader::new(std::io::Cursor::new(&bytes))?;
        if as_f64 {
            let depth: Array2<f64> = npz.by_name("depth_gt")?;
            Ok(depth.mapv(|v| v as f32))
        } else {
            npz.by_name("depth_gt")
        }
    };
    let depth_gt = read(false)
        .or_else(|_| read(true))
        .map_err(|e| DatasetError::format(&depth_path, format!("depth_gt: {e}")))?;
    for (what, got) in [("mask.png", mask.dim()), ("depth_gt", depth_gt.dim())] {
        if got != shape {
            return Err(DatasetError::format(
                dir,
                format!("{what} is {got:?} but normal_map.png is {shape:?} (rows, columns)"),
            ));
        }
    }
    Ok(NormalIntegrationObject {
        normals,
        mask,
        intrinsics,
        depth_gt,
    })
}

/// The benchmark's score of an estimated distance along the optical axis `depth` (any scale)
/// against `depth_gt`, in the ground truth's unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthScore {
    /// Mean absolute depth error after scaling (MADE).
    pub made: f64,
    /// The scale median(d_gt / d) applied to the estimate.
    pub scale: f64,
    /// Pixels of the mask where both depths are finite and positive.
    pub compared: usize,
    /// Pixels of the mask without a finite estimate.
    pub missing: usize,
}

/// MADE of `depth` against `depth_gt` over `mask` (module docs); `None` when no pixel of the
/// mask has both depths finite and positive.
pub fn mean_absolute_depth_error(
    depth: &Array2<f32>,
    depth_gt: &Array2<f32>,
    mask: &Array2<bool>,
) -> Option<DepthScore> {
    let mut pairs = Vec::new();
    let mut missing = 0;
    for ((p, &m), &d) in mask.indexed_iter().zip(depth.iter()) {
        if !m {
            continue;
        }
        let (d, g) = (f64::from(d), f64::from(depth_gt[p]));
        if d.is_finite() && d > 0.0 && g.is_finite() && g > 0.0 {
            pairs.push((d, g));
        } else if !d.is_finite() {
            missing += 1;
        }
    }
    if pairs.is_empty() {
        return None;
    }
    let mut ratios: Vec<f64> = pairs.iter().map(|(d, g)| g / d).collect();
    let mid = ratios.len() / 2;
    let (_, &mut median, _) = ratios.select_nth_unstable_by(mid, f64::total_cmp);
    let made = pairs
        .iter()
        .map(|(d, g)| (median * d - g).abs())
        .sum::<f64>()
        / pairs.len() as f64;
    Some(DepthScore {
        made,
        scale: median,
        compared: pairs.len(),
        missing,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn made_is_scale_free_and_counts_missing_pixels() {
        let gt = Array2::from_shape_fn((4, 5), |(r, c)| 1000.0 + (r * 5 + c) as f32);
        let mask = Array2::from_shape_fn((4, 5), |(r, _)| r > 0);
        let mut est = gt.mapv(|v| v / 3.0);
        let score = mean_absolute_depth_error(&est, &gt, &mask).unwrap();
        assert!(score.made < 1e-3, "{score:?}");
        assert!((score.scale - 3.0).abs() < 1e-6);
        assert_eq!((score.compared, score.missing), (15, 0));
        est[(1, 1)] = f32::NAN;
        est[(2, 2)] += 10.0 / 3.0;
        let score = mean_absolute_depth_error(&est, &gt, &mask).unwrap();
        assert_eq!((score.compared, score.missing), (14, 1));
        assert!((score.made - 10.0 / 14.0).abs() < 1e-3, "{score:?}");
        assert!(mean_absolute_depth_error(&est, &gt, &Array2::from_elem((4, 5), false)).is_none());
    }

    #[test]
    fn intrinsics_matrix_must_be_a_pinhole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("K.txt");
        std::fs::write(&path, "500 0 320\n0 510 240\n0 0 1\n").unwrap();
        let k = read_intrinsics_matrix(&path).unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (500.0, 510.0, 320.0, 240.0));
        std::fs::write(&path, "500 0 320\n0 510 240\n").unwrap();
        assert!(read_intrinsics_matrix(&path).is_err());
        std::fs::write(&path, "-500 0 320\n0 510 240\n0 0 1\n").unwrap();
        assert!(read_intrinsics_matrix(&path).is_err());
    }
}
