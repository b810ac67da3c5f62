//! TCSPC histograms: per-pixel photon arrival-time counts of a SPAD camera (H×W×bins) and the
//! reference histogram they are correlated against (thesis §6.2.2: one histogram of a white
//! board at a known distance, or one per pixel).
//!
//! Counts are read from `.npy` files of any unsigned or signed integer type or float32/64 and
//! held as `f32` (exact up to 2^24 counts per bin).

use super::TofError;
use ndarray::{Array1, Array3, ArrayD, Axis, Dimension, Ix1, Ix3};
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
        let array = read_counts(path)?;
        let counts = array
            .into_dimensionality::<Ix3>()
            .map_err(|e| file_error(path, format!("expected an H×W×bins array ({e})")))?;
        let histograms = Self { counts };
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
        let array = read_counts(path)?;
        let reference = match array.ndim() {
            1 => Self::Global(
                array
                    .into_dimensionality::<Ix1>()
                    .map_err(|e| file_error(path, e.to_string()))?,
            ),
            3 => Self::PerPixel(
                array
                    .into_dimensionality::<Ix3>()
                    .map_err(|e| file_error(path, e.to_string()))?,
            ),
            n => {
                return Err(file_error(
                    path,
                    format!("a reference is 1-D (bins) or 3-D (H×W×bins), this one has {n} axes"),
                ));
            }
        };
        Ok(reference)
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

fn file_error(path: &Path, reason: String) -> TofError {
    TofError::File {
        path: path.to_path_buf(),
        reason,
    }
}

/// Reads an `.npy` array of counts of any integer or float element type as `f32`.
fn read_counts(path: &Path) -> Result<ArrayD<f32>, TofError> {
    use ndarray_npy::ReadNpyError;
    let bytes = std::fs::read(path).map_err(|e| file_error(path, e.to_string()))?;
    macro_rules! attempt {
        ($t:ty) => {
            match <ArrayD<$t> as ndarray_npy::ReadNpyExt>::read_npy(&bytes[..]) {
                Ok(a) => return Ok(a.mapv(|v| v as f32)),
                Err(ReadNpyError::WrongDescriptor(_)) => {}
                Err(e) => {
                    return Err(file_error(path, format!("not a readable .npy array: {e}")));
                }
            }
        };
    }
    attempt!(f32);
    attempt!(f64);
    attempt!(u16);
    attempt!(u32);
    attempt!(u64);
    attempt!(u8);
    attempt!(i16);
    attempt!(i32);
    attempt!(i64);
    Err(file_error(
        path,
        "photon counts must be an integer or float32/float64 .npy array".into(),
    ))
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
        ndarray_npy::write_npy(&path, &counts).unwrap();
        let h = Histograms::read(&path).unwrap();
        assert_eq!(h.counts[(1, 2, 7)], 10.0);
        assert_eq!(h.bins(), 8);

        let zeros = dir.path().join("z.npy");
        ndarray_npy::write_npy(&zeros, &Array3::<u32>::zeros((2, 2, 8))).unwrap();
        let err = Histograms::read(&zeros).unwrap_err();
        assert!(matches!(err, TofError::NoPhotons(_)), "{err}");

        let flat = dir.path().join("flat.npy");
        ndarray_npy::write_npy(&flat, &Array1::<f32>::ones(6)).unwrap();
        let err = Histograms::read(&flat).unwrap_err().to_string();
        assert!(err.contains("H×W×bins"), "{err}");

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
