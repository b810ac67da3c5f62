//! NumPy `.npy` arrays (format 1.0–3.0, through `ndarray-npy`) with errors a user can act on:
//! a wrong element type names the type found and the one expected, a wrong shape gives both
//! shapes, a truncated file says so.
//!
//! Images and normal fields are float32; float64 files are accepted and converted wherever a
//! float array is read ([`read_float`]), so every command reads the same files.

use super::FilesError;
use ndarray::{Array, ArrayD, Dimension};
use ndarray_npy::{ReadNpyError, ReadNpyExt, ReadableElement, WritableElement, WriteNpyExt};
use std::path::Path;

/// Writes `array` to `path` as `.npy` (float32 arrays as `<f4`, masks as `|b1`).
pub fn write_npy<A, D>(path: &Path, array: &Array<A, D>) -> Result<(), FilesError>
where
    A: WritableElement,
    D: Dimension,
{
    let bytes = encode(path, array)?;
    std::fs::write(path, bytes).map_err(|e| FilesError::write(path, e))
}

/// Writes `array` to `path` as [`write_npy`] does and waits until it is on disk, large arrays
/// past the page cache ([`super::direct`]).
pub fn write_npy_synced<A, D>(path: &Path, array: &Array<A, D>) -> Result<(), FilesError>
where
    A: WritableElement,
    D: Dimension,
{
    let bytes = encode(path, array)?;
    super::direct::write_synced(path, &bytes).map_err(|e| FilesError::write(path, e))?;
    Ok(())
}

/// The `.npy` file of `array` (to be written at `path`), in memory.
fn encode<A, D>(path: &Path, array: &Array<A, D>) -> Result<Vec<u8>, FilesError>
where
    A: WritableElement,
    D: Dimension,
{
    // The data and a header of at most a few hundred bytes, without regrowing.
    let mut bytes =
        Vec::with_capacity(std::mem::size_of_val(array.as_slice().unwrap_or(&[])) + 512);
    array
        .write_npy(&mut bytes)
        .map_err(|e| FilesError::Encode {
            path: path.to_path_buf(),
            source: Box::new(e),
        })?;
    Ok(bytes)
}

/// Reads a float array (float32, or float64 converted to float32) and checks its shape:
/// `shape[k] == None` accepts any length on axis k.
pub fn read_float<D: Dimension>(
    path: &Path,
    shape: &[Option<usize>],
) -> Result<Array<f32, D>, FilesError> {
    let bytes = read_bytes(path)?;
    let array = match decode::<f32>(path, &bytes) {
        Err(FilesError::NpyType { .. }) => {
            decode::<f64>(path, &bytes).map(|a| a.mapv(|v| v as f32))
        }
        other => other,
    }
    .map_err(|e| match e {
        FilesError::NpyType { path, found, .. } => FilesError::NpyType {
            path,
            found,
            expected: "float32 (or float64)",
        },
        e => e,
    })?;
    with_shape(path, array, shape)
}

/// Reads an array of element type `T` (e.g. `bool` for masks) and checks its shape as
/// [`read_float`] does.
pub fn read_exact<T: ReadableElement, D: Dimension>(
    path: &Path,
    shape: &[Option<usize>],
) -> Result<Array<T, D>, FilesError> {
    let bytes = read_bytes(path)?;
    with_shape(path, decode::<T>(path, &bytes)?, shape)
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, FilesError> {
    std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => FilesError::Missing {
            path: path.to_path_buf(),
        },
        _ => FilesError::read(path, e),
    })
}

/// Parses `.npy` bytes into an array of any dimension.
fn decode<T: ReadableElement>(path: &Path, bytes: &[u8]) -> Result<ArrayD<T>, FilesError> {
    let path = path.to_path_buf();
    ArrayD::<T>::read_npy(bytes).map_err(|e| match e {
        ReadNpyError::Io(source) => FilesError::Read { path, source },
        ReadNpyError::ParseHeader(source) => FilesError::NpyHeader {
            path,
            source: Box::new(source),
        },
        ReadNpyError::ParseData(source) => FilesError::NpyData { path, source },
        ReadNpyError::WrongDescriptor(descr) => FilesError::NpyType {
            path,
            found: type_name(&descr.to_string()),
            expected: std::any::type_name::<T>(),
        },
        ReadNpyError::MissingData => FilesError::NpyTruncated { path },
        ReadNpyError::ExtraBytes(extra) => FilesError::NpyExtraBytes { path, extra },
        ReadNpyError::LengthOverflow | ReadNpyError::WrongNdim(..) => FilesError::NpyShape {
            path,
            found: "an array too large to address".into(),
            expected: "an image-sized array".into(),
        },
        // `ReadNpyError` may grow variants; report them as unreadable data.
        #[allow(unreachable_patterns)]
        other => FilesError::NpyData {
            path,
            source: Box::new(other),
        },
    })
}

