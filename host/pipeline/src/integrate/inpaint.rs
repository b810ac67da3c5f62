//! Filling unknown values inside a region from the known ones around them: slopes of two-LED
//! pixels and holes, their albedo, and a warm start's missing depths ([`super::coverage`]).
//!
//! A push–pull pyramid (Gortler et al., "The Lumigraph", SIGGRAPH 1996, §3.4): coarser levels
//! average the known values (pull), finer ones blend their partial averages with the coarser
//! level's (push), which reaches into holes of any size; a few red–black Gauss–Seidel sweeps of
//! the Laplace equation over the filled pixels then smooth the seams. Everything that depends only
//! on which pixels are known — the pyramid's weights and every filled pixel's neighbours — is
//! worked out once in an [`Inpainting`] and shared by the channels filled over the same pixels
//! (s_x and s_y, filled together as pairs in one pass, or as triples with the albedo where it is
//! known at the same pixels: [`Channels`]). The fill works in the grid's own row-major storage:
//! the pull reads the known values there, the push reaches the grid only at the pixels to fill
//! (its weights there are 0), and the sweeps update it in place.

use crate::regions::{grid_neighbours, row_major};
use ndarray::Array2;

/// Red–black Gauss–Seidel sweeps that smooth the push–pull interpolation.
const SMOOTHING_SWEEPS: usize = 30;

/// A pixel's values in the channels filled together: one value, or a pair (s_x, s_y) filled in
/// one pass over the shared pyramid and stencil. Every operation acts on each channel on its
/// own, so a pair is filled exactly as its two channels would be one by one.
pub(crate) trait Channels: Copy {
    /// The same value in every channel.
    fn splat(v: f64) -> Self;
    /// `f` of every channel.
    fn map(self, f: impl Fn(f64) -> f64) -> Self;
    /// `f` of every channel of `self` and the same channel of `other`.
    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self;
}

impl Channels for f64 {
    fn splat(v: f64) -> Self {
        v
    }

    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        f(self)
    }

    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        f(self, other)
    }
}

impl Channels for (f64, f64) {
    fn splat(v: f64) -> Self {
        (v, v)
    }

    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        (f(self.0), f(self.1))
    }

    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        (f(self.0, other.0), f(self.1, other.1))
    }
}

impl Channels for (f64, f64, f64) {
    fn splat(v: f64) -> Self {
        (v, v, v)
    }

    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        (f(self.0), f(self.1), f(self.2))
    }

    fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        (f(self.0, other.0), f(self.1, other.1), f(self.2, other.2))
    }
}

/// One level of the pull pyramid: its size, each cell's summed weight of known values below
/// and that weight clipped to 1 (the cell's confidence in the next level and in the push).
struct Level {
    cols: usize,
    len: usize,
    summed: Vec<f64>,
    weight: Vec<f64>,
}

/// How to fill the pixels of `wanted` that are not `known` (module docs).
pub(crate) struct Inpainting {
    /// Grid size (rows, columns).
    shape: (usize, usize),
    /// Level 0 (the grid, weight 1 where known) and the coarser levels, finest first.
    levels: Vec<Level>,
    /// Row-major index of each pixel to fill: those of even row + column first, then the odd
    /// ones, each in raster order. No pixel neighbours one of its own colour, so a sweep in
    /// this order is a red–black Gauss–Seidel sweep: within a colour no update waits for the
    /// one before it (in raster order each waited for its left neighbour's, and a sweep took
    /// 2.5× as long).
    free: Vec<u32>,
    /// Cell of level 1 above each pixel to fill (the push reaches level 0 only there: its
    /// weights are 0 or 1, so a pixel to fill takes its parent's value).
    parent: Vec<u32>,
    /// Neighbours (up, down, left, right) of each pixel to fill that are wanted or known, and
    /// their count.
    stencil: Vec<([u32; 4], u8)>,
}

