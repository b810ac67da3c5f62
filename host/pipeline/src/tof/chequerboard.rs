//! Chequerboard corner detection in the SPAD's photon-counting image and the PS camera's image
//! (thesis §6.4), through OpenCV when meb is built with the `opencv` feature (the only part of
//! meb that needs it; without it [`find_corners`] refuses and says how to rebuild): `findChessboardCorners` (quad detection), or, when that fails
//! (low-resolution, noisy SPAD images), the sector-based `findChessboardCornersSB` of Duda &
//! Frese ("Accurate detection and localization of checkerboard corners for calibration",
//! BMVC 2018); then `cornerSubPix` in a window of a third of a square. On rendered boards the
//! quad detector + `cornerSubPix` was the more accurate pair (worst corner 0.08 px vs 0.16 px
//! for the sector-based detector).
//!
//! Corners are returned as (x, y) = (column, row) with integer values at pixel centres, in
//! row-major board order starting from the corner nearest the image's top-left, so the two
//! cameras' lists correspond point by point.

use super::TofError;
use ndarray::Array2;

/// Whether this build can find chequerboard corners (built with the `opencv` feature).
pub const CORNER_DETECTOR: bool = cfg!(feature = "opencv");

/// Refuses, before any work, when this build has no corner detector.
pub fn require_corner_detector() -> Result<(), TofError> {
    if CORNER_DETECTOR {
        Ok(())
    } else {
        Err(TofError::NoCornerDetector)
    }
}

/// Inner-corner counts of a chequerboard (squares − 1 along each side).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct BoardSize {
    /// Inner corners along a row.
    pub cols: usize,
    /// Inner corners along a column.
    pub rows: usize,
}

impl BoardSize {
    /// Parses `COLSxROWS`, e.g. `9x6`.
    pub fn parse(text: &str) -> Result<Self, TofError> {
        let bad = || TofError::Invalid {
            field: "board".into(),
            reason: format!("`{text}` is not COLSxROWS inner corners, e.g. 9x6"),
        };
        let (c, r) = text.split_once(['x', 'X']).ok_or_else(bad)?;
        let cols: usize = c.trim().parse().map_err(|_| bad())?;
        let rows: usize = r.trim().parse().map_err(|_| bad())?;
        if cols < 2 || rows < 2 || cols > 100 || rows > 100 {
            return Err(TofError::Invalid {
                field: "board".into(),
                reason: format!("{cols}x{rows}: need 2 to 100 inner corners each way"),
            });
        }
        Ok(Self { cols, rows })
    }

    /// Number of inner corners.
    pub fn corners(&self) -> usize {
        self.cols * self.rows
    }
}

impl std::fmt::Display for BoardSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.cols, self.rows)
    }
}

/// Finds the inner corners of `board` in a grey `image` (any scale); `which` names the image
/// in errors.
pub fn find_corners(
    image: &Array2<f32>,
    board: BoardSize,
    which: &str,
) -> Result<Vec<[f64; 2]>, TofError> {
    let not_found = |reason: String| TofError::BoardNotFound {
        image: which.into(),
        cols: board.cols,
        rows: board.rows,
        reason,
    };
    require_corner_detector()?;
    let grey = to_u8(image).ok_or_else(|| not_found("the image is blank".into()))?;
    let points = opencv_detector::detect(&grey, image.dim(), board).map_err(not_found)?;
    Ok(canonical_order(points, board))
}

/// OpenCV's detectors (module docs).
#[cfg(feature = "opencv")]
mod opencv_detector {
    use super::BoardSize;
    use opencv::core::{
        Mat, Point2f, Size, TermCriteria, TermCriteria_COUNT, TermCriteria_EPS, Vector,
    };
    use opencv::{calib3d, imgproc};

