//! Filling unknown values inside a region from the known ones around them: slopes of two-LED
//! pixels and holes, their albedo, and a warm start's missing depths ([`super::coverage`]).
//!
//! A push–pull pyramid (Gortler et al., "The Lumigraph", SIGGRAPH 1996, §3.4): coarser levels
//! average the known values (pull), finer ones blend their partial averages with the coarser
//! level's (push), which reaches into holes of any size; a few Gauss–Seidel sweeps of the
//! Laplace equation over the filled pixels then smooth the seams. Everything that depends only
//! on which pixels are known — the pyramid's weights and every filled pixel's neighbours — is
//! worked out once in an [`Inpainting`] and shared by the channels filled over the same pixels
//! (s_x and s_y), on flat row-major arrays.

use ndarray::Array2;

/// Gauss–Seidel sweeps that smooth the push–pull interpolation.
const SMOOTHING_SWEEPS: usize = 30;

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
    /// Row-major index of each pixel to fill, in raster order.
    free: Vec<u32>,
    /// Neighbours (up, down, left, right) of each pixel to fill that are wanted or known, and
    /// their count.
    stencil: Vec<([u32; 4], u8)>,
}

impl Inpainting {
    /// The pyramid and smoothing stencil for filling `wanted ∧ ¬known` from `known`.
    pub fn new(known: &Array2<bool>, wanted: &Array2<bool>) -> Self {
        let shape = known.dim();
        let (rows, cols) = shape;
        let known: Vec<bool> = known.iter().copied().collect();
        let wanted: Vec<bool> = wanted.iter().copied().collect();
        let free: Vec<u32> = (0..rows * cols)
            .filter(|&i| wanted[i] && !known[i])
            .map(|i| i as u32)
            .collect();
        let stencil = free
            .iter()
            .map(|&i| {
                let (r, c) = (i as usize / cols, i as usize % cols);
                let mut nb = [0u32; 4];
                let mut n = 0u8;
                let candidates = [
                    (r > 0).then(|| i as usize - cols),
                    (r + 1 < rows).then(|| i as usize + cols),
                    (c > 0).then(|| i as usize - 1),
                    (c + 1 < cols).then(|| i as usize + 1),
                ];
                for q in candidates.into_iter().flatten() {
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
                for (i, &w) in fine.weight.iter().enumerate() {
                    if w > 0.0 {
                        let (r, c) = (i / fine.cols, i % fine.cols);
                        summed[(r / 2) * coarse_cols + c / 2] += w;
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
        Self {
            shape,
            levels,
            free,
            stencil,
        }
    }

    /// Fills `values` (of the grid's size) at the free pixels; the values there on entry are
    /// ignored (they may be NaN).
    pub fn fill(&self, values: &mut Array2<f64>) {
        if self.free.is_empty() {
            return;
        }
        assert_eq!(
            values.dim(),
            self.shape,
            "inpainting a grid of another size"
        );
        // Pull: every level's weighted mean of the known values below it.
        let mut pyramid: Vec<Vec<f64>> = vec![values.iter().copied().collect()];
        for pair in self.levels.windows(2) {
            let (fine, coarse) = (&pair[0], &pair[1]);
            let v = &pyramid[pyramid.len() - 1];
            let mut cv = vec![0.0; coarse.len];
            for (i, &w) in fine.weight.iter().enumerate() {
                if w > 0.0 {
                    let (r, c) = (i / fine.cols, i % fine.cols);
                    cv[(r / 2) * coarse.cols + c / 2] += w * v[i];
                }
            }
            for (value, &summed) in cv.iter_mut().zip(&coarse.summed) {
                if summed > 0.0 {
                    *value /= summed;
                }
            }
            pyramid.push(cv);
        }
        // Push: blend every level with its parent where it is not fully known.
        for l in (0..self.levels.len() - 1).rev() {
            let (upper, lower) = pyramid.split_at_mut(l + 1);
            let (fine_v, coarse_v) = (&mut upper[l], &lower[0]);
            let (fine, coarse) = (&self.levels[l], &self.levels[l + 1]);
            for (i, (v, &w)) in fine_v.iter_mut().zip(&fine.weight).enumerate() {
                if w < 1.0 {
                    // An unknown value (w = 0) may be NaN: take the coarse level's alone.
                    let (r, c) = (i / fine.cols, i % fine.cols);
                    let parent = coarse_v[(r / 2) * coarse.cols + c / 2];
                    *v = if w > 0.0 {
                        w * *v + (1.0 - w) * parent
                    } else {
                        parent
                    };
                }
            }
        }
        let filled = &pyramid[0];
        let mut flat: Vec<f64> = values.iter().copied().collect();
        for &i in &self.free {
            let v = filled[i as usize];
            flat[i as usize] = if v.is_finite() { v } else { 0.0 };
        }
        for _ in 0..SMOOTHING_SWEEPS {
            for (&i, &(nb, n)) in self.free.iter().zip(&self.stencil) {
                if n > 0 {
                    let sum: f64 = nb[..n as usize].iter().map(|&q| flat[q as usize]).sum();
                    flat[i as usize] = sum / f64::from(n);
                }
            }
        }
        for (v, &f) in values.iter_mut().zip(&flat) {
            *v = f;
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
        assert_eq!((a1.clone(), b1), (a2, b2));
        // Known pixels and pixels outside `wanted` keep their values.
        for ((p, &k), &w) in known.indexed_iter().zip(wanted.iter()) {
            if k || !w {
                assert_eq!(a1[p], a[p], "{p:?}");
            }
        }
    }
}
