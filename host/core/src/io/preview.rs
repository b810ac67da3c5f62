//! PNG previews: normal map ((n + 1)/2 as RGB), grey images, values through the colour
//! [`ramp`], signed error maps and masks. Pixels without data (NaN) are drawn dark grey.

use super::FilesError;
use super::colour::ramp;
use image::{ImageFormat, Rgb, RgbImage};
use ndarray::{Array2, Array3};
use std::path::Path;

/// Colour of pixels without data.
pub const NO_DATA: Rgb<u8> = Rgb([40, 40, 40]);

/// Encodes an RGB image as PNG bytes.
pub fn png_bytes(image: &RgbImage) -> Result<Vec<u8>, FilesError> {
    let mut out = std::io::Cursor::new(Vec::new());
    image
        .write_to(&mut out, ImageFormat::Png)
        .map_err(|source| FilesError::Image {
            path: "(PNG in memory)".into(),
            source,
        })?;
    Ok(out.into_inner())
}

/// Writes an RGB image as a PNG file.
pub fn write_png(path: &Path, image: &RgbImage) -> Result<(), FilesError> {
    let bytes = png_bytes(image)?;
    std::fs::write(path, bytes).map_err(|e| FilesError::write(path, e))
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
    let top = crate::stats::quantile(values.iter().copied(), 0.99)
        .unwrap_or(1.0)
        .max(f32::MIN_POSITIVE);
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

/// `values` through [`ramp`], `lo` dark blue and `hi` yellow.
pub fn ramp_map(values: &Array2<f32>, lo: f32, hi: f32) -> RgbImage {
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    let (rows, cols) = values.dim();
    RgbImage::from_fn(cols as u32, rows as u32, |c, r| {
        let v = values[(r as usize, c as usize)];
        if v.is_finite() {
            ramp((v - lo) / span)
        } else {
            NO_DATA
        }
    })
}

/// Depth through [`ramp`] between its min and max.
pub fn depth_map(depth: &Array2<f32>) -> RgbImage {
    let (lo, hi) = depth
        .iter()
        .filter(|v| v.is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        });
    ramp_map(depth, lo, hi)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn previews_mark_missing_data_and_use_the_ramp() {
        let mut depth = Array2::from_shape_fn((2, 3), |(r, c)| (r * 3 + c) as f32);
        depth[(0, 1)] = f32::NAN;
        let img = depth_map(&depth);
        assert_eq!(*img.get_pixel(1, 0), NO_DATA);
        assert_eq!(*img.get_pixel(0, 0), ramp(0.0));
        assert_eq!(*img.get_pixel(2, 1), ramp(1.0));
        let png = png_bytes(&img).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
    }
}