    /// The corners of `board` in the 8-bit image `grey` of (rows, cols), in OpenCV's order;
    /// the error says why none were found.
    pub fn detect(
        grey: &[u8],
        (rows, cols): (usize, usize),
        board: BoardSize,
    ) -> Result<Vec<[f64; 2]>, String> {
        let cv = |e: opencv::Error| format!("OpenCV: {e}");
        let mat = Mat::new_rows_cols_with_data(rows as i32, cols as i32, grey).map_err(cv)?;
        let size = Size::new(board.cols as i32, board.rows as i32);
        let mut corners = Vector::<Point2f>::new();
        let complete =
            |found: bool, corners: &Vector<Point2f>| found && corners.len() == board.corners();
        let found = calib3d::find_chessboard_corners(
            &mat,
            size,
            &mut corners,
            calib3d::CALIB_CB_ADAPTIVE_THRESH | calib3d::CALIB_CB_NORMALIZE_IMAGE,
        )
        .map_err(cv)?;
        if !complete(found, &corners) {
            corners.clear();
            let found = calib3d::find_chessboard_corners_sb(
                &mat,
                size,
                &mut corners,
                calib3d::CALIB_CB_NORMALIZE_IMAGE | calib3d::CALIB_CB_EXHAUSTIVE,
            )
            .map_err(cv)?;
            if !complete(found, &corners) {
                return Err(format!(
                    "neither OpenCV detector found all {} inner corners (check that COLSxROWS counts inner corners, that the whole board is in view with a light border, and the focus/exposure)",
                    board.corners()
                ));
            }
        }
        // Refine within a window of about a third of a square (corner spacing along a row).
        let spacing = corners
            .iter()
            .zip(corners.iter().skip(1))
            .take(board.cols - 1)
            .map(|(a, b)| f64::from((b.x - a.x).hypot(b.y - a.y)))
            .sum::<f64>()
            / (board.cols - 1) as f64;
        let half = (spacing * 0.35).round().clamp(2.0, 10.0) as i32;
        let criteria =
            TermCriteria::new(TermCriteria_COUNT + TermCriteria_EPS, 50, 1e-3).map_err(cv)?;
        imgproc::corner_sub_pix(
            &mat,
            &mut corners,
            Size::new(half, half),
            Size::new(-1, -1),
            criteria,
        )
        .map_err(cv)?;
        Ok(corners
            .iter()
            .map(|p| [f64::from(p.x), f64::from(p.y)])
            .collect())
    }
}

/// Stands in for OpenCV in a build without it: never reached, [`require_corner_detector`]
/// refuses first.
#[cfg(not(feature = "opencv"))]
mod opencv_detector {
    use super::BoardSize;

    /// Always refuses (module docs).
    pub fn detect(
        _grey: &[u8],
        _size: (usize, usize),
        _board: BoardSize,
    ) -> Result<Vec<[f64; 2]>, String> {
        Err("this build has no corner detector".into())
    }
}

/// Scales `image` to 8 bits between its 0.5 % and 99.5 % quantiles; `None` if it is flat.
fn to_u8(image: &Array2<f32>) -> Option<Vec<u8>> {
    let mut finite: Vec<f32> = image.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        return None;
    }
    let q = |p: f64, v: &mut Vec<f32>| {
        let k = ((v.len() - 1) as f64 * p).round() as usize;
        *v.select_nth_unstable_by(k, f32::total_cmp).1
    };
    let lo = q(0.005, &mut finite);
    let hi = q(0.995, &mut finite);
    if hi <= lo {
        return None;
    }
    Some(
        image
            .iter()
            .map(|&v| {
                if v.is_finite() {
                    ((v - lo) / (hi - lo) * 255.0).clamp(0.0, 255.0).round() as u8
                } else {
                    0
                }
            })
            .collect(),
    )
}

