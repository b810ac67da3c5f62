//! TCSPC histograms: per-pixel photon arrival-time counts of a SPAD camera (H×W×bins) and the
//! reference histogram they are correlated against (thesis §6.2.2: one histogram of a white
//! board at a known distance, or one per pixel).
//!
//! Counts are read from `.npy` files of any unsigned or signed integer type or float32/64 and
//! held as `f32` (exact up to 2^24 counts per bin).

use super::TofError;
use meb_core::io::{self, FilesError};
use ndarray::{Array, Array1, Array3, Axis, Dimension, Ix1, Ix3};
use std::path::Path;

/// Per-pixel TCSPC histograms: `counts[(row, col, bin)]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Histograms {
    /// H×W×bins photon counts.
    pub counts: Array3<f32>,
}

/// The reference histogram(s) of a white board at a known distance.
#[derive(Debug, Clone, PartialEq)]
pub enum Reference {
    /// One histogram for every pixel, taken where the board crosses the optical axis (its
    /// time is that of the radial distance `reference_distance_mm`).
    Global(Array1<f32>),
    /// One histogram per pixel (H×W×bins) of a board perpendicular to the optical axis at
    /// axial depth `reference_distance_mm`.
    PerPixel(Array3<f32>),
}

impl Histograms {
    /// Number of time bins.
    pub fn bins(&self) -> usize {
        self.counts.dim().2
    }

    /// Image height and width.
    pub fn shape(&self) -> (usize, usize) {
        let (h, w, _) = self.counts.dim();
        (h, w)
    }

    /// Reads H×W×bins counts from a `.npy` file.
    pub fn read(path: &Path) -> Result<Self, TofError> {
        let histograms = Self {
            counts: read_counts::<Ix3>(path, &[None; 3])?,
        };
        histograms.validate()?;
        Ok(histograms)
    }

    /// Checks that there is at least one bin and one photon and that counts are finite and ≥ 0.
    pub fn validate(&self) -> Result<(), TofError> {
        let (h, w, bins) = self.counts.dim();
        if h == 0 || w == 0 || bins < 4 {
            return Err(TofError::Shape {
                what: "histograms".into(),
                detail: format!("{h}×{w}×{bins}: need at least one pixel and 4 time bins"),
            });
        }
        check_counts("histograms", self.counts.view().into_dyn())
    }
}

impl Reference {
    /// Reads a reference: a 1-D `bins` array or an H×W×bins array.
    pub fn read(path: &Path) -> Result<Self, TofError> {
        match read_counts::<Ix1>(path, &[None]) {
            Err(TofError::Files(FilesError::NpyShape { .. })) => {
                Ok(Self::PerPixel(read_counts::<Ix3>(path, &[None; 3])?))
            }
            other => other.map(Self::Global),
        }
    }

    /// Number of time bins.
    pub fn bins(&self) -> usize {
        match self {
            Self::Global(r) => r.len(),
            Self::PerPixel(r) => r.dim().2,
        }
    }

    /// Checks the reference against `histograms`: same number of bins, same image size for a
    /// per-pixel reference, finite non-negative counts, at least one photon.
    pub fn check_against(&self, histograms: &Histograms) -> Result<(), TofError> {
        if self.bins() != histograms.bins() {
            return Err(TofError::Shape {
                what: "reference".into(),
                detail: format!(
                    "it has {} time bins but the histograms have {}; both must come from the same TDC settings",
                    self.bins(),
                    histograms.bins()
                ),
            });
        }
        match self {
            Self::Global(r) => check_counts("reference", r.view().into_dyn()),
            Self::PerPixel(r) => {
                let (h, w, _) = r.dim();
                if (h, w) != histograms.shape() {
                    return Err(TofError::Shape {
                        what: "reference".into(),
                        detail: format!(
                            "per-pixel reference is {w}x{h} pixels but the histograms are {}x{}",
                            histograms.shape().1,
                            histograms.shape().0
                        ),
                    });
                }
                check_counts("reference", r.view().into_dyn())
            }
        }
    }
}

/// Rejects negative or non-finite counts and arrays without a single photon.
fn check_counts(what: &str, counts: ndarray::ArrayViewD<f32>) -> Result<(), TofError> {
    let mut bad = 0usize;
    let mut first = None;
    let mut total = 0.0f64;
    for (index, &v) in counts.indexed_iter() {
        if !(v.is_finite() && v >= 0.0) {
            bad += 1;
            first.get_or_insert_with(|| index.slice().to_vec());
        } else {
            total += f64::from(v);
        }
    }
    if let Some(first) = first {
        return Err(TofError::BadCounts {
            what: what.into(),
            count: bad,
            first,
        });
    }
    if total <= 0.0 {
        return Err(TofError::NoPhotons(what.into()));
    }
    Ok(())
}

/// Reads an `.npy` array of counts of any integer or float element type as `f32`, through
/// the shared file layer (same shape and type checks as every other command's inputs).
fn read_counts<D: Dimension>(
    path: &Path,
    shape: &[Option<usize>],
) -> Result<Array<f32, D>, TofError> {
    macro_rules! attempt {
        ($($t:ty),*) => {
            $(match io::read_exact::<$t, D>(path, shape) {
                Ok(a) => return Ok(a.mapv(|v| v as f32)),
                Err(FilesError::NpyType { .. }) => {}
                Err(e) => return Err(e.into()),
            })*
        };
    }
    attempt!(f32, f64, u16, u32, u64, u8, i16, i32, i64);
    Err(TofError::File {
        path: path.to_path_buf(),
        reason: "photon counts must be an integer or float32/float64 .npy array".into(),
    })
}

/// Sums the histograms of all pixels (the summed-board reference of a per-pixel capture).
pub fn sum_over_pixels(counts: &Array3<f32>) -> Array1<f32> {
    counts
        .sum_axis(Axis(0))
        .sum_axis(Axis(0))
        .mapv(|v| v.max(0.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array;

    #[test]
    fn integer_histograms_read_and_bad_inputs_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.npy");
        let counts = Array::from_shape_fn((2, 3, 8), |(r, c, b)| (r + c + b) as u16);
        meb_core::io::write_npy(&path, &counts).unwrap();
        let h = Histograms::read(&path).unwrap();
        assert_eq!(h.counts[(1, 2, 7)], 10.0);
        assert_eq!(h.bins(), 8);

        let zeros = dir.path().join("z.npy");
        meb_core::io::write_npy(&zeros, &Array3::<u32>::zeros((2, 2, 8))).unwrap();
        let err = Histograms::read(&zeros).unwrap_err();
        assert!(matches!(err, TofError::NoPhotons(_)), "{err}");

        let flat = dir.path().join("flat.npy");
        meb_core::io::write_npy(&flat, &Array1::<f32>::ones(6)).unwrap();
        let err = Histograms::read(&flat).unwrap_err().to_string();
        assert!(err.contains("3-D") && err.contains("1-D, 6"), "{err}");

        let reference = Reference::Global(Array1::ones(6));
        let err = reference.check_against(&h).unwrap_err().to_string();
        assert!(
            err.contains("6 time bins") && err.contains("have 8"),
            "{err}"
        );

        let mut negative = h.clone();
        negative.counts[(0, 1, 2)] = -1.0;
        assert!(matches!(
            negative.validate(),
            Err(TofError::BadCounts { count: 1, .. })
        ));
    }
}
