//! The decode output folder: `led1.npy … ledN.npy` (float32 H×W, A_i as a fraction of full
//! scale), `ledI.png` colour-mapped previews, `noise.npy`, `saturated.npy` / `underexposed.npy`
//! (bool masks) and `decode.json` (the [`super::DecodeReport`]).
//!
//! [`write_decode_dir`] fills a folder that the caller replaces atomically (an
//! [`OutputFolder`](meb_core::io::OutputFolder)); [`read_decode_dir`] reads it back,
//! checking that every file is present and of the size `decode.json` records. Files go through
//! the common file layer ([`meb_core::io`]).

use super::Decoded;
use meb_core::io::{FilesError, preview, read_exact, read_float, write_npy};
use ndarray::{Array2, Ix2};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors reading or writing a decode folder.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DecodeDirError {
    /// A file could not be read or written.
    #[error(transparent)]
    Files(#[from] FilesError),
    /// A file the folder must hold is absent.
    #[error("{path} is missing (not a complete `meb decode` output folder)")]
    Missing {
        /// The file.
        path: PathBuf,
    },
    /// `decode.json` cannot be parsed.
    #[error("{path} is not a decode report")]
    Report {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
}

/// Turns "file does not exist" into [`DecodeDirError::Missing`].
fn in_folder(e: FilesError) -> DecodeDirError {
    match e {
        FilesError::Missing { path } => DecodeDirError::Missing { path },
        e => DecodeDirError::Files(e),
    }
}

/// Reads a folder written by [`write_decode_dir`]; `saturated.npy` and `underexposed.npy`
/// are optional (all false when absent).
pub fn read_decode_dir(dir: &Path) -> Result<Decoded, DecodeDirError> {
    let json_path = dir.join("decode.json");
    let text = std::fs::read_to_string(&json_path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DecodeDirError::Missing {
            path: json_path.clone(),
        },
        _ => FilesError::read(&json_path, e).into(),
    })?;
    let report: super::DecodeReport =
        serde_json::from_str(&text).map_err(|source| DecodeDirError::Report {
            path: json_path.clone(),
            source,
        })?;
    let shape = [Some(report.height), Some(report.width)];
    let images = (1..=report.leds)
        .map(|i| read_float::<Ix2>(&dir.join(format!("led{i}.npy")), &shape).map_err(in_folder))
        .collect::<Result<Vec<_>, _>>()?;
    let noise = read_float::<Ix2>(&dir.join("noise.npy"), &shape).map_err(in_folder)?;
    let optional_mask = |name: &str| match read_exact::<bool, Ix2>(&dir.join(name), &shape) {
        Err(FilesError::Missing { .. }) => {
            Ok(Array2::from_elem((report.height, report.width), false))
        }
        other => other.map_err(DecodeDirError::Files),
    };
    let saturated = optional_mask("saturated.npy")?;
    let underexposed = optional_mask("underexposed.npy")?;
    Ok(Decoded {
        leds: meb_core::types::LedImages { images },
        noise,
        saturated,
        underexposed,
        report,
    })
}

/// Writes `decoded` into the existing folder `dir`.
pub fn write_decode_dir(dir: &Path, decoded: &Decoded) -> Result<(), DecodeDirError> {
    let top = preview_white_point(&decoded.leds.images);
    for (i, image) in decoded.leds.images.iter().enumerate() {
        write_npy(&dir.join(format!("led{}.npy", i + 1)), image)?;
        preview::write_png(
            &dir.join(format!("led{}.png", i + 1)),
            &preview::ramp_map(image, 0.0, top),
        )?;
    }
    write_npy(&dir.join("noise.npy"), &decoded.noise)?;
    write_npy(&dir.join("saturated.npy"), &decoded.saturated)?;
    write_npy(&dir.join("underexposed.npy"), &decoded.underexposed)?;
    let json_path = dir.join("decode.json");
    let json = serde_json::to_vec_pretty(&decoded.report).map_err(|e| FilesError::Encode {
        path: json_path.clone(),
        source: Box::new(e),
    })?;
    std::fs::write(&json_path, json).map_err(|e| FilesError::write(&json_path, e))?;
    Ok(())
}

/// The 99.5th percentile of all LED images: the white point of the previews.
fn preview_white_point(images: &[Array2<f32>]) -> f32 {
    meb_core::stats::quantile(images.iter().flat_map(|im| im.iter().copied()), 0.995)
        .filter(|&top| top > 0.0)
        .unwrap_or(1.0)
}
