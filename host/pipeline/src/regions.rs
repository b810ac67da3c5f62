//! Connected regions of pixel masks (4-connectivity): labelling, dropping small pieces, finding
//! the holes a mask encloses, and a mask's bounding box. Shared by the object mask of
//! photometric stereo, the per-piece integration of normals and the video's focus and
//! pictures, so none depends on another.

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

/// Labels the 4-connected regions of `mask` in raster order of their first pixel, by runs
/// (Rosenfeld & Pfaltz's two-pass labelling on row runs, with union–find): each row's runs
/// of set pixels are joined to the runs they overlap in the row above, and every run is then
/// written with its region's label. A pixel-by-pixel flood fill of a video window's object box
/// (≈ 110 000 pixels, one large region) took a third of a millisecond; the runs of that box
/// number a few hundred.
pub fn label(mask: &Array2<bool>) -> Regions {
    let (rows, cols) = mask.dim();
    let runs = RunRegions::of(mask);
    let mut label = vec![OUTSIDE; rows * cols];
    for (run, &id) in runs.runs.runs.iter().zip(&runs.region_of_run) {
        label[run.clone()].fill(id);
    }
    Regions {
        label: Array2::from_shape_vec((rows, cols), label)
            .expect("one label per pixel of the mask"),
        sizes: runs.sizes,
    }
}

/// The regions of a mask as runs ([`label`] before its labels are written per pixel).
struct RunRegions {
    runs: RowRuns,
    /// Region of each run, numbered in raster order of the regions' first pixels.
    region_of_run: Vec<u32>,
    /// Pixel count of each region.
    sizes: Vec<usize>,
}

impl RunRegions {
    fn of(mask: &Array2<bool>) -> Self {
        let (rows, cols) = mask.dim();
        let inside = row_major(mask);
        let runs = row_runs(&inside, (rows, cols));
        // Union–find over the runs, the root of a set always its first run in raster order.
        let mut parent: Vec<u32> = (0..runs.runs.len() as u32).collect();
        for r in 1..rows {
            let (above, here) = (runs.of_row(r - 1), runs.of_row(r));
            let (mut i, mut j) = (above.start, here.start);
            while i < above.end && j < here.end {
                // Run a one row up, in the row-major indices of b's row.
                let (a, b) = (&runs.runs[i], &runs.runs[j]);
                let (a_start, a_end) = (a.start + cols, a.end + cols);
                // 4-connected: the column ranges overlap.
                if a_start < b.end && b.start < a_end {
                    let (x, y) = (root(&mut parent, i as u32), root(&mut parent, j as u32));
                    let (low, high) = (x.min(y), x.max(y));
                    parent[high as usize] = low;
                }
                if a_end < b.end {
                    i += 1;
                } else {
                    j += 1;
                }
            }
        }
        // Regions numbered in order of their first run (so of their first pixel) in raster
        // order.
        let mut region_of_run = vec![OUTSIDE; runs.runs.len()];
        let mut sizes: Vec<usize> = Vec::new();
        for (k, run) in runs.runs.iter().enumerate() {
            let first = root(&mut parent, k as u32) as usize;
            let id = if first == k {
                sizes.push(0);
                (sizes.len() - 1) as u32
            } else {
                region_of_run[first]
            };
            region_of_run[k] = id;
            sizes[id as usize] += run.len();
        }
        Self {
            runs,
            region_of_run,
            sizes,
        }
    }
}

/// The runs of set pixels of a row-major grid, as row-major index ranges in raster order, and
/// where each row's runs start in that list.
struct RowRuns {
    /// Every run, as a range of row-major indices.
    runs: Vec<std::ops::Range<usize>>,
    /// `first[r]`: index in `runs` of row r's first run (`first[rows]` = the run count).
    first: Vec<usize>,
}

impl RowRuns {
    /// Indices in `runs` of row `r`'s runs.
    fn of_row(&self, r: usize) -> std::ops::Range<usize> {
        self.first[r]..self.first[r + 1]
    }
}

/// The [`RowRuns`] of `inside`, a `rows`×`cols` grid in row-major order.
fn row_runs(inside: &[bool], (rows, cols): (usize, usize)) -> RowRuns {
    let mut runs = Vec::new();
    let mut first = Vec::with_capacity(rows + 1);
    for (r, line) in inside.chunks_exact(cols.max(1)).take(rows).enumerate() {
        first.push(runs.len());
        let mut c = 0;
        while let Some(offset) = line[c..].iter().position(|&m| m) {
            let start = c + offset;
            let end = line[start..]
                .iter()
                .position(|&m| !m)
                .map_or(cols, |o| start + o);
            runs.push(r * cols + start..r * cols + end);
            c = end;
        }
    }
    first.resize(rows + 1, runs.len());
    RowRuns { runs, first }
}

