//! Mask images: any image whose non-zero pixels mark the inside (8/16-bit, grey or colour),
//! written as 8-bit greyscale PNG with 255 inside.

use super::FilesError;
use image::{ImageBuffer, Luma};
use ndarray::Array2;
use std::path::Path;

/// Reads a mask image: pixels whose grey value is non-zero are inside.
pub fn read_mask(path: &Path) -> Result<Array2<bool>, FilesError> {
    let img = image::open(path)
        .map_err(|source| FilesError::Image {
            path: path.to_path_buf(),
            source,
        })?
        .into_luma16();
    let (w, h) = img.dimensions();
    Ok(Array2::from_shape_fn((h as usize, w as usize), |(r, c)| {
        img.get_pixel(c as u32, r as u32).0[0] > 0
    }))
}

/// Writes `mask` as an 8-bit greyscale PNG, 255 inside and 0 outside.
pub fn write_mask(path: &Path, mask: &Array2<bool>) -> Result<(), FilesError> {
    let (h, w) = mask.dim();
    let pixels: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    let img =
        ImageBuffer::<Luma<u8>, _>::from_raw(w as u32, h as u32, pixels).ok_or_else(|| {
            FilesError::Encode {
                path: path.to_path_buf(),
                source: "mask size does not fit a PNG".into(),
            }
        })?;
    let mut bytes = std::io::Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|source| FilesError::Image {
            path: path.to_path_buf(),
            source,
        })?;
    std::fs::write(path, bytes.into_inner()).map_err(|e| FilesError::write(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_round_trip_and_bad_files_are_named() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("mask.png");
        let mask = Array2::from_shape_fn((5, 7), |(r, c)| (r + c) % 3 == 0);
        write_mask(&path, &mask).unwrap();
        assert_eq!(read_mask(&path).unwrap(), mask);
        let bad = tmp.path().join("bad.png");
        std::fs::write(&bad, b"not a png").unwrap();
        let err = read_mask(&bad).unwrap_err();
        assert!(err.to_string().contains("bad.png"), "{err}");
    }
}
