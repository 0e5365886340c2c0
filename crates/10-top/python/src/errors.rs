//! Rust errors as Python exceptions, with the messages the CLI prints.
//!
//! The exception classes live in the pure-Python half of the package (`handeye/_errors.py`), so
//! they can inherit from two bases: `InputError(HandeyeError, ValueError)` for bad input (shapes,
//! NaN, non-rigid matrices, millimetres, a refused solve, a malformed file) and
//! `FileError(HandeyeError, OSError)` for a file that cannot be read or written. The message is
//! the error and its causes joined by `: `, each said once, as the CLI prints them
//! (`handeye_core::error_text::error_chain`).

use std::error::Error;

use handeye_core::error_text::error_chain;
use pyo3::prelude::*;
use pyo3::types::PyType;

/// True when an I/O failure is somewhere in the chain (a file problem, not bad content).
fn is_io(error: &(dyn Error + 'static)) -> bool {
    let mut current = Some(error);
    while let Some(e) = current {
        if e.downcast_ref::<std::io::Error>().is_some() {
            return true;
        }
        current = e.source();
    }
    false
}

/// One of the package's exception classes, by name (`InputError`, `FileError`, `HandeyeError`).
fn class<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyType>> {
    Ok(py
        .import("handeye._errors")?
        .getattr(name)?
        .cast_into::<PyType>()?)
}

/// An exception of the package's class `name` with `text` as its message.
pub(crate) fn raise(py: Python<'_>, name: &str, text: impl Into<String>) -> PyErr {
    let text = text.into();
    match class(py, name) {
        Ok(class) => PyErr::from_type(class, text),
        // The package is incomplete (the extension imported on its own): a plain ValueError
        // still carries the message.
        Err(_) => pyo3::exceptions::PyValueError::new_err(text),
    }
}

/// Bad input: `handeye.InputError` (a `ValueError`).
pub(crate) fn input(py: Python<'_>, text: impl Into<String>) -> PyErr {
    raise(py, "InputError", text)
}

/// A library error: `FileError` (an `OSError`) when the cause is an I/O failure, else
/// `InputError` (a `ValueError`); the message is the error's chain.
pub(crate) fn from_error(py: Python<'_>, error: &(dyn Error + 'static)) -> PyErr {
    let name = if is_io(error) {
        "FileError"
    } else {
        "InputError"
    };
    raise(py, name, error_chain(error))
}

/// [`from_error`] with `context` before the message (`solving session DIR: ...`), as the CLI
/// adds it.
pub(crate) fn with_context(py: Python<'_>, context: &str, error: &(dyn Error + 'static)) -> PyErr {
    let name = if is_io(error) {
        "FileError"
    } else {
        "InputError"
    };
    raise(py, name, format!("{context}: {}", error_chain(error)))
}

/// `handeye.CalibrationWarning` (through `handeye._errors.warn_verdict`, the one place that
/// says it) when `verdict` is not GOOD, pointing at the Python line that called into Rust. A
/// warnings filter set to "error" makes it an exception, returned here.
pub(crate) fn warn_verdict(
    py: Python<'_>,
    verdict: Option<Py<crate::calibrate::VerdictPy>>,
) -> PyResult<()> {
    if let Some(verdict) = verdict {
        // Stack level 1 above `warn_verdict`'s own frame: a Rust function has no frame, so
        // that is the caller's line.
        py.import("handeye._errors")?
            .call_method1("warn_verdict", (verdict, 1))?;
    }
    Ok(())
}
