//! Pictures of a 3-D frame for the output videos: the depth through the colour ramp, and the
//! reconstructed surface shaded as seen from the camera.
//!
//! Both are drawn from the depth map itself (not the photometric normals), so they show what
//! the integration produced. The shaded view lights the surface normals of the depth
//! (central differences, [`normals_from_depth`]) with a Lambertian light over the viewer's
//! left shoulder. Frames are drawn at an integer fraction of the camera's resolution (every
//! f-th pixel), with even sizes as H.264's 4:2:0 sampling needs.

use crate::regions::bounding_box;
use image::{Rgb, RgbImage};
use meb_core::io::colour::ramp;
use meb_core::io::preview::NO_DATA;
use meb_core::metrics::normals_from_depth;
use ndarray::{Array2, s};
use std::ops::Range;

/// Size of the output pictures for a camera of `width` × `height`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PictureSize {
    /// Every `factor`-th camera pixel is drawn.
    pub factor: usize,
    /// Picture width (even).
    pub width: usize,
    /// Picture height (even).
    pub height: usize,
}

impl PictureSize {
    /// The largest size at most `max_width` wide (0 = full resolution), at least 2×2.
    pub fn fit(width: usize, height: usize, max_width: usize) -> Self {
        let factor = if max_width == 0 {
            1
        } else {
            width.div_ceil(max_width).max(1)
        };
        let even = |n: usize| (n.div_ceil(factor) & !1).max(2);
        Self {
            factor,
            width: even(width),
            height: even(height),
        }
    }

    /// The camera pixels drawn, `height` × `width`, NaN beyond the camera.
    fn sample(&self, depth: &Array2<f32>) -> Array2<f32> {
        let f = self.factor;
        let sub = depth.slice(s![..;f, ..;f]);
        Array2::from_shape_fn((self.height, self.width), |p| {
            sub.get(p).copied().unwrap_or(f32::NAN)
        })
    }
}

/// The sampled depth of a picture inside the box of its finite values: the object fills a
/// tenth of a video frame, and only the box is drawn, on a no-data picture.
struct SampledObject {
    depth: Array2<f32>,
    rows: Range<usize>,
    cols: Range<usize>,
}

impl SampledObject {
    /// The object in `depth` as drawn at `size`; `None` when no pixel has data.
    fn of(depth: &Array2<f32>, size: PictureSize) -> Option<Self> {
        let sampled = size.sample(depth);
        let (rows, cols) = bounding_box(&sampled.mapv(f32::is_finite))?;
        let depth = sampled.slice(s![rows.clone(), cols.clone()]).to_owned();
        Some(Self { depth, rows, cols })
    }

    /// Sets the picture's pixel at the object's `(r, c)`.
    fn put(&self, picture: &mut RgbImage, (r, c): (usize, usize), colour: Rgb<u8>) {
        picture.put_pixel(
            (self.cols.start + c) as u32,
            (self.rows.start + r) as u32,
            colour,
        );
    }
}

/// The two pictures of one 3-D frame, drawn from one sampling of its depth.
#[derive(Debug, Clone, PartialEq)]
pub struct Pictures {
    /// Depth through the colour ramp (\[`depth_picture`\]).
    pub depth: RgbImage,
    /// The surface shaded from the camera's viewpoint (\[`shaded_picture`\]).
    pub shaded: RgbImage,
}

/// Both pictures of `depth` (grid pitch `pitch_mm`), coloured between `lo` and `hi` mm.
pub fn pictures(
    depth: &Array2<f32>,
    size: PictureSize,
    pitch_mm: f64,
    lo: f32,
    hi: f32,
) -> Pictures {
    let object = SampledObject::of(depth, size);
    Pictures {
        depth: depth_picture(object.as_ref(), size, lo, hi),
        shaded: shaded_picture(object.as_ref(), pitch_mm, size),
    }
}

/// Depth between `lo` and `hi` mm through the colour ramp; no data is dark grey.
fn depth_picture(object: Option<&SampledObject>, size: PictureSize, lo: f32, hi: f32) -> RgbImage {
    let mut picture = blank_picture(size);
    let Some(object) = object else {
        return picture;
    };
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    for (p, &z) in object.depth.indexed_iter() {
        if z.is_finite() {
            object.put(&mut picture, p, ramp((z - lo) / span));
        }
    }
    picture
}

/// The surface (grid pitch `pitch_mm`) shaded from the camera's viewpoint. The normals are
/// those of the object's box alone: a neighbour beyond it is no data either way, so they equal
/// the whole picture's.
fn shaded_picture(object: Option<&SampledObject>, pitch_mm: f64, size: PictureSize) -> RgbImage {
    let mut picture = blank_picture(size);
    let Some(object) = object else {
        return picture;
    };
    let normals = normals_from_depth(&object.depth, pitch_mm * size.factor as f64);
    let light = [-0.4f32, 0.5, 1.0];
    let norm = light.iter().map(|v| v * v).sum::<f32>().sqrt();
    let light = light.map(|v| v / norm);
    for (r, c) in ndarray::indices(object.depth.dim()) {
        let n = [0, 1, 2].map(|j| normals[(r, c, j)]);
        if n.iter().any(|v| !v.is_finite()) {
            continue;
        }
        let lambert: f32 = n.iter().zip(&light).map(|(a, b)| a * b).sum();
        let shade = 0.15 + 0.85 * lambert.max(0.0);
        let colour = Rgb([215.0, 205.0, 190.0].map(|v: f32| (v * shade).round() as u8));
        object.put(&mut picture, (r, c), colour);
    }
    picture
}

