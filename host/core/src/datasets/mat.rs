//! Numeric arrays from MATLAB v5 files (via the `matfile` crate), converted from MATLAB's
//! column-major order to row-major `ndarray`s.

use super::DatasetError;
use ndarray::{ArrayD, IxDyn, ShapeBuilder};
use std::path::Path;

/// Reads the real part of variable `name` from a MATLAB v5 file as f64, in row-major order.
pub fn read_mat_array(path: &Path, name: &str) -> Result<ArrayD<f64>, DatasetError> {
    let file = std::fs::File::open(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mat = matfile::MatFile::parse(std::io::BufReader::new(file))
        .map_err(|e| DatasetError::format(path, format!("not a MATLAB v5 file: {e}")))?;
    let array = mat
        .find_by_name(name)
        .ok_or_else(|| DatasetError::format(path, format!("no variable `{name}`")))?;
    use matfile::NumericData as N;
    let values: Vec<f64> = match array.data() {
        N::Double { real, .. } => real.clone(),
        N::Single { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::UInt8 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::Int8 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::UInt16 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::Int16 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::UInt32 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::Int32 { real, .. } => real.iter().map(|&v| f64::from(v)).collect(),
        N::UInt64 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Int64 { real, .. } => real.iter().map(|&v| v as f64).collect(),
    };
    let shape = array.size().clone();
    let column_major = ArrayD::from_shape_vec(IxDyn(&shape).f(), values)
        .map_err(|e| DatasetError::format(path, format!("variable `{name}`: {e}")))?;
    Ok(column_major.as_standard_layout().into_owned())
}
