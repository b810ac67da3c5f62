//! Test helpers for array layouts: code that walks an array's storage must read any layout as
//! the same pixels, so tests feed it copies stored otherwise.

use ndarray::{Array2, ShapeBuilder};

/// `a` stored column by column (Fortran order): the same pixels, but for a grid of at least
/// 2×2 no row is contiguous.
pub fn column_major<T: Clone>(a: &Array2<T>) -> Array2<T> {
    let stored = Array2::from_shape_vec(a.dim().f(), a.t().iter().cloned().collect())
        .expect("one value per pixel");
    assert!(
        a.nrows() < 2 || a.ncols() < 2 || stored.row(0).as_slice().is_none(),
        "a column-major copy with contiguous rows"
    );
    stored
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_column_major_copy_holds_the_same_pixels_by_columns() {
        let a = Array2::from_shape_fn((3, 4), |(r, c)| 10 * r + c);
        let b = column_major(&a);
        assert_eq!(b, a);
        assert_eq!(b.strides(), &[1, 3]);
        assert_eq!(column_major(&Array2::<u8>::zeros((1, 5))).dim(), (1, 5));
    }
}
