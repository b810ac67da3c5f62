//! Ground truth for the 3-D frames of a video: the true depth at the time a window was
//! filmed.
//!
//! A [`TruthSource`] answers, for the camera frames a window decoded, with a depth map of the
//! scene at (or near) the middle of those frames. [`TruthFolder`] reads them from files: one
//! `depth.npy` for a still scene, or `depth_FFFFF.npy` files named by the camera frame whose
//! start they describe (`meb simulate --truth-every K` writes them under `truth/`); a window
//! is compared with the file nearest its middle, when that is within a quarter of the
//! decoded frames of it.

use super::VideoError;
use meb_core::io::read_float;
use ndarray::{Array2, Ix2};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The true depth for a window.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthDepth {
    /// Depth in mm, NaN off the object.
    pub depth_mm: Array2<f32>,
    /// Camera frame (fractional) the depth describes.
    pub frame: f64,
}

/// Ground truth for windows of camera frames. `Send`: the decoding stage of [`super::process`]
/// reads each window's truth on its own thread, ahead of the window's reconstruction.
pub trait TruthSource: Send {
    /// The true depth for a window that decoded camera frames `decoded`, or `None` when
    /// there is none near its time.
    fn depth_for(&mut self, decoded: Range<usize>) -> Result<Option<TruthDepth>, VideoError>;
}

/// Truth depth files of `(height, width)` in a folder (module docs).
#[derive(Debug, Clone)]
pub struct TruthFolder {
    shape: (usize, usize),
    /// `(camera frame, file)` sorted by frame; one entry with frame `None` for a still scene.
    files: Vec<(Option<usize>, PathBuf)>,
}

impl TruthFolder {
    /// Finds the truth files in `path`: a depth `.npy` file (a still scene), or a folder with
    /// `depth_FFFFF.npy` files (directly or under `truth/`), or a folder with one `depth.npy`.
    pub fn open(path: &Path, shape: (usize, usize)) -> Result<Self, VideoError> {
        let missing = || {
            VideoError::Truth(format!(
                "{}: no depth .npy file, depth.npy or depth_FFFFF.npy files found",
                path.display()
            ))
        };
        if path.is_file() {
            return Ok(Self {
                shape,
                files: vec![(None, path.to_path_buf())],
            });
        }
        for dir in [path.join("truth"), path.to_path_buf()] {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            let mut files: Vec<(Option<usize>, PathBuf)> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter_map(|p| {
                    let name = p.file_name()?.to_str()?;
                    let frame = name.strip_prefix("depth_")?.strip_suffix(".npy")?;
                    Some((Some(frame.parse().ok()?), p))
                })
                .collect();
            if !files.is_empty() {
                files.sort();
                return Ok(Self { shape, files });
            }
        }
        let single = path.join("depth.npy");
        if single.is_file() {
            return Ok(Self {
                shape,
                files: vec![(None, single)],
            });
        }
        Err(missing())
    }

    /// The camera frames that have a truth file and their files, in frame order (none for a
    /// still scene).
    pub fn files(&self) -> impl Iterator<Item = (usize, &Path)> {
        self.files
            .iter()
            .filter_map(|(frame, path)| frame.map(|f| (f, path.as_path())))
    }
}

impl TruthSource for TruthFolder {
    fn depth_for(&mut self, decoded: Range<usize>) -> Result<Option<TruthDepth>, VideoError> {
        let middle = (decoded.start + decoded.end) as f64 / 2.0;
        let tolerance = (decoded.end - decoded.start) as f64 / 4.0;
        let nearest = self
            .files
            .iter()
            .min_by(|a, b| {
                let distance = |f: &Option<usize>| f.map_or(0.0, |f| (f as f64 - middle).abs());
                distance(&a.0).total_cmp(&distance(&b.0))
            })
            .cloned();
        let Some((frame, path)) = nearest else {
            return Ok(None);
        };
        if frame.is_some_and(|f| (f as f64 - middle).abs() > tolerance) {
            return Ok(None);
        }
        let depth = read_float::<Ix2>(&path, &[Some(self.shape.0), Some(self.shape.1)])?;
        Ok(Some(TruthDepth {
            depth_mm: depth,
            frame: frame.map_or(middle, |f| f as f64),
        }))
    }
}

