//! Image sets with known lights, including the DiLiGenT layout (Shi et al., CVPR 2016):
//! `filenames.txt`, `light_directions.txt` (one "x y z" per image), `light_intensities.txt`
//! (one "r g b" per image), `mask.png`, optional `Normal_gt.mat`. Images may be 8- or 16-bit,
//! grey or RGB; each channel is divided by its light intensity and grey is the mean of the
//! channels. DiLiGenT's frame is x right, y up, z towards the camera, as this project's.

use super::{DatasetError, mat::read_mat_array};
use crate::types::LedImages;
use nalgebra::Vector3;
use ndarray::{Array2, Array3};
use std::path::{Path, PathBuf};

/// Images, their light vectors, and optional mask and ground-truth normals.
#[derive(Debug, Clone)]
pub struct ImageSet {
    /// One grey image per light.
    pub images: LedImages,
    /// Light vectors in image order.
    pub lights: Vec<Vector3<f64>>,
    /// Object mask, when the set has one.
    pub mask: Option<Array2<bool>>,
    /// Ground-truth unit normals H×W×3, when the set has them.
    pub normals_gt: Option<Array3<f32>>,
}

/// Reads rows of whitespace- or comma-separated numbers (blank lines and `#` comments skipped).
pub fn read_rows(path: &Path, width: usize) -> Result<Vec<Vec<f64>>, DatasetError> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut rows = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let row = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .map(str::parse::<f64>)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| DatasetError::format(path, format!("line {}: {e}", i + 1)))?;
        if row.len() != width || row.iter().any(|v| !v.is_finite()) {
            return Err(DatasetError::format(
                path,
                format!("line {}: expected {width} finite numbers", i + 1),
            ));
        }
        rows.push(row);
    }
    Ok(rows)
}

/// Reads an image as grey f32 in [0, 1] (full 16-bit precision), dividing channel c by
/// `intensity[c]` first.
pub fn read_grey(path: &Path, intensity: [f64; 3]) -> Result<Array2<f32>, DatasetError> {
    let img = image::open(path)
        .map_err(|e| DatasetError::format(path, format!("cannot decode image: {e}")))?;
    let rgb = img.into_rgb32f();
    let (w, h) = rgb.dimensions();
    let inv = intensity.map(|v| if v > 0.0 { 1.0 / v } else { 0.0 });
    Ok(Array2::from_shape_fn((h as usize, w as usize), |(r, c)| {
        let p = rgb.get_pixel(c as u32, r as u32).0;
        ((f64::from(p[0]) * inv[0] + f64::from(p[1]) * inv[1] + f64::from(p[2]) * inv[2]) / 3.0)
            as f32
    }))
}

/// Loads images with lights from a text file (one "x y z" row per image) and optional
/// per-image intensities (one "r g b" or one value per row) and mask.
pub fn load_image_set(
    images: &[PathBuf],
    lights: &Path,
    intensities: Option<&Path>,
    mask: Option<&Path>,
) -> Result<ImageSet, DatasetError> {
    let light_rows = read_rows(lights, 3)?;
    if light_rows.len() != images.len() {
        return Err(DatasetError::format(
            lights,
            format!(
                "{} light rows for {} images",
                light_rows.len(),
                images.len()
            ),
        ));
    }
    let gains: Vec<[f64; 3]> = match intensities {
        None => vec![[1.0; 3]; images.len()],
        Some(p) => {
            let rows = read_rows(p, 3).or_else(|_| read_rows(p, 1))?;
            if rows.len() != images.len() {
                return Err(DatasetError::format(
                    p,
                    format!("{} intensity rows for {} images", rows.len(), images.len()),
                ));
            }
            rows.iter()
                .map(|r| {
                    if r.len() == 3 {
                        [r[0], r[1], r[2]]
                    } else {
                        [r[0]; 3]
                    }
                })
                .collect()
        }
    };
    let grey = images
        .iter()
        .zip(&gains)
        .map(|(p, g)| read_grey(p, *g))
        .collect::<Result<Vec<_>, _>>()?;
    let mask = mask.map(crate::io::read_mask).transpose()?;
    Ok(ImageSet {
        images: LedImages { images: grey },
        lights: light_rows
            .iter()
            .map(|r| Vector3::new(r[0], r[1], r[2]))
            .collect(),
        mask,
        normals_gt: None,
    })
}

/// Loads a DiLiGenT object folder (see the module docs).
pub fn load_diligent(dir: &Path) -> Result<ImageSet, DatasetError> {
    let names_path = dir.join("filenames.txt");
    let names = std::fs::read_to_string(&names_path).map_err(|source| DatasetError::Io {
        path: names_path.clone(),
        source,
    })?;
    let images: Vec<PathBuf> = names
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(|l| dir.join(l))
        .collect();
    let intensities = dir.join("light_intensities.txt");
    let mask = dir.join("mask.png");
    let mut set = load_image_set(
        &images,
        &dir.join("light_directions.txt"),
        intensities.exists().then_some(intensities.as_path()),
        mask.exists().then_some(mask.as_path()),
    )?;
    let gt = dir.join("Normal_gt.mat");
    if gt.exists() {
        let n = read_mat_array(&gt, "Normal_gt")?;
        let n = n
            .into_dimensionality::<ndarray::Ix3>()
            .map_err(|e| DatasetError::format(&gt, format!("Normal_gt: {e}")))?;
        set.normals_gt = Some(n.mapv(|v| v as f32));
    }
    Ok(set)
}