/// A picture with no data (a window without a reconstruction).
pub fn blank_picture(size: PictureSize) -> RgbImage {
    RgbImage::from_pixel(size.width as u32, size.height as u32, NO_DATA)
}

/// A depth range that keeps a video's colours steady: the 0.5 % and 99.5 % quantiles of the
/// first 3-D frame, widened by half their span on each side (the object turns and moves).
pub fn depth_range(depth: &Array2<f32>) -> Option<(f32, f32)> {
    let lo = meb_core::stats::quantile(depth.iter().copied(), 0.005)?;
    let hi = meb_core::stats::quantile(depth.iter().copied(), 0.995)?;
    let span = (hi - lo).max(1.0);
    Some((lo - 0.5 * span, hi + 0.5 * span))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dome() -> Array2<f32> {
        Array2::from_shape_fn((61, 81), |(r, c)| {
            let d2 = (r as f32 - 30.0).powi(2) + (c as f32 - 40.0).powi(2);
            if d2 < 625.0 {
                (625.0 - d2).sqrt()
            } else {
                f32::NAN
            }
        })
    }

    /// The shaded picture drawn whole, as before pictures were drawn in the object's box.
    fn shaded_whole(depth: &Array2<f32>, pitch_mm: f64, size: PictureSize) -> RgbImage {
        let normals = normals_from_depth(&size.sample(depth), pitch_mm * size.factor as f64);
        let light = [-0.4f32, 0.5, 1.0];
        let norm = light.iter().map(|v| v * v).sum::<f32>().sqrt();
        let light = light.map(|v| v / norm);
        RgbImage::from_fn(size.width as u32, size.height as u32, |c, r| {
            let n = [0, 1, 2].map(|j| normals[(r as usize, c as usize, j)]);
            if n.iter().any(|v| !v.is_finite()) {
                return NO_DATA;
            }
            let lambert: f32 = n.iter().zip(&light).map(|(a, b)| a * b).sum();
            let shade = 0.15 + 0.85 * lambert.max(0.0);
            Rgb([215.0, 205.0, 190.0].map(|v: f32| (v * shade).round() as u8))
        })
    }

    /// Drawn in the object's box, the pictures equal the whole picture's: for the dome, an
    /// object touching the frame's corner with a lone pixel apart, at full size and every
    /// third pixel, and for no object at all.
    #[test]
    fn pictures_drawn_in_the_object_box_equal_whole_ones() {
        let mut cornered = dome().slice(s![20.., 25..]).to_owned();
        cornered[(0, 55)] = 3.0;
        let empty = Array2::from_elem((61, 81), f32::NAN);
        for depth in [dome(), cornered, empty] {
            let (height, width) = depth.dim();
            for max_width in [0, 30] {
                let size = PictureSize::fit(width, height, max_width);
                let drawn = pictures(&depth, size, 0.7, 0.0, 25.0);
                assert_eq!(drawn.shaded, shaded_whole(&depth, 0.7, size));
                let sampled = size.sample(&depth);
                let whole = RgbImage::from_fn(size.width as u32, size.height as u32, |c, r| {
                    let z = sampled[(r as usize, c as usize)];
                    if z.is_finite() {
                        ramp(z / 25.0)
                    } else {
                        NO_DATA
                    }
                });
                assert_eq!(drawn.depth, whole);
            }
        }
    }

    #[test]
    fn sizes_are_even_fractions_of_the_camera() {
        assert_eq!(
            PictureSize::fit(1280, 720, 640),
            PictureSize {
                factor: 2,
                width: 640,
                height: 360
            }
        );
        assert_eq!(PictureSize::fit(81, 61, 0).width, 80);
        assert_eq!(
            PictureSize::fit(81, 61, 40),
            PictureSize {
                factor: 3,
                width: 26,
                height: 20
            }
        );
    }

    #[test]
    fn the_dome_is_lit_from_the_upper_left_and_coloured_by_height() {
        let depth = dome();
        let size = PictureSize::fit(81, 61, 0);
        let (lo, hi) = depth_range(&depth).unwrap();
        assert!(lo < 1.0 && hi > 25.0);
        let Pictures {
            depth: coloured,
            shaded,
        } = pictures(&depth, size, 1.0, 0.0, 25.0);
        // Upper-left flank faces the light, lower-right flank faces away.
        let lit = shaded.get_pixel(30, 20).0[0];
        let dark = shaded.get_pixel(50, 40).0[0];
        assert!(lit > dark + 40, "{lit} vs {dark}");
        assert_eq!(*shaded.get_pixel(0, 0), NO_DATA);
        assert_eq!(*coloured.get_pixel(40, 30), ramp(1.0));
        assert_eq!(*coloured.get_pixel(0, 0), NO_DATA);
        assert_eq!(blank_picture(size).dimensions(), (80, 60));
    }
}
