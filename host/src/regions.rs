//! Connected regions of pixel masks (4-connectivity): labelling, dropping small pieces and finding
//! the holes a mask encloses. Shared by the object mask of photometric stereo and the per-piece
//! integration of normals, so neither depends on the other.

use ndarray::Array2;
use std::borrow::Cow;

/// Label of a pixel outside every region.
pub const OUTSIDE: u32 = u32::MAX;

/// The 4-connected regions of a mask.
#[derive(Debug, Clone, PartialEq)]
pub struct Regions {
    /// Region index per pixel (0, 1, …), [`OUTSIDE`] where the mask is false.
    pub label: Array2<u32>,
    /// Pixel count of each region.
    pub sizes: Vec<usize>,
}

/// The values of a boolean grid in row-major order, borrowed when they are stored so.
pub(crate) fn row_major(mask: &Array2<bool>) -> Cow<'_, [bool]> {
    match mask.as_slice() {
        Some(flat) => Cow::Borrowed(flat),
        None => Cow::Owned(mask.iter().copied().collect()),
    }
}

/// The row-major indices of the 4-neighbours of pixel `index` of a `rows`×`cols` grid (up,
/// down, left, right; `None` beyond the grid's edge).
pub(crate) fn grid_neighbours(index: usize, (rows, cols): (usize, usize)) -> [Option<usize>; 4] {
    let (r, c) = (index / cols, index % cols);
    [
        (r > 0).then(|| index - cols),
        (r + 1 < rows).then(|| index + cols),
        (c > 0).then(|| index - 1),
        (c + 1 < cols).then(|| index + 1),
    ]
}

/// Labels the 4-connected regions of `mask` in raster order of their first pixel. The flood
/// fill works on row-major indices (the labelling of an object's box was a millisecond of
/// every video window's serial time with 2-D indexing).
pub fn label(mask: &Array2<bool>) -> Regions {
    let (rows, cols) = mask.dim();
    let inside = row_major(mask);
    let mut label = vec![OUTSIDE; rows * cols];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..rows * cols {
        if !inside[start] || label[start] != OUTSIDE {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0;
        label[start] = id;
        stack.push(start);
        while let Some(q) = stack.pop() {
            size += 1;
            for n in grid_neighbours(q, (rows, cols)).into_iter().flatten() {
                if inside[n] && label[n] == OUTSIDE {
                    label[n] = id;
                    stack.push(n);
                }
            }
        }
        sizes.push(size);
    }
    Regions {
        label: Array2::from_shape_vec((rows, cols), label)
            .expect("one label per pixel of the mask"),
        sizes,
    }
}

/// Clears the regions of `mask` with fewer than `min_pixels` pixels.
pub fn remove_small(mask: &mut Array2<bool>, min_pixels: usize) {
    let regions = label(mask);
    for (m, &l) in mask.iter_mut().zip(regions.label.iter()) {
        if l != OUTSIDE && regions.sizes[l as usize] < min_pixels {
            *m = false;
        }
    }
}

/// The holes of `mask`: regions of its complement that do not touch the image border and have
/// at most `max_pixels` pixels.
pub fn enclosed_holes(mask: &Array2<bool>, max_pixels: usize) -> Array2<bool> {
    let (rows, cols) = mask.dim();
    let background = mask.mapv(|m| !m);
    let regions = label(&background);
    let mut touches_border = vec![false; regions.sizes.len()];
    for ((r, c), &l) in regions.label.indexed_iter() {
        if l != OUTSIDE && (r == 0 || c == 0 || r + 1 == rows || c + 1 == cols) {
            touches_border[l as usize] = true;
        }
    }
    regions.label.mapv(|l| {
        l != OUTSIDE && !touches_border[l as usize] && regions.sizes[l as usize] <= max_pixels
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring (with a 3×3 hole) and a separate 2-pixel bar, on an 8×10 grid.
    fn ring_and_bar() -> Array2<bool> {
        Array2::from_shape_fn((8, 10), |(r, c)| {
            let ring = (1..6).contains(&r) && (1..6).contains(&c) && !(r == 3 && c == 3);
            let hole_edge = (2..5).contains(&r) && (2..5).contains(&c);
            (ring && !hole_edge) || (r == 7 && (8..10).contains(&c))
        })
    }

    #[test]
    fn labels_remove_and_holes() {
        let mask = ring_and_bar();
        let regions = label(&mask);
        assert_eq!(regions.sizes, vec![16, 2]);
        assert_eq!(regions.label[(1, 1)], 0);
        assert_eq!(regions.label[(7, 9)], 1);
        assert_eq!(regions.label[(0, 0)], OUTSIDE);
        let holes = enclosed_holes(&mask, 100);
        assert_eq!(holes.iter().filter(|&&h| h).count(), 9);
        assert!(holes[(3, 3)] && !holes[(0, 0)] && !holes[(7, 0)]);
        assert!(
            !enclosed_holes(&mask, 8).iter().any(|&h| h),
            "hole larger than the limit"
        );
        let mut kept = mask.clone();
        remove_small(&mut kept, 3);
        assert_eq!(kept.iter().filter(|&&m| m).count(), 16);
        assert!(!kept[(7, 9)]);
    }
}