/// Puts the corners in row-major order from the one nearest the image's top-left: reverses
/// the list when it starts at the far end, and transposes a square board's order when its rows
/// run vertically.
fn canonical_order(mut points: Vec<[f64; 2]>, board: BoardSize) -> Vec<[f64; 2]> {
    let score = |p: &[f64; 2]| p[0] + p[1];
    if let (Some(first), Some(last)) = (points.first(), points.last())
        && score(first) > score(last)
    {
        points.reverse();
    }
    if board.cols == board.rows && points.len() > 1 {
        let d = [points[1][0] - points[0][0], points[1][1] - points[0][1]];
        if d[1].abs() > d[0].abs() {
            let n = board.cols;
            points = (0..n * n).map(|i| points[(i % n) * n + i / n]).collect();
        }
    }
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A build without OpenCV refuses before any work, saying how to rebuild; a build with it
    /// goes on. (CI tests the build with the feature; `meb tof calibrate`'s refusal in the
    /// default build is the CLI test `tof_cli::calibrate_without_opencv_refuses_…`.)
    #[test]
    fn the_corner_detector_is_refused_exactly_in_a_build_without_opencv() {
        assert_eq!(CORNER_DETECTOR, cfg!(feature = "opencv"));
        let gate = require_corner_detector();
        assert_eq!(gate.is_ok(), cfg!(feature = "opencv"), "{gate:?}");
        if let Err(error) = gate {
            assert!(matches!(error, TofError::NoCornerDetector), "{error}");
        }
        let text = TofError::NoCornerDetector.to_string();
        assert!(text.contains("built without OpenCV"), "{text}");
        assert!(text.contains("--features opencv"), "{text}");
        assert!(text.contains("scripts/setup.sh"), "{text}");
    }

    /// A rendered board (anti-aliased by 4×4 supersampling) with a known affine placement.
    fn board_image(
        rows: usize,
        cols: usize,
        board: BoardSize,
        origin: [f64; 2],
        square: f64,
        angle: f64,
    ) -> (Array2<f32>, Vec<[f64; 2]>) {
        let (s, c) = angle.sin_cos();
        // Board coordinates (u, v) in squares; pixel = origin + square·R·(u, v).
        let to_board = |x: f64, y: f64| {
            let (dx, dy) = (x - origin[0], y - origin[1]);
            ((c * dx + s * dy) / square, (-s * dx + c * dy) / square)
        };
        let image = Array2::from_shape_fn((rows, cols), |(r, cc)| {
            let mut sum = 0.0;
            for i in 0..4 {
                for j in 0..4 {
                    let x = cc as f64 - 0.5 + (j as f64 + 0.5) / 4.0;
                    let y = r as f64 - 0.5 + (i as f64 + 0.5) / 4.0;
                    let (u, v) = to_board(x, y);
                    let inside =
                        u > -1.0 && v > -1.0 && u < board.cols as f64 && v < board.rows as f64;
                    let dark = inside && (u.floor() as i64 + v.floor() as i64).rem_euclid(2) == 0;
                    sum += if dark { 0.1 } else { 0.9 };
                }
            }
            (sum / 16.0) as f32
        });
        let corners = (0..board.rows)
            .flat_map(|v| (0..board.cols).map(move |u| (u, v)))
            .map(|(u, v)| {
                let (u, v) = (u as f64 * square, v as f64 * square);
                [origin[0] + c * u - s * v, origin[1] + s * u + c * v]
            })
            .collect();
        (image, corners)
    }

    #[test]
    #[cfg_attr(not(feature = "opencv"), ignore = "needs the opencv feature")]
    fn finds_rotated_board_to_a_tenth_of_a_pixel_in_order() {
        let board = BoardSize::parse("7x5").unwrap();
        let (image, truth) = board_image(120, 160, board, [30.3, 28.7], 14.2, 0.12);
        let found = find_corners(&image, board, "test").unwrap();
        assert_eq!(found.len(), 35);
        let worst = found
            .iter()
            .zip(&truth)
            .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
            .fold(0.0, f64::max);
        let mean = found.iter().zip(&truth).fold([0.0, 0.0], |m, (a, b)| {
            [m[0] + (a[0] - b[0]) / 35.0, m[1] + (a[1] - b[1]) / 35.0]
        });
        assert!(
            worst < 0.1,
            "worst corner error {worst} px, mean offset {mean:?}"
        );
    }

    #[test]
    #[cfg_attr(not(feature = "opencv"), ignore = "needs the opencv feature")]
    fn blank_images_and_bad_board_sizes_are_refused() {
        let board = BoardSize { cols: 7, rows: 5 };
        let err = find_corners(&Array2::from_elem((50, 60), 0.5), board, "ToF").unwrap_err();
        assert!(matches!(err, TofError::BoardNotFound { .. }), "{err}");
        let (image, _) = board_image(120, 160, board, [30.0, 30.0], 14.0, 0.0);
        let err = find_corners(&image, BoardSize { cols: 9, rows: 6 }, "camera").unwrap_err();
        assert!(err.to_string().contains("9x6"), "{err}");
        assert!(BoardSize::parse("9by6").is_err());
        assert!(BoardSize::parse("1x6").is_err());
    }

    #[test]
    #[cfg_attr(feature = "opencv", ignore = "this build has OpenCV")]
    fn without_opencv_corner_finding_refuses_and_says_how_to_rebuild() {
        let board = BoardSize { cols: 7, rows: 5 };
        let (image, _) = board_image(120, 160, board, [30.0, 30.0], 14.0, 0.0);
        let err = find_corners(&image, board, "camera").unwrap_err();
        assert!(matches!(err, TofError::NoCornerDetector), "{err}");
        let text = err.to_string();
        assert!(text.contains("--features opencv"), "{text}");
        assert!(require_corner_detector().is_err());
    }
}
