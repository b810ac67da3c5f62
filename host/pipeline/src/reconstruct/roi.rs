//! The region of interest of a warm-started window.
//!
//! From one window of `meb video` to the next the object moves little, so a warm window is
//! reconstructed inside the previous depth's bounding box grown by [`ROI_MARGIN_PX`], on LED
//! images, noise, mask and a camera cut to that region ([`meb_core::rig::Camera::cropped`]: every
//! pixel keeps its ray), and the result is pasted back into full-frame arrays that hold, outside
//! the region, exactly what a full-frame reconstruction leaves outside its object (NaN normals,
//! albedo and depth, no LEDs, no masks, no pieces). Photometric stereo, integration and the
//! depth-offset search then visit the object's neighbourhood instead of the whole frame. An
//! object that reaches an edge of the region that is not an edge of the frame may go on beyond
//! it: that window is reconstructed on the full frame instead ([`Roi::reached_edge`]).

use crate::integrate::{Confidence, Integration};
use crate::photometric::PhotometricResult;
use meb_core::rig::{Projection, Rig};
use meb_core::types::LedImages;
use ndarray::{Array2, Array3, ArrayView2, s};
use rayon::prelude::*;
use std::mem::MaybeUninit;
use std::ops::Range;

/// Pixels added on every side of the warm start's bounding box: what the object's silhouette
/// may move between windows (the turning ellipsoid's rim moves a few pixels per window).
pub const ROI_MARGIN_PX: usize = 32;

/// A region of interest cuts less than this share of the frame's pixels: not worth it.
const WORTHWHILE_SHARE: f64 = 0.75;

/// Row `r`'s first and last column whose pixel is inside, from its (column, inside) pairs.
fn row_span(
    r: usize,
    row: &mut impl DoubleEndedIterator<Item = (usize, bool)>,
) -> Option<(usize, usize, usize)> {
    let first = row.find(|&(_, inside)| inside)?.0;
    let last = row.rfind(|&(_, inside)| inside).map_or(first, |(c, _)| c);
    Some((r, first, last))
}

/// A rectangle of the frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Roi {
    pub(super) rows: Range<usize>,
    pub(super) cols: Range<usize>,
    /// The frame's (rows, columns).
    frame: (usize, usize),
}

impl Roi {
    /// The bounding box of the finite values of `depth` and the pixels of `mask` grown by
    /// `margin` pixels on every side and clipped to the frame; `None` without such a pixel or
    /// when the region would keep more than [`WORTHWHILE_SHARE`] of the frame.
    pub fn around(depth: &Array2<f32>, mask: Option<&Array2<bool>>, margin: usize) -> Option<Self> {
        let frame = depth.dim();
        if mask.is_some_and(|m| m.dim() != frame) {
            return None;
        }
        // Each row's first and last pixel inside, rows in parallel (over row-major copies of
        // the arrays only should they be stored otherwise).
        let width = frame.1.max(1);
        let depth = depth.as_standard_layout();
        let mask = mask.map(|m| m.as_standard_layout());
        let mask = match &mask {
            Some(m) => Some(m.as_slice()?),
            None => None,
        };
        let spans: Vec<(usize, usize, usize)> = depth
            .as_slice()?
            .par_chunks(width)
            .enumerate()
            .filter_map(|(r, row)| {
                let masked = mask.map(|m| &m[r * width..][..row.len()]);
                let mut inside = row
                    .iter()
                    .enumerate()
                    .map(|(c, z)| (c, z.is_finite() || masked.is_some_and(|m| m[c])));
                row_span(r, &mut inside)
            })
            .collect();
        let (first, last) = (spans.first()?, spans.last()?);
        let (top, bottom) = (first.0, last.0);
        let left = spans.iter().map(|s| s.1).min()?;
        let right = spans.iter().map(|s| s.2).max()?;
        let roi = Self {
            rows: top.saturating_sub(margin)..(bottom + margin + 1).min(frame.0),
            cols: left.saturating_sub(margin)..(right + margin + 1).min(frame.1),
            frame,
        };
        let share = (roi.rows.len() * roi.cols.len()) as f64 / (frame.0 * frame.1) as f64;
        (share <= WORTHWHILE_SHARE).then_some(roi)
    }