/// The root of element `i`'s set in the union–find forest `parent`, halving the path on the
/// way.
pub(crate) fn root(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

/// Rows and columns holding a set pixel of `mask` (`None`: none is set).
pub fn bounding_box(
    mask: &Array2<bool>,
) -> Option<(std::ops::Range<usize>, std::ops::Range<usize>)> {
    let spans: Vec<(usize, usize, usize)> = mask
        .outer_iter()
        .enumerate()
        .filter_map(|(r, row)| {
            let first = row.iter().position(|&m| m)?;
            let last = row.iter().rposition(|&m| m).unwrap_or(first);
            Some((r, first, last))
        })
        .collect();
    let (top, bottom) = (spans.first()?.0, spans.last()?.0);
    let left = spans.iter().map(|s| s.1).min()?;
    let right = spans.iter().map(|s| s.2).max()?;
    Some((top..bottom + 1, left..right + 1))
}

/// Clears the regions of `mask` with fewer than `min_pixels` pixels, run by run (no label is
/// written per pixel).
pub fn remove_small(mask: &mut Array2<bool>, min_pixels: usize) {
    let regions = RunRegions::of(mask);
    let cols = mask.ncols();
    let small = regions
        .runs
        .runs
        .iter()
        .zip(&regions.region_of_run)
        .filter(|&(_, &id)| regions.sizes[id as usize] < min_pixels)
        .map(|(run, _)| run.clone());
    match mask.as_slice_mut() {
        Some(flat) => small.for_each(|run| flat[run].fill(false)),
        None => {
            for i in small.flatten() {
                mask[(i / cols, i % cols)] = false;
            }
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
    use meb_core::layouts::column_major;

    /// The box spans the extreme rows and columns of any set pixel; an empty mask has none.
    #[test]
    fn the_bounding_box_holds_every_set_pixel() {
        let mut mask = Array2::from_elem((6, 9), false);
        assert_eq!(bounding_box(&mask), None);
        mask[(1, 7)] = true;
        mask[(4, 2)] = true;
        assert_eq!(bounding_box(&mask), Some((1..5, 2..8)));
    }

    /// A ring (with a 3×3 hole) and a separate 2-pixel bar, on an 8×10 grid.
    fn ring_and_bar() -> Array2<bool> {
        Array2::from_shape_fn((8, 10), |(r, c)| {
            let ring = (1..6).contains(&r) && (1..6).contains(&c) && !(r == 3 && c == 3);
            let hole_edge = (2..5).contains(&r) && (2..5).contains(&c);
            (ring && !hole_edge) || (r == 7 && (8..10).contains(&c))
        })
    }

    /// The labelling by a pixel-by-pixel flood fill, in raster order of each region's first
    /// pixel: the reference the run labelling must equal.
    fn flood_fill_labels(mask: &Array2<bool>) -> Regions {
        let (rows, cols) = mask.dim();
        let inside = row_major(mask);
        let mut label = vec![OUTSIDE; rows * cols];
        let mut sizes = Vec::new();
        for start in 0..rows * cols {
            if !inside[start] || label[start] != OUTSIDE {
                continue;
            }
            let id = sizes.len() as u32;
            let (mut size, mut stack) = (0, vec![start]);
            label[start] = id;
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
            label: Array2::from_shape_vec((rows, cols), label).unwrap(),
            sizes,
        }
    }

    /// Random masks of every density (fixed seed), spirals and combs whose regions join far
    /// below their first rows, and degenerate shapes: the runs label exactly as the flood fill,
    /// and clear exactly its small regions.
    #[test]
    fn run_labels_equal_the_flood_fill() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut masks: Vec<Array2<bool>> = Vec::new();
        for density in [0.05, 0.3, 0.5, 0.6, 0.9] {
            for _ in 0..20 {
                let (rows, cols) = (rng.random_range(1..40), rng.random_range(1..40));
                masks.push(Array2::from_shape_fn((rows, cols), |_| {
                    rng.random_bool(density)
                }));
            }
        }
        // A comb: teeth that join only at the bottom row, and a U whose arms meet late.
        masks.push(Array2::from_shape_fn((12, 15), |(r, c)| {
            c % 2 == 0 || r == 11
        }));
        masks.push(Array2::from_shape_fn((9, 9), |(r, c)| {
            (c == 0 || c == 8 || r == 8) && !(r == 8 && c == 4)
        }));
        masks.push(Array2::from_shape_fn((9, 9), |(r, c)| {
            c == 0 || c == 8 || r == 8
        }));
        // A spiral.
        masks.push(Array2::from_shape_fn((11, 11), |(r, c)| {
            let ring = r.min(c).min(10 - r).min(10 - c);
            ring % 2 == 0 && !(c == ring + 1 && r == ring && ring < 5)
        }));
        masks.push(Array2::from_elem((0, 5), true));
        masks.push(Array2::from_elem((5, 0), true));
        masks.push(Array2::from_elem((3, 4), true));
        masks.push(Array2::from_elem((3, 4), false));
        // A column-major mask (not stored row by row).
        masks.push(column_major(&ring_and_bar()));
        for mask in &masks {
            assert_eq!(label(mask), flood_fill_labels(mask), "{mask:?}");
            // Small regions cleared by their runs are those the labels call small, whatever
            // the mask's layout.
            let regions = flood_fill_labels(mask);
            for min_pixels in [2, 5, 40] {
                let expected = regions
                    .label
                    .mapv(|l| l != OUTSIDE && regions.sizes[l as usize] >= min_pixels);
                let mut cleared = mask.clone();
                remove_small(&mut cleared, min_pixels);
                assert_eq!(cleared, expected, "{mask:?} without regions < {min_pixels}");
                let mut stored_by_columns = column_major(mask);
                remove_small(&mut stored_by_columns, min_pixels);
                assert_eq!(stored_by_columns, expected, "column-major {mask:?}");
            }
        }
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
