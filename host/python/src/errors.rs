//! The package's exceptions and the conversion of library errors into them.
//!
//! `MebError` is raised for what the library refuses (its message is the library error's, with
//! its causes, as the `meb` command prints it); `ImplausibleError` (a `MebError`) for a result
//! the library judged implausible, carrying the verdict. Bad arguments raise `ValueError`
//! (wrong shapes, values, NaN) or `TypeError` (wrong dtypes).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    _meb,
    MebError,
    PyException,
    "An input meb cannot process or a result it refuses; the message says what looks wrong and what to try."
);
create_exception!(
    _meb,
    ImplausibleError,
    MebError,
    "A result meb judges implausible (a decode, a rig or a reconstruction that does not explain the data). `verdict` holds the problems and the advice; pass force=True to keep such a result."
);

/// Adds the exceptions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("MebError", py.get_type::<MebError>())?;
    m.add("ImplausibleError", py.get_type::<ImplausibleError>())?;
    Ok(())
}

/// An error's message followed by its causes (`: `-separated), as the `meb` command shows
/// the chain.
pub fn chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut message = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let text = cause.to_string();
        if !message.contains(&text) {
            message.push_str(": ");
            message.push_str(&text);
        }
        source = cause.source();
    }
    message
}

/// A `MebError` with `context` before the library error's chain (`context: error: cause`).
pub fn meb_error(context: Option<&str>, error: &(dyn std::error::Error + 'static)) -> PyErr {
    let text = chain(error);
    MebError::new_err(match context {
        Some(context) => format!("{context}: {text}"),
        None => text,
    })
}

/// An `ImplausibleError` with `message`, its `verdict` attribute set to `verdict` (a dict:
/// status, problems, advice) and `report` to the result's report, if any.
pub fn implausible(
    py: Python<'_>,
    message: String,
    verdict: Py<PyAny>,
    report: Option<Py<PyAny>>,
) -> PyErr {
    let error = ImplausibleError::new_err(message);
    let value = error.value(py);
    // Setting attributes on a fresh exception instance cannot fail in practice; if it did,
    // the exception still carries its message.
    let _ = value.setattr("verdict", verdict);
    let _ = value.setattr("report", report.unwrap_or_else(|| py.None()));
    error
}