/// Ground truth for frames binned by a factor ([`meb_core::capture::binning`]): each block's
/// mean depth, NaN where any pixel of the block is off the object (the block's ray passes
/// through its centre, where a smooth surface's depth is the block's mean to second order).
pub struct BinnedTruth<'a> {
    inner: &'a mut dyn TruthSource,
    factor: usize,
}

impl<'a> BinnedTruth<'a> {
    /// The truth of `inner` binned by `factor` (1 or 0: unchanged).
    pub fn new(inner: &'a mut dyn TruthSource, factor: usize) -> Self {
        Self { inner, factor }
    }
}

impl TruthSource for BinnedTruth<'_> {
    fn depth_for(&mut self, decoded: Range<usize>) -> Result<Option<TruthDepth>, VideoError> {
        let truth = self.inner.depth_for(decoded)?;
        if self.factor <= 1 {
            return Ok(truth);
        }
        Ok(truth.map(|t| TruthDepth {
            depth_mm: block_mean(&t.depth_mm, self.factor),
            frame: t.frame,
        }))
    }
}

/// The mean of every whole `k`×`k` block of `depth` (NaN when the block has a NaN).
fn block_mean(depth: &Array2<f32>, k: usize) -> Array2<f32> {
    let (rows, cols) = (depth.nrows() / k, depth.ncols() / k);
    Array2::from_shape_fn((rows, cols), |(r, c)| {
        let block = depth.slice(ndarray::s![r * k..(r + 1) * k, c * k..(c + 1) * k]);
        block.iter().map(|&d| f64::from(d)).sum::<f64>() as f32 / (k * k) as f32
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use meb_core::io::write_npy;

    #[test]
    fn the_nearest_truth_file_within_a_quarter_window_is_used() {
        let dir = tempfile::tempdir().unwrap();
        let truth = dir.path().join("truth");
        std::fs::create_dir(&truth).unwrap();
        for frame in [0usize, 20, 60] {
            let depth = Array2::from_elem((2, 3), frame as f32);
            write_npy(&truth.join(format!("depth_{frame:05}.npy")), &depth).unwrap();
        }
        let mut folder = TruthFolder::open(dir.path(), (2, 3)).unwrap();
        let files: Vec<(usize, &Path)> = folder.files().collect();
        let file_20 = truth.join("depth_00020.npy");
        assert_eq!(files.iter().map(|f| f.0).collect::<Vec<_>>(), [0, 20, 60]);
        assert_eq!(files[1].1, file_20);
        let t = folder.depth_for(4..36).unwrap().unwrap();
        assert_eq!((t.frame, t.depth_mm[(1, 2)]), (20.0, 20.0));
        // Window 44..76 has its middle at 60.
        assert_eq!(folder.depth_for(44..76).unwrap().unwrap().frame, 60.0);
        // Middle 40: the nearest file (20 or 60) is 20 frames away, more than 32 / 4.
        assert!(folder.depth_for(24..56).unwrap().is_none());
        let wrong = TruthFolder::open(dir.path(), (3, 3))
            .unwrap()
            .depth_for(4..36)
            .unwrap_err();
        assert!(wrong.to_string().contains("depth_00020.npy"), "{wrong}");
        assert!(TruthFolder::open(&dir.path().join("nothing"), (2, 3)).is_err());
    }

    /// Binned truth is the block mean, NaN on blocks that leave the object; factor 1 passes
    /// the truth through.
    #[test]
    fn binned_truth_is_the_mean_of_whole_blocks() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("depth.npy");
        let mut depth = Array2::from_shape_fn((4, 5), |(r, c)| (r * 10 + c) as f32);
        depth[(3, 3)] = f32::NAN;
        write_npy(&file, &depth).unwrap();
        let mut folder = TruthFolder::open(&file, (4, 5)).unwrap();
        assert_eq!(
            folder.files().count(),
            0,
            "a still scene's file has no frame"
        );
        let binned = BinnedTruth::new(&mut folder, 2)
            .depth_for(0..8)
            .unwrap()
            .unwrap();
        assert_eq!(binned.depth_mm.dim(), (2, 2));
        assert_eq!(binned.depth_mm[(0, 0)], 5.5);
        assert_eq!(binned.depth_mm[(1, 0)], 25.5);
        assert!(binned.depth_mm[(1, 1)].is_nan());
        let same = BinnedTruth::new(&mut folder, 1)
            .depth_for(0..8)
            .unwrap()
            .unwrap();
        assert_eq!(same.depth_mm.dim(), (4, 5));
    }
}