    /// The rows and columns of a frame of `frame` (rows, columns) that `rect` covers; `None`
    /// when it is empty or does not lie inside the frame.
    pub fn of_rect(rect: crate::demod::Roi, frame: (usize, usize)) -> Option<Self> {
        let rows = rect.y..rect.y.checked_add(rect.height)?;
        let cols = rect.x..rect.x.checked_add(rect.width)?;
        let inside = !rows.is_empty() && !cols.is_empty() && rows.end <= frame.0;
        (inside && cols.end <= frame.1).then_some(Self { rows, cols, frame })
    }

    /// Whether arrays of these sizes are of the region's frame (and can be cut to it).
    pub fn fits(&self, mut sizes: impl Iterator<Item = (usize, usize)>) -> bool {
        sizes.all(|size| size == self.frame)
    }

    /// The region of a full-frame array, in place.
    pub fn view<'a, T>(&self, full: &'a Array2<T>) -> ArrayView2<'a, T> {
        full.slice(s![self.rows.clone(), self.cols.clone()])
    }

    /// The region of a full-frame array.
    pub fn cut<T: Clone>(&self, full: &Array2<T>) -> Array2<T> {
        self.view(full).to_owned()
    }

    /// The LED images cut to the region.
    pub fn cut_images(&self, images: &LedImages) -> LedImages {
        LedImages {
            images: images.images.iter().map(|image| self.cut(image)).collect(),
        }
    }

    /// The rig whose camera sees the region only.
    pub fn cut_rig(&self, rig: &Rig) -> Rig {
        Rig {
            camera: rig.camera.cropped(self.rows.clone(), self.cols.clone()),
            ..rig.clone()
        }
    }

    /// Whether `object` (of the region's size) reaches an edge of the region that is not an
    /// edge of the frame: the object may go on beyond it.
    pub fn reached_edge(&self, object: &Array2<bool>) -> bool {
        let (rows, cols) = object.dim();
        let any = |view: ndarray::ArrayView1<bool>| view.iter().any(|&b| b);
        (self.rows.start > 0 && any(object.row(0)))
            || (self.rows.end < self.frame.0 && rows > 0 && any(object.row(rows - 1)))
            || (self.cols.start > 0 && any(object.column(0)))
            || (self.cols.end < self.frame.1 && cols > 0 && any(object.column(cols - 1)))
    }

    /// A full-frame array holding `region` (of the region's size) inside the region and
    /// `outside` elsewhere.
    pub(super) fn paste2<T: Copy + Send + Sync>(
        &self,
        region: &Array2<T>,
        outside: T,
    ) -> Array2<T> {
        region
            .as_slice()
            .and_then(|values| self.paste_rows(values, 1, outside))
            .and_then(|full| Array2::from_shape_vec(self.frame, full).ok())
            .unwrap_or_else(|| {
                let mut full = Array2::from_elem(self.frame, outside);
                full.slice_mut(s![self.rows.clone(), self.cols.clone()])
                    .assign(region);
                full
            })
    }

    /// [`Self::paste2`] for per-pixel vectors (rows, columns, channels).
    pub(super) fn paste3(&self, region: &Array3<f32>, outside: f32) -> Array3<f32> {
        let channels = region.dim().2;
        let shape = (self.frame.0, self.frame.1, channels);
        region
            .as_slice()
            .and_then(|values| self.paste_rows(values, channels, outside))
            .and_then(|full| Array3::from_shape_vec(shape, full).ok())
            .unwrap_or_else(|| {
                let mut full = Array3::from_elem(shape, outside);
                full.slice_mut(s![self.rows.clone(), self.cols.clone(), ..])
                    .assign(region);
                full
            })
    }

    /// The frame's values in row-major order (`channels` per pixel): `region`'s (row-major,
    /// the region's size) inside the region, `outside` elsewhere; `None` when `region` is not
    /// of the region's size. The frame's rows are written in parallel, each element once,
    /// into memory allocated without being filled first. At 1280×720 the pasted arrays are
    /// ≈ 40 MB per window; filled first and then overwritten, on one thread per half of them,
    /// the paste of the benchmark's warm window took 2.1–2.8 ms in steady state (minimum and
    /// median of 60), and 1.8–2.2 ms this way.
    fn paste_rows<T: Copy + Send + Sync>(
        &self,
        region: &[T],
        channels: usize,
        outside: T,
    ) -> Option<Vec<T>> {
        let row_len = self.frame.1 * channels;
        let (start, end) = (self.cols.start * channels, self.cols.end * channels);
        let inside_len = end - start;
        let len = self.frame.0 * row_len;
        if region.len() != self.rows.len() * inside_len || end > row_len {
            return None;
        }
        let mut full: Vec<T> = Vec::with_capacity(len);
        let fill = |slots: &mut [MaybeUninit<T>]| {
            slots.iter_mut().for_each(|slot| {
                slot.write(outside);
            })
        };
        full.spare_capacity_mut()[..len]
            .par_chunks_mut(row_len.max(1))
            .enumerate()
            .for_each(|(r, row)| {
                let Some(inside) = r
                    .checked_sub(self.rows.start)
                    .filter(|_| self.rows.contains(&r))
                else {
                    fill(row);
                    return;
                };
                let (before, rest) = row.split_at_mut(start);
                let (middle, after) = rest.split_at_mut(inside_len);
                fill(before);
                fill(after);
                let values = &region[inside * inside_len..][..inside_len];
                for (slot, &value) in middle.iter_mut().zip(values) {
                    slot.write(value);
                }
            });
        // SAFETY: the capacity is `len`, and every row of it was written whole: before, middle
        // and after the region cover the row, and the middle takes `inside_len` values (the
        // region's length was checked to hold them for every row of the region).
        unsafe { full.set_len(len) };
        Some(full)
    }

    /// The results of the region as full-frame ones: pixel indices moved by the region's
    /// corner, arrays pasted into the frame, and the depth's perspective projection replaced by
    /// the full frame's `projection`. The photometric and the integration arrays (≈ 20 MB each
    /// at 1280×720, bound by memory bandwidth) are pasted side by side.
    pub fn paste(
        &self,
        mut photometric: PhotometricResult,
        mut integration: Integration,
        projection: &Projection,
    ) -> (PhotometricResult, Integration) {
        let (top, left) = (self.rows.start, self.cols.start);
        let ps = &mut photometric;
        let it = &mut integration;
        rayon::join(
            || {
                ps.field.normals = self.paste3(&ps.field.normals, f32::NAN);
                ps.field.albedo = self.paste2(&ps.field.albedo, f32::NAN);
                ps.field.mask = self.paste2(&ps.field.mask, false);
                ps.lit_count = self.paste2(&ps.lit_count, 0);
                ps.object_mask = self.paste2(&ps.object_mask, false);
                ps.fill = self.paste2(&ps.fill, false);
                for plane in &mut ps.planes {
                    plane.pixel = (plane.pixel.0 + top, plane.pixel.1 + left);
                }
            },
            || {
                it.depth.depth_mm = self.paste2(&it.depth.depth_mm, f32::NAN);
                if it.depth.perspective.is_some() {
                    it.depth.perspective = Some(*projection);
                }
                it.kept = self.paste2(&it.kept, false);
                it.piece = self.paste2(&it.piece, u32::MAX);
                it.part = self.paste2(&it.part, u32::MAX);
                it.confidence = self.paste2(&it.confidence, Confidence::None);
                it.completed_normals = self.paste3(&it.completed_normals, f32::NAN);
            },
        );
        (photometric, integration)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::ShapeBuilder;

    fn depth_with_block(
        frame: (usize, usize),
        rows: Range<usize>,
        cols: Range<usize>,
    ) -> Array2<f32> {
        Array2::from_shape_fn(frame, |(r, c)| {
            if rows.contains(&r) && cols.contains(&c) {
                (r * frame.1 + c) as f32
            } else {
                f32::NAN
            }
        })
    }

    #[test]
    fn the_region_is_the_bounding_box_grown_and_clipped_to_the_frame() {
        let depth = depth_with_block((60, 80), 20..30, 5..40);
        let roi = Roi::around(&depth, None, 8).expect("a small object");
        assert_eq!((roi.rows.clone(), roi.cols.clone()), (12..38, 0..48));
        // A given mask widens the box.
        let mut mask = Array2::from_elem((60, 80), false);
        mask[(40, 50)] = true;
        let roi = Roi::around(&depth, Some(&mask), 8).expect("a small object");
        assert_eq!((roi.rows.clone(), roi.cols.clone()), (12..49, 0..59));
        // Nothing known, or a region that keeps most of the frame: no region.
        assert_eq!(
            Roi::around(&Array2::from_elem((60, 80), f32::NAN), None, 8),
            None
        );
        assert_eq!(
            Roi::around(&depth_with_block((60, 80), 5..55, 5..75), None, 8),
            None
        );
    }

    #[test]
    fn an_object_at_an_inner_edge_of_the_region_may_go_on_beyond_it() {
        let roi = Roi::around(&depth_with_block((60, 80), 20..30, 5..40), None, 8).unwrap();
        let (rows, cols) = (roi.rows.len(), roi.cols.len());
        let object = |r: usize, c: usize| {
            let mut o = Array2::from_elem((rows, cols), false);
            o[(r, c)] = true;
            o
        };
        assert!(!roi.reached_edge(&object(10, 10)));
        // The left edge is the frame's: nothing lies beyond it.
        assert!(!roi.reached_edge(&object(10, 0)));
        assert!(roi.reached_edge(&object(0, 10)));
        assert!(roi.reached_edge(&object(rows - 1, 10)));
        assert!(roi.reached_edge(&object(10, cols - 1)));
    }

    #[test]
    fn cut_and_pasted_arrays_keep_the_region_and_fill_the_rest() {
        let frame = (30, 40);
        let depth = depth_with_block(frame, 10..14, 12..20);
        let roi = Roi::around(&depth, None, 2).unwrap();
        let region = roi.cut(&depth);
        assert_eq!(region.dim(), (8, 12));
        let full = roi.paste2(&region, f32::NAN);
        for ((p, a), b) in full.indexed_iter().zip(&depth) {
            assert!(a == b || (a.is_nan() && b.is_nan()), "{p:?}: {a} vs {b}");
        }
        // Stored by columns (not row-major) the region is pasted the same way.
        let by_columns =
            Array2::from_shape_vec((8, 12).f(), region.t().iter().copied().collect()).unwrap();
        assert!(by_columns.as_slice().is_none());
        let again = roi.paste2(&by_columns, f32::NAN);
        assert!(
            full.iter()
                .zip(&again)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        let vectors = Array3::from_shape_fn((8, 12, 3), |(r, c, j)| (r * 100 + c * 10 + j) as f32);
        let pasted = roi.paste3(&vectors, -1.0);
        assert_eq!(pasted.dim(), (30, 40, 3));
        for ((r, c, j), &v) in pasted.indexed_iter() {
            let expected = if (8..16).contains(&r) && (10..22).contains(&c) {
                vectors[(r - 8, c - 10, j)]
            } else {
                -1.0
            };
            assert_eq!(v, expected, "({r}, {c}, {j})");
        }
        // Labels: the region's own, outside it none.
        let labels = Array2::from_shape_fn((8, 12), |(r, c)| (r * 12 + c) as u32);
        let pasted = roi.paste2(&labels, u32::MAX);
        assert_eq!(pasted[(8, 10)], 0);
        assert_eq!(pasted[(15, 21)], 95);
        assert_eq!(pasted[(7, 10)], u32::MAX);
        assert_eq!(pasted.iter().filter(|&&l| l != u32::MAX).count(), 96);
    }
}
