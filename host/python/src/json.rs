//! Library records (serde) as Python objects: dicts, lists, numbers and strings, through
//! JSON, so that Python sees exactly the fields `decode.json` and `report.json` hold.

use pyo3::prelude::*;

/// `value` serialised with serde and parsed by Python's `json` module.
pub fn to_python<T: serde::Serialize>(py: Python<'_>, value: &T) -> PyResult<Py<PyAny>> {
    let text = serde_json::to_string(value).map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!("cannot convert a record: {e}"))
    })?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}