/// "float64 ('<f8')" from a NumPy type descriptor such as `'<f8'`.
fn type_name(descr: &str) -> String {
    let code = descr.trim_matches(|c| c == '\'' || c == '"');
    let kind = code.trim_start_matches(['<', '>', '|', '=']);
    let name = match kind {
        "f2" => "float16",
        "f4" => "float32",
        "f8" => "float64",
        "i1" => "int8",
        "i2" => "int16",
        "i4" => "int32",
        "i8" => "int64",
        "u1" => "uint8",
        "u2" => "uint16",
        "u4" => "uint32",
        "u8" => "uint64",
        "b1" => "bool",
        _ => return format!("{descr} (not a plain number type)"),
    };
    format!("{name} ({descr})")
}

/// "3-D, 4×5×3" for messages.
pub fn describe_shape(shape: &[usize]) -> String {
    let sizes: Vec<String> = shape.iter().map(usize::to_string).collect();
    format!("{}-D, {}", shape.len(), sizes.join("×"))
}

/// "H×W×3" style text for an expected shape.
fn describe_expected(shape: &[Option<usize>]) -> String {
    let names = ["H", "W", "C", "D"];
    let sizes: Vec<String> = shape
        .iter()
        .enumerate()
        .map(|(k, s)| {
            s.map_or_else(
                || names.get(k).unwrap_or(&"N").to_string(),
                |n| n.to_string(),
            )
        })
        .collect();
    format!("{}-D, {}", shape.len(), sizes.join("×"))
}

fn with_shape<T, D: Dimension>(
    path: &Path,
    array: ArrayD<T>,
    shape: &[Option<usize>],
) -> Result<Array<T, D>, FilesError> {
    let fits = array.ndim() == shape.len()
        && D::NDIM.is_none_or(|n| n == shape.len())
        && array
            .shape()
            .iter()
            .zip(shape)
            .all(|(&n, s)| s.is_none_or(|s| s == n));
    if !fits {
        return Err(FilesError::NpyShape {
            path: path.to_path_buf(),
            found: describe_shape(array.shape()),
            expected: describe_expected(shape),
        });
    }
    let found = describe_shape(array.shape());
    array
        .into_dimensionality::<D>()
        .map_err(|_| FilesError::NpyShape {
            path: path.to_path_buf(),
            found,
            expected: describe_expected(shape),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array2, Array3, Ix2, Ix3};

    #[test]
    fn float64_is_accepted_and_other_types_are_named() {
        let tmp = tempfile::tempdir().unwrap();
        let f64_path = tmp.path().join("f64.npy");
        write_npy(&f64_path, &Array2::from_elem((2, 3), 0.5f64)).unwrap();
        let back: Array2<f32> = read_float::<Ix2>(&f64_path, &[None, None]).unwrap();
        assert_eq!(back, Array2::from_elem((2, 3), 0.5f32));
        let i32_path = tmp.path().join("i32.npy");
        write_npy(&i32_path, &Array2::from_elem((2, 3), 7i32)).unwrap();
        let err = read_float::<Ix2>(&i32_path, &[None, None]).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("int32 ('<i4')") && text.contains("float32 (or float64) expected"),
            "{text}"
        );
    }

    #[test]
    fn shape_errors_show_both_shapes() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("normals.npy");
        write_npy(&path, &Array3::from_elem((4, 5, 2), 0.0f32)).unwrap();
        let err = read_float::<Ix3>(&path, &[None, None, Some(3)]).unwrap_err();
        assert!(
            err.to_string()
                .contains("is 3-D, 4×5×2; expected 3-D, H×W×3"),
            "{err}"
        );
        let err = read_float::<Ix2>(&path, &[Some(4), Some(5)]).unwrap_err();
        assert!(err.to_string().contains("expected 2-D, 4×5"), "{err}");
        let truncated = tmp.path().join("cut.npy");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&truncated, &bytes[..bytes.len() - 8]).unwrap();
        let err = read_float::<Ix3>(&truncated, &[None, None, Some(3)]).unwrap_err();
        assert!(matches!(err, FilesError::NpyTruncated { .. }), "{err}");
        let missing = read_float::<Ix2>(&tmp.path().join("nope.npy"), &[None, None]);
        assert!(matches!(missing, Err(FilesError::Missing { .. })));
    }
}