impl Inpainting {
    /// The pyramid and smoothing stencil for filling `wanted ∧ ¬known` from `known`.
    pub fn new(known: &Array2<bool>, wanted: &Array2<bool>) -> Self {
        let shape = known.dim();
        let (rows, cols) = shape;
        assert_eq!(wanted.dim(), shape, "inpainting masks of different sizes");
        let (known, wanted) = (row_major(known), row_major(wanted));
        // Red–black order: the pixels of even (row + column) first, then the odd ones.
        let (mut free, odd): (Vec<u32>, Vec<u32>) = (0..rows * cols)
            .filter(|&i| wanted[i] && !known[i])
            .map(|i| i as u32)
            .partition(|&i| (i as usize / cols + i as usize % cols).is_multiple_of(2));
        free.extend(odd);
        let stencil = free
            .iter()
            .map(|&i| {
                let mut nb = [0u32; 4];
                let mut n = 0u8;
                for q in grid_neighbours(i as usize, shape).into_iter().flatten() {
                    if wanted[q] || known[q] {
                        nb[n as usize] = q as u32;
                        n += 1;
                    }
                }
                (nb, n)
            })
            .collect();
        let mut levels = vec![Level {
            cols,
            len: rows * cols,
            summed: Vec::new(),
            weight: known.iter().map(|&k| if k { 1.0 } else { 0.0 }).collect(),
        }];
        let mut level_rows = rows;
        if !free.is_empty() {
            loop {
                let fine = &levels[levels.len() - 1];
                if (level_rows <= 1 && fine.cols <= 1) || fine.weight.iter().all(|&w| w > 0.0) {
                    break;
                }
                let (coarse_rows, coarse_cols) = (level_rows.div_ceil(2), fine.cols.div_ceil(2));
                let mut summed = vec![0.0; coarse_rows * coarse_cols];
                for (r, weights) in fine.weight.chunks_exact(fine.cols).enumerate() {
                    let parents = &mut summed[(r / 2) * coarse_cols..][..coarse_cols];
                    for (c, &w) in weights.iter().enumerate() {
                        if w > 0.0 {
                            parents[c / 2] += w;
                        }
                    }
                }
                let weight = summed.iter().map(|&w| f64::min(w, 1.0)).collect();
                levels.push(Level {
                    cols: coarse_cols,
                    len: coarse_rows * coarse_cols,
                    summed,
                    weight,
                });
                level_rows = coarse_rows;
            }
        }
        let parent = match levels.get(1) {
            Some(coarse) => free
                .iter()
                .map(|&i| {
                    let (r, c) = (i as usize / cols, i as usize % cols);
                    ((r / 2) * coarse.cols + c / 2) as u32
                })
                .collect(),
            None => Vec::new(),
        };
        Self {
            shape,
            levels,
            free,
            parent,
            stencil,
        }
    }

    /// Fills `values` (of the grid's size; one channel or several, [`Channels`]) at the free
    /// pixels; the values there on entry are ignored (they may be NaN).
    pub fn fill<T: Channels>(&self, values: &mut Array2<T>) {
        if self.free.is_empty() {
            return;
        }
        assert_eq!(
            values.dim(),
            self.shape,
            "inpainting a grid of another size"
        );
        match values.as_slice_mut() {
            Some(flat) => self.fill_row_major(flat),
            None => {
                let mut flat: Vec<T> = values.iter().copied().collect();
                self.fill_row_major(&mut flat);
                for (v, f) in values.iter_mut().zip(flat) {
                    *v = f;
                }
            }
        }
    }

