//! The decode output directory: `led1.npy … ledN.npy` (float32 H×W, A_i as a fraction of full
//! scale), `ledI.png` colour-mapped previews, `noise.npy`, `saturated.npy` / `underexposed.npy`
//! (bool masks) and `decode.json` (the [`super::DecodeReport`]).
//!
//! Every file is written under a temporary name and renamed into place, `decode.json` last, so
//! a directory with a `decode.json` is always complete. [`read_decode_dir`] reads it back and
//! checks that every file is present and of the size `decode.json` records.

use super::Decoded;
use ndarray::Array2;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors writing a decode directory.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum OutputError {
    /// Creating or renaming a file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Encoding a file failed.
    #[error("cannot encode {path}: {reason}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// Errors reading a decode directory.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReadError {
    /// A file the directory must hold is absent.
    #[error("{path} is missing (not a complete `meb decode` output folder)")]
    Missing {
        /// The file.
        path: PathBuf,
    },
    /// A file could not be read or parsed.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// An array's size differs from the one in `decode.json`.
    #[error("{path} is {found:?} (rows, cols) but decode.json says {expected:?}")]
    SizeMismatch {
        /// The file.
        path: PathBuf,
        /// (height, width) from `decode.json`.
        expected: (usize, usize),
        /// (rows, cols) of the array.
        found: (usize, usize),
    },
}

/// Reads a directory written by [`write_decode_dir`]; `saturated.npy` and `underexposed.npy`
/// are optional (all false when absent).
pub fn read_decode_dir(dir: &Path) -> Result<Decoded, ReadError> {
    let json_path = dir.join("decode.json");
    let text = std::fs::read_to_string(&json_path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => ReadError::Missing {
            path: json_path.clone(),
        },
        _ => ReadError::Read {
            path: json_path.clone(),
            reason: e.to_string(),
        },
    })?;
    let report: super::DecodeReport = serde_json::from_str(&text).map_err(|e| ReadError::Read {
        path: json_path.clone(),
        reason: e.to_string(),
    })?;
    let shape = (report.height, report.width);
    let images = (1..=report.leds)
        .map(|i| read_npy::<f32>(&dir.join(format!("led{i}.npy")), shape))
        .collect::<Result<Vec<_>, _>>()?;
    let noise = read_npy::<f32>(&dir.join("noise.npy"), shape)?;
    let optional_mask = |name: &str| {
        let path = dir.join(name);
        if path.exists() {
            read_npy::<bool>(&path, shape)
        } else {
            Ok(Array2::from_elem(shape, false))
        }
    };
    let saturated = optional_mask("saturated.npy")?;
    let underexposed = optional_mask("underexposed.npy")?;
    Ok(Decoded {
        leds: crate::types::LedImages { images },
        noise,
        saturated,
        underexposed,
        report,
    })
}

/// Reads one 2-D array and checks its shape.
fn read_npy<T: ndarray_npy::ReadableElement>(
    path: &Path,
    shape: (usize, usize),
) -> Result<Array2<T>, ReadError> {
    if !path.exists() {
        return Err(ReadError::Missing {
            path: path.to_path_buf(),
        });
    }
    let array: Array2<T> = ndarray_npy::read_npy(path).map_err(|e| ReadError::Read {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    if array.dim() != shape {
        return Err(ReadError::SizeMismatch {
            path: path.to_path_buf(),
            expected: shape,
            found: array.dim(),
        });
    }
    Ok(array)
}

/// Writes `decoded` into `dir` (created if missing).
pub fn write_decode_dir(dir: &Path, decoded: &Decoded) -> Result<(), OutputError> {
    std::fs::create_dir_all(dir).map_err(|source| OutputError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let top = preview_scale(&decoded.leds.images);
    for (i, image) in decoded.leds.images.iter().enumerate() {
        write_npy(&dir.join(format!("led{}.npy", i + 1)), image)?;
        write_preview(&dir.join(format!("led{}.png", i + 1)), image, top)?;
    }
    write_npy(&dir.join("noise.npy"), &decoded.noise)?;
    write_npy(&dir.join("saturated.npy"), &decoded.saturated)?;
    write_npy(&dir.join("underexposed.npy"), &decoded.underexposed)?;
    let json_path = dir.join("decode.json");
    let json = serde_json::to_vec_pretty(&decoded.report).map_err(|e| OutputError::Encode {
        path: json_path.clone(),
        reason: e.to_string(),
    })?;
    atomic_write(&json_path, |tmp| {
        std::fs::write(tmp, &json).map_err(|e| e.to_string())
    })
}

/// Writes through a temporary file and renames it to `path`.
fn atomic_write(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), OutputError> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    write(&tmp).map_err(|reason| OutputError::Encode {
        path: path.to_path_buf(),
        reason,
    })?;
    std::fs::rename(&tmp, path).map_err(|source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes one array as `.npy`.
fn write_npy<T: ndarray_npy::WritableElement>(
    path: &Path,
    array: &Array2<T>,
) -> Result<(), OutputError> {
    atomic_write(path, |tmp| {
        ndarray_npy::write_npy(tmp, array).map_err(|e| e.to_string())
    })
}

/// The 99.5th percentile of all LED images: the white point of the previews.
fn preview_scale(images: &[Array2<f32>]) -> f32 {
    let mut values: Vec<f32> = images
        .iter()
        .flat_map(|im| im.iter().copied())
        .filter(|v| v.is_finite())
        .collect();
    if values.is_empty() {
        return 1.0;
    }
    values.sort_by(f32::total_cmp);
    let top = values[(values.len() - 1) * 995 / 1000];
    if top > 0.0 { top } else { 1.0 }
}

/// Perceptually ordered colour ramp (dark blue → teal → yellow), anchors of the viridis map.
const RAMP: [[f32; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];

/// Colour of a value in [0, 1].
fn colour(value: f32) -> [u8; 3] {
    let v = if value.is_finite() {
        value.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = v * (RAMP.len() - 1) as f32;
    let k = (x.floor() as usize).min(RAMP.len() - 2);
    let t = x - k as f32;
    let mut rgb = [0u8; 3];
    for (c, out) in rgb.iter_mut().enumerate() {
        *out = (RAMP[k][c] * (1.0 - t) + RAMP[k + 1][c] * t).round() as u8;
    }
    rgb
}

/// Writes a colour-mapped PNG preview of one LED image.
fn write_preview(path: &Path, image: &Array2<f32>, top: f32) -> Result<(), OutputError> {
    let (height, width) = image.dim();
    let mut rgb = image::RgbImage::new(width as u32, height as u32);
    for ((row, col), &v) in image.indexed_iter() {
        rgb.put_pixel(col as u32, row as u32, image::Rgb(colour(v / top)));
    }
    atomic_write(path, |tmp| {
        rgb.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(|e| e.to_string())
    })
}
