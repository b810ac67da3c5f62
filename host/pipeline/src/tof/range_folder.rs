//! The files of a range map on disk (what `meb tof range` writes and `meb reconstruct --tof`
//! reads): one H×W `.npy` per field of [`RangeMap`], so that the layout is known in one place.
//! The counts of rejected pixels live in the folder's summary (`range.json`), not here.

use super::TofError;
use super::range::{RangeMap, Rejections};
use meb_core::io::{read_float, write_npy};
use ndarray::{Array2, Ix2};
use std::path::Path;

/// The range (axial depth, mm; NaN where unreliable).
pub const RANGE_FILE: &str = "range.npy";
/// The range's standard deviation, mm.
pub const SIGMA_FILE: &str = "sigma.npy";
/// The confidence in [0, 1].
pub const CONFIDENCE_FILE: &str = "confidence.npy";
/// The fitted signal photons.
pub const SIGNAL_FILE: &str = "signal.npy";
/// The fitted background photons per bin.
pub const BACKGROUND_FILE: &str = "background.npy";
/// The correlation with the shifted reference.
pub const CORRELATION_FILE: &str = "correlation.npy";
/// The pixels whose photons entered each pixel's range (spatial smoothing).
pub const SAMPLES_FILE: &str = "samples.npy";

/// Each pixel's own range before smoothing, mm.
pub const RAW_RANGE_FILE: &str = "raw_range.npy";
/// Its standard deviation, mm.
pub const RAW_SIGMA_FILE: &str = "raw_sigma.npy";

/// Every file of a range folder, in [`RangeMap`] field order.
pub const FILES: [&str; 9] = [
    RANGE_FILE,
    SIGMA_FILE,
    CONFIDENCE_FILE,
    SIGNAL_FILE,
    BACKGROUND_FILE,
    CORRELATION_FILE,
    SAMPLES_FILE,
    RAW_RANGE_FILE,
    RAW_SIGMA_FILE,
];

/// Writes `map`'s fields into the existing folder `dir`.
pub fn write_range_folder(dir: &Path, map: &RangeMap) -> Result<(), TofError> {
    let fields = [
        &map.range_mm,
        &map.sigma_mm,
        &map.confidence,
        &map.signal_photons,
        &map.background_per_bin,
        &map.correlation,
        &map.samples,
        &map.raw_range_mm,
        &map.raw_sigma_mm,
    ];
    for (file, field) in FILES.into_iter().zip(fields) {
        write_npy(&dir.join(file), field)?;
    }
    Ok(())
}

/// Reads a range folder written by [`write_range_folder`]; refuses a folder with a missing
/// file (naming every missing one) or fields of different sizes. `rejected` is left at zero.
pub fn read_range_folder(dir: &Path) -> Result<RangeMap, TofError> {
    if !dir.is_dir() {
        return Err(TofError::File {
            path: dir.to_path_buf(),
            reason: "not a folder: expected the output folder of `meb tof range`".into(),
        });
    }
    let missing: Vec<&str> = FILES
        .into_iter()
        .filter(|f| !dir.join(f).is_file())
        .collect();
    if !missing.is_empty() {
        return Err(TofError::File {
            path: dir.to_path_buf(),
            reason: format!(
                "not a complete `meb tof range` folder: missing {} (run `meb tof range` again into a new --out)",
                missing.join(", ")
            ),
        });
    }
    let range_mm: Array2<f32> = read_float::<Ix2>(&dir.join(RANGE_FILE), &[None, None])?;
    let (rows, cols) = range_mm.dim();
    let read = |file: &str| read_float::<Ix2>(&dir.join(file), &[Some(rows), Some(cols)]);
    Ok(RangeMap {
        sigma_mm: read(SIGMA_FILE)?,
        confidence: read(CONFIDENCE_FILE)?,
        signal_photons: read(SIGNAL_FILE)?,
        background_per_bin: read(BACKGROUND_FILE)?,
        correlation: read(CORRELATION_FILE)?,
        samples: read(SAMPLES_FILE)?,
        raw_range_mm: read(RAW_RANGE_FILE)?,
        raw_sigma_mm: read(RAW_SIGMA_FILE)?,
        range_mm,
        rejected: Rejections::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> RangeMap {
        let field = |k: f32| Array2::from_shape_fn((3, 4), |(r, c)| k + (r * 4 + c) as f32);
        let mut range_mm = field(600.0);
        range_mm[(1, 2)] = f32::NAN;
        RangeMap {
            range_mm,
            sigma_mm: field(1.0),
            confidence: field(0.5),
            signal_photons: field(100.0),
            background_per_bin: field(0.01),
            correlation: field(0.9),
            samples: field(1.0),
            raw_range_mm: field(601.0),
            raw_sigma_mm: field(5.0),
            rejected: Rejections::default(),
        }
    }

    #[test]
    fn a_written_folder_reads_back_field_by_field() {
        let dir = tempfile::tempdir().unwrap();
        let written = map();
        write_range_folder(dir.path(), &written).unwrap();
        let read = read_range_folder(dir.path()).unwrap();
        let same = |a: &Array2<f32>, b: &Array2<f32>| {
            a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
        };
        assert!(same(&read.range_mm, &written.range_mm));
        assert!(same(&read.sigma_mm, &written.sigma_mm));
        assert!(same(&read.confidence, &written.confidence));
        assert!(same(&read.signal_photons, &written.signal_photons));
        assert!(same(&read.background_per_bin, &written.background_per_bin));
        assert!(same(&read.correlation, &written.correlation));
        assert!(same(&read.samples, &written.samples));
        assert!(same(&read.raw_range_mm, &written.raw_range_mm));
        assert!(same(&read.raw_sigma_mm, &written.raw_sigma_mm));
    }

    #[test]
    fn missing_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        write_range_folder(dir.path(), &map()).unwrap();
        std::fs::remove_file(dir.path().join(SIGMA_FILE)).unwrap();
        std::fs::remove_file(dir.path().join(CORRELATION_FILE)).unwrap();
        let err = read_range_folder(dir.path()).unwrap_err().to_string();
        assert!(err.contains("missing sigma.npy, correlation.npy"), "{err}");
        let err = read_range_folder(&dir.path().join("nothing"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a folder"), "{err}");
    }

    #[test]
    fn fields_of_another_size_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        write_range_folder(dir.path(), &map()).unwrap();
        write_npy(
            &dir.path().join(CONFIDENCE_FILE),
            &Array2::<f32>::zeros((2, 4)),
        )
        .unwrap();
        assert!(read_range_folder(dir.path()).is_err());
    }
}