    /// [`Self::fill`] on the grid's values in row-major order.
    fn fill_row_major<T: Channels>(&self, values: &mut [T]) {
        // Pull: every coarser level's weighted mean of the known values below it.
        let mut pyramid: Vec<Vec<T>> = Vec::with_capacity(self.levels.len().saturating_sub(1));
        for pair in self.levels.windows(2) {
            let below: &[T] = pyramid.last().map_or(&*values, |v| v);
            let pulled = pull(&pair[0], &pair[1], below);
            pyramid.push(pulled);
        }
        // Push: blend every coarser level with its parent where it is not fully known.
        for l in (1..pyramid.len()).rev() {
            let (upper, lower) = pyramid.split_at_mut(l);
            push(
                &self.levels[l],
                &self.levels[l + 1],
                &mut upper[l - 1],
                &lower[0],
            );
        }
        // Level 0: a pixel to fill (weight 0) takes its parent's value.
        let finite = |v: T| v.map(|a| if a.is_finite() { a } else { 0.0 });
        match pyramid.first() {
            Some(level_1) => {
                for (&i, &p) in self.free.iter().zip(&self.parent) {
                    values[i as usize] = finite(level_1[p as usize]);
                }
            }
            None => {
                for &i in &self.free {
                    values[i as usize] = finite(values[i as usize]);
                }
            }
        }
        for _ in 0..SMOOTHING_SWEEPS {
            for (&i, &(nb, n)) in self.free.iter().zip(&self.stencil) {
                // Summed in order from −0 like `Iterator::sum`; an inner pixel's four
                // neighbours without the loop.
                let add = |s: T, q: u32| s.zip(values[q as usize], |a, b| a + b);
                let sum = match n {
                    0 => continue,
                    4 => nb.iter().fold(T::splat(-0.0), |s, &q| add(s, q)),
                    _ => nb[..n as usize]
                        .iter()
                        .fold(T::splat(-0.0), |s, &q| add(s, q)),
                };
                values[i as usize] = sum.map(|a| a / f64::from(n));
            }
        }
    }
}

/// The weighted means on `coarse` of the values `below` on `fine` (row-major) where known.
fn pull<T: Channels>(fine: &Level, coarse: &Level, below: &[T]) -> Vec<T> {
    let mut pulled = vec![T::splat(0.0); coarse.len];
    let rows = fine
        .weight
        .chunks_exact(fine.cols)
        .zip(below.chunks_exact(fine.cols));
    for (r, (weights, row)) in rows.enumerate() {
        let parents = &mut pulled[(r / 2) * coarse.cols..][..coarse.cols];
        for (c, (&w, &v)) in weights.iter().zip(row).enumerate() {
            if w > 0.0 {
                let p = &mut parents[c / 2];
                *p = p.zip(v, |sum, v| sum + w * v);
            }
        }
    }
    for (value, &summed) in pulled.iter_mut().zip(&coarse.summed) {
        if summed > 0.0 {
            *value = value.map(|v| v / summed);
        }
    }
    pulled
}

/// Blends the values of `fine` (row-major) with their parents on `coarse` where `fine` is
/// not fully known.
fn push<T: Channels>(fine: &Level, coarse: &Level, values: &mut [T], parents: &[T]) {
    let rows = values
        .chunks_exact_mut(fine.cols)
        .zip(fine.weight.chunks_exact(fine.cols));
    for (r, (row, weights)) in rows.enumerate() {
        let above = &parents[(r / 2) * coarse.cols..][..coarse.cols];
        for (c, (v, &w)) in row.iter_mut().zip(weights).enumerate() {
            if w < 1.0 {
                // An unknown value (w = 0) may be NaN: take the coarse level's alone.
                let parent = above[c / 2];
                *v = if w > 0.0 {
                    v.zip(parent, |v, p| w * v + (1.0 - w) * p)
                } else {
                    parent
                };
            }
        }
    }
}

