//! PNG previews: normal map ((n + 1)/2 as RGB), albedo (grey), depth and error maps through
//! colour maps, masks. Pixels without data are drawn dark grey.

use super::{ExportError, write_atomic};
use image::{ImageFormat, Rgb, RgbImage};
use ndarray::{Array2, Array3};
use std::path::Path;

/// Colour of pixels without data.
const NO_DATA: Rgb<u8> = Rgb([40, 40, 40]);

/// Encodes an RGB image as PNG bytes.
pub fn png_bytes(image: &RgbImage) -> Result<Vec<u8>, ExportError> {
    let mut out = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, ImageFormat::Png)
        .map_err(|e| ExportError::Write {
            path: "(png)".into(),
            reason: e.to_string(),
        })?;
    Ok(out.into_inner())
}

/// Writes an RGB image as a PNG file.
pub fn write_png(path: &Path, image: &RgbImage) -> Result<(), ExportError> {
    write_atomic(path, &png_bytes(image)?)
}

/// Normal map: (n + 1)/2 → RGB.
pub fn normal_map(normals: &Array3<f32>) -> RgbImage {
    let (rows, cols, _) = normals.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let n = [0, 1, 2].map(|j| normals[(r as usize, c as usize, j)]);
        if n.iter().any(|v| !v.is_finite()) {
            return NO_DATA;
        }
        Rgb(n.map(|v| ((v + 1.0) * 0.5 * 255.0).clamp(0.0, 255.0) as u8))
    })
}

/// Grey image of `values` scaled so the 99th percentile is white.
pub fn grey_map(values: &Array2<f32>) -> RgbImage {
    let top =
        crate::photometric::mask::quantile(values.iter().copied(), 0.99).max(f32::MIN_POSITIVE);
    let (rows, cols) = values.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let v = values[(r as usize, c as usize)];
        if !v.is_finite() {
            return NO_DATA;
        }
        let g = (v / top * 255.0).clamp(0.0, 255.0) as u8;
        Rgb([g, g, g])
    })
}

/// A perceptually ordered colour ramp (dark blue → teal → yellow) at t ∈ [0, 1].
pub fn ramp(t: f32) -> Rgb<u8> {
    const STOPS: [[f32; 3]; 5] = [
        [68.0, 1.0, 84.0],
        [59.0, 82.0, 139.0],
        [33.0, 145.0, 140.0],
        [94.0, 201.0, 98.0],
        [253.0, 231.0, 37.0],
    ];
    let t = t.clamp(0.0, 1.0) * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f32;
    let mix = |j: usize| (STOPS[i][j] * (1.0 - f) + STOPS[i + 1][j] * f) as u8;
    Rgb([mix(0), mix(1), mix(2)])
}

/// Depth through [`ramp`] between its min and max.
pub fn depth_map(depth: &Array2<f32>) -> RgbImage {
    let (lo, hi) = depth
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let (rows, cols) = depth.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let v = depth[(r as usize, c as usize)];
        if v.is_finite() {
            ramp((v - lo) / span)
        } else {
            NO_DATA
        }
    })
}

/// Signed error map: blue negative, white zero, red positive, saturating at ±`limit`.
pub fn error_map(error: &Array2<f32>, limit: f32) -> RgbImage {
    let (rows, cols) = error.dim();
    let limit = limit.max(f32::MIN_POSITIVE);
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let v = error[(r as usize, c as usize)];
        if !v.is_finite() {
            return NO_DATA;
        }
        let t = (v / limit).clamp(-1.0, 1.0);
        let fade = (255.0 * (1.0 - t.abs())) as u8;
        if t >= 0.0 {
            Rgb([255, fade, fade])
        } else {
            Rgb([fade, fade, 255])
        }
    })
}

/// A mask as black and white.
pub fn mask_image(mask: &Array2<bool>) -> RgbImage {
    let (rows, cols) = mask.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        if mask[(r as usize, c as usize)] {
            Rgb([255; 3])
        } else {
            Rgb([0; 3])
        }
    })
}
