//! numpy arrays in and out: typed, shape-checked inputs with clear errors, and read-only
//! views of Rust arrays owned by a result object.

use ndarray::{Array, ArrayView2, Dimension};
use numpy::{Element, PyArray, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// `object` as a numpy array of element `T` and dimension `D`; `name` and `dtype` (numpy's
/// name, e.g. `float32`) word the errors: `TypeError` for a non-array or another dtype,
/// `ValueError` for another number of dimensions. Nothing is converted.
pub fn typed<'py, T: Element, D: Dimension>(
    object: &Bound<'py, PyAny>,
    name: &str,
    dtype: &str,
    what: &str,
) -> PyResult<Bound<'py, PyArray<T, D>>> {
    if let Ok(array) = object.cast::<PyArray<T, D>>() {
        return Ok(array.clone());
    }
    let Ok(untyped) = object.cast::<PyUntypedArray>() else {
        let kind = object
            .get_type()
            .name()
            .map_or_else(|_| "?".to_string(), |n| n.to_string());
        return Err(PyTypeError::new_err(format!(
            "{name} must be a numpy array ({what}, {dtype}), got {kind}"
        )));
    };
    let shape = untyped.shape().to_vec();
    if let Some(ndim) = D::NDIM
        && shape.len() != ndim
    {
        return Err(PyValueError::new_err(format!(
            "{name} must be {what}, got an array of shape {shape:?}"
        )));
    }
    let got = untyped.dtype().to_string();
    Err(PyTypeError::new_err(format!(
        "{name} must be {dtype}, got {got} (meb converts nothing silently: pass \
         {name}.astype(np.{dtype}))"
    )))
}

/// A read-only numpy view of `array`, whose memory `owner` (a result object holding it
/// behind an `Arc` it never mutates) keeps alive.
pub fn view<'py, T: Element, D: Dimension>(
    array: &Array<T, D>,
    owner: Bound<'py, PyAny>,
) -> Bound<'py, PyArray<T, D>> {
    // SAFETY: `owner` becomes the view's base object, so it outlives the view, and it holds
    // `array` immutably (behind an `Arc`, never replaced): the memory is neither freed nor
    // reallocated while the view exists.
    let view = unsafe { PyArray::borrow_from_array(array, owner) };
    view.readwrite().make_nonwriteable();
    view
}

/// Refuses NaN or infinite values of `values` where `mask` is set (`ValueError` naming the
/// first such pixel).
pub fn check_finite_in(
    values: impl Iterator<Item = ((usize, usize), bool)>,
    name: &str,
) -> PyResult<()> {
    for ((row, col), finite) in values {
        if !finite {
            return Err(PyValueError::new_err(format!(
                "{name} holds NaN or infinity at row {row}, column {col} inside the mask \
                 (mask such pixels out, or fill them)"
            )));
        }
    }
    Ok(())
}

/// Checks that `mask` has the shape `(rows, cols)` and at least one set pixel.
pub fn check_mask(mask: &ArrayView2<'_, bool>, rows: usize, cols: usize, of: &str) -> PyResult<()> {
    if mask.dim() != (rows, cols) {
        return Err(PyValueError::new_err(format!(
            "mask is {}x{} (rows x columns) but {of} is {rows}x{cols}",
            mask.dim().0,
            mask.dim().1
        )));
    }
    if !mask.iter().any(|&m| m) {
        return Err(PyValueError::new_err("empty mask: no pixel is set"));
    }
    Ok(())
}