/// Fills `values` at the pixels of `wanted` that are not `known`, from the known ones (module
/// docs; one channel).
pub(crate) fn inpaint(values: &mut Array2<f64>, known: &Array2<bool>, wanted: &Array2<bool>) {
    Inpainting::new(known, wanted).fill(values);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inpainting_fills_a_hole_in_a_linear_ramp_exactly_enough() {
        let shape = (20, 24);
        let ramp = Array2::from_shape_fn(shape, |(r, c)| 0.1 * c as f64 - 0.05 * r as f64);
        let hole =
            Array2::from_shape_fn(shape, |(r, c)| (6..12).contains(&r) && (8..16).contains(&c));
        let known = hole.mapv(|h| !h);
        let mut values = ramp.mapv(|v| v);
        values.zip_mut_with(&hole, |v, &h| {
            if h {
                *v = 99.0;
            }
        });
        let wanted = Array2::from_elem(shape, true);
        let mut unknown_nan = values.clone();
        unknown_nan.zip_mut_with(&hole, |v, &h| {
            if h {
                *v = f64::NAN;
            }
        });
        inpaint(&mut values, &known, &wanted);
        // Unknown values do not leak in, even when they are NaN.
        inpaint(&mut unknown_nan, &known, &wanted);
        assert_eq!(unknown_nan, values);
        let worst = values
            .iter()
            .zip(ramp.iter())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // A harmonic fill of a linear function is the function; 30 sweeps get close.
        assert!(worst < 0.05, "worst {worst}");
    }

    #[test]
    fn one_inpainting_fills_several_channels_as_separate_ones_do() {
        // Two holes, one touching the border, and a region that is not the whole grid.
        let shape = (17, 23);
        let known = Array2::from_shape_fn(shape, |(r, c)| {
            let first_hole = (3..9).contains(&r) && (4..12).contains(&c);
            let border_hole = r < 4 && c > 18;
            !(first_hole || border_hole)
        });
        let wanted = Array2::from_shape_fn(shape, |(r, c)| r + c > 3);
        let a = Array2::from_shape_fn(shape, |(r, c)| ((r * 7 + c * 13) % 11) as f64);
        let b = Array2::from_shape_fn(shape, |(r, c)| (r as f64 * 0.3).sin() + c as f64);
        let shared = Inpainting::new(&known, &wanted);
        let (mut a1, mut b1) = (a.clone(), b.clone());
        shared.fill(&mut a1);
        shared.fill(&mut b1);
        let (mut a2, mut b2) = (a.clone(), b.clone());
        inpaint(&mut a2, &known, &wanted);
        inpaint(&mut b2, &known, &wanted);
        assert_eq!((a1.clone(), b1.clone()), (a2, b2));
        // Both channels filled together as pairs, bit for bit as one by one (NaN at the
        // pixels to fill, which must not leak in).
        let mut pairs = Array2::from_shape_fn(shape, |p| {
            if known[p] || !wanted[p] {
                (a[p], b[p])
            } else {
                (f64::NAN, -0.0)
            }
        });
        shared.fill(&mut pairs);
        let bits = |v: &Array2<f64>| v.mapv(f64::to_bits);
        assert_eq!(bits(&pairs.mapv(|p| p.0)), bits(&a1));
        assert_eq!(bits(&pairs.mapv(|p| p.1)), bits(&b1));
        // And three channels as triples (the third: a doubled, which every step keeps exact).
        let mut triples = Array2::from_shape_fn(shape, |p| {
            if known[p] || !wanted[p] {
                (a[p], b[p], 2.0 * a[p])
            } else {
                (-0.0, f64::NAN, f64::INFINITY)
            }
        });
        shared.fill(&mut triples);
        assert_eq!(bits(&triples.mapv(|p| p.0)), bits(&a1));
        assert_eq!(bits(&triples.mapv(|p| p.1)), bits(&b1));
        assert_eq!(bits(&triples.mapv(|p| p.2 / 2.0)), bits(&a1));
        // Known pixels and pixels outside `wanted` keep their values.
        for ((p, &k), &w) in known.indexed_iter().zip(wanted.iter()) {
            if k || !w {
                assert_eq!(a1[p], a[p], "{p:?}");
            }
        }
    }

    #[test]
    fn a_grid_stored_by_columns_is_filled_as_one_stored_by_rows() {
        use ndarray::ShapeBuilder;
        let shape = (9, 14);
        let known = Array2::from_shape_fn(shape, |(r, c)| !((2..6).contains(&r) && c > 3));
        let wanted = Array2::from_shape_fn(shape, |(r, c)| r + c < 19);
        let values = Array2::from_shape_fn(shape, |(r, c)| (r * r) as f64 - 0.5 * c as f64);
        let inpainting = Inpainting::new(&known, &wanted);
        let mut by_rows = values.clone();
        inpainting.fill(&mut by_rows);
        let mut by_columns = Array2::from_shape_fn(shape.f(), |p| values[p]);
        assert!(by_columns.as_slice().is_none());
        inpainting.fill(&mut by_columns);
        assert_eq!(by_columns, by_rows);
        assert_ne!(by_rows, values);
    }
}
