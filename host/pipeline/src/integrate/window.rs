//! The window of the grid an integration works on: the bounding box of everything to integrate.
//! Outside it nothing is integrated, so solving inside it gives the same result as on the whole
//! grid at a fraction of the cost; full-frame work is limited to finding the box.

use super::IntegrateError;
use ndarray::{Array2, s};

/// A box of the grid (module docs).
pub(super) struct Window {
    /// Its rows.
    pub rows: std::ops::Range<usize>,
    /// Its columns.
    pub cols: std::ops::Range<usize>,
}

impl Window {
    /// The smallest box holding every set pixel of `mask`, or `None` if there is none.
    pub fn around(mask: &Array2<bool>) -> Option<Self> {
        Self::around_all(&[mask], std::iter::empty())
    }

    /// The smallest box holding every set pixel of `masks` and every pixel of `pixels`, or
    /// `None` if there is none.
    pub fn around_all(
        masks: &[&Array2<bool>],
        pixels: impl Iterator<Item = (usize, usize)>,
    ) -> Option<Self> {
        let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
        for mask in masks {
            for (r, row) in mask.outer_iter().enumerate() {
                if let Some(first) = row.iter().position(|&m| m) {
                    let last = row.len() - 1 - row.iter().rev().position(|&m| m).unwrap_or(0);
                    (r0, r1) = (r0.min(r), r1.max(r + 1));
                    (c0, c1) = (c0.min(first), c1.max(last + 1));
                }
            }
        }
        for (r, c) in pixels {
            (r0, r1) = (r0.min(r), r1.max(r + 1));
            (c0, c1) = (c0.min(c), c1.max(c + 1));
        }
        (r0 < r1).then_some(Self {
            rows: r0..r1,
            cols: c0..c1,
        })
    }

    /// The part of `a` inside the window.
    pub fn view<'a, T>(&self, a: &'a Array2<T>) -> ndarray::ArrayView2<'a, T> {
        a.slice(s![self.rows.clone(), self.cols.clone()])
    }

    /// Moves pixel positions in an error from window to grid coordinates.
    pub fn shift_error(&self, e: IntegrateError) -> IntegrateError {
        match e {
            IntegrateError::NonFinite { count, row, col } => IntegrateError::NonFinite {
                count,
                row: row + self.rows.start,
                col: col + self.cols.start,
            },
            other => other,
        }
    }
}
