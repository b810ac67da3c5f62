//! Surface slopes from normals: ∂z/∂x = −n_x/n_z, ∂z/∂y = −n_y/n_z, y up
//! (docs/maths/integration.md#slopes-from-normals).

use super::IntegrateError;
use meb_core::types::NormalField;
use ndarray::{Array2, ArrayView2, ArrayView3};

/// Dimensionless slopes of z(x, y) on the pixel grid and the pixels to integrate over.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceGradients {
    /// ∂z/∂x, x to the right (along columns).
    pub dzdx: Array2<f64>,
    /// ∂z/∂y, y up (towards row 0).
    pub dzdy: Array2<f64>,
    /// Pixels inside the surface.
    pub mask: Array2<bool>,
}

impl SurfaceGradients {
    /// Slopes of a normal field inside its mask; normals facing away from the camera (n_z ≤ 0)
    /// are left out and slopes are clipped to ±`max_slope`. NaN normals inside the mask are an error.
    pub fn from_normals(field: &NormalField, max_slope: f64) -> Result<Self, IntegrateError> {
        check_field_shape(field)?;
        Self::from_normal_views(field.normals.view(), field.mask.view(), max_slope)
    }

    /// [`Self::from_normals`] on views of equal shape (H×W×3 normals, H×W mask).
    pub(crate) fn from_normal_views(
        normals: ArrayView3<f32>,
        mask: ArrayView2<bool>,
        max_slope: f64,
    ) -> Result<Self, IntegrateError> {
        let shape = mask.dim();
        let mut bad = (0usize, 0, 0);
        let mut mask = mask.to_owned();
        let mut dzdx = Array2::zeros(shape);
        let mut dzdy = Array2::zeros(shape);
        for ((r, c), m) in mask.indexed_iter_mut() {
            if !*m {
                continue;
            }
            let n = [0, 1, 2].map(|j| f64::from(normals[(r, c, j)]));
            if n.iter().any(|v| !v.is_finite()) {
                if bad.0 == 0 {
                    bad = (0, r, c);
                }
                bad.0 += 1;
                continue;
            }
            if n[2] <= 1e-6 {
                *m = false;
                continue;
            }
            dzdx[(r, c)] = (-n[0] / n[2]).clamp(-max_slope, max_slope);
            dzdy[(r, c)] = (-n[1] / n[2]).clamp(-max_slope, max_slope);
        }
        if bad.0 > 0 {
            return Err(IntegrateError::NonFinite {
                count: bad.0,
                row: bad.1,
                col: bad.2,
            });
        }
        Ok(Self { dzdx, dzdy, mask })
    }

    /// Checks that the slope arrays have the mask's shape.
    pub fn check_shapes(&self) -> Result<(), IntegrateError> {
        let shape = self.mask.dim();
        for (what, a) in [("dzdx", &self.dzdx), ("dzdy", &self.dzdy)] {
            if a.dim() != shape {
                return Err(IntegrateError::SizeMismatch {
                    what: what.into(),
                    got: a.dim(),
                    expected: shape,
                });
            }
        }
        Ok(())
    }

    /// Checks shapes and finiteness inside the mask.
    pub fn validate(&self) -> Result<(), IntegrateError> {
        self.check_shapes()?;
        let mut first = None;
        let mut count = 0;
        for ((r, c), &m) in self.mask.indexed_iter() {
            if m && !(self.dzdx[(r, c)].is_finite() && self.dzdy[(r, c)].is_finite()) {
                count += 1;
                first.get_or_insert((r, c));
            }
        }
        if let Some((row, col)) = first {
            return Err(IntegrateError::NonFinite { count, row, col });
        }
        if !self.mask.iter().any(|&m| m) {
            return Err(IntegrateError::EmptyMask);
        }
        Ok(())
    }
}

/// Checks that a normal field is H×W×3 over its H×W mask.
pub(crate) fn check_field_shape(field: &NormalField) -> Result<(), IntegrateError> {
    let shape = field.mask.dim();
    let (nr, nc, three) = field.normals.dim();
    if (nr, nc) != shape || three != 3 {
        return Err(IntegrateError::SizeMismatch {
            what: "normal field".into(),
            got: (nr, nc),
            expected: shape,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array3;

    #[test]
    fn nan_normals_inside_the_mask_are_an_error() {
        let mut normals =
            Array3::from_shape_fn((3, 3, 3), |(_, _, j)| if j == 2 { 1.0 } else { 0.0 });
        normals[(1, 2, 0)] = f32::NAN;
        let field = NormalField {
            normals,
            albedo: Array2::ones((3, 3)),
            mask: Array2::from_elem((3, 3), true),
        };
        let err = SurfaceGradients::from_normals(&field, 10.0).unwrap_err();
        assert!(
            matches!(
                err,
                IntegrateError::NonFinite {
                    count: 1,
                    row: 1,
                    col: 2
                }
            ),
            "{err}"
        );
        let empty = NormalField {
            mask: Array2::from_elem((3, 3), false),
            ..field
        };
        let g = SurfaceGradients::from_normals(&empty, 10.0).unwrap();
        assert!(matches!(g.validate(), Err(IntegrateError::EmptyMask)));
    }
}
