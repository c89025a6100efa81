//! Mapping of [`GeomError`] to Python exceptions.
//!
//! ValueError: bad values (non-finite or outside the coordinate domain, too few points,
//! degenerate, bad parameter, unknown class, duplicate id, corrupt file). KeyError: unknown instance id. OSError (the errno subclass, e.g.
//! FileNotFoundError, when the OS gave one): I/O failures, with the path as `filename`.

use icmap_geom::GeomError;
use pyo3::exceptions::{PyKeyError, PyOSError, PyValueError};
use pyo3::PyErr;

/// Converts a core error into the Python exception the contract names.
pub fn to_py(err: GeomError) -> PyErr {
    let msg = err.to_string();
    match err {
        GeomError::UnknownId(_) => PyKeyError::new_err(msg),
        GeomError::Io { path, source } => match source.raw_os_error() {
            // OSError(errno, strerror, filename) picks the errno subclass (FileNotFoundError ...).
            Some(errno) => PyOSError::new_err((errno, msg, path)),
            None => PyOSError::new_err(msg),
        },
        GeomError::NonFinite { .. }
        | GeomError::OutOfDomain { .. }
        | GeomError::TooFewPoints { .. }
        | GeomError::Degenerate { .. }
        | GeomError::UnknownClass(_)
        | GeomError::DuplicateId(_)
        | GeomError::InvalidParameter { .. }
        | GeomError::Format { .. } => PyValueError::new_err(msg),
    }
}

/// `Result<T, GeomError>` -> `PyResult<T>`.
pub trait IntoPyResult<T> {
    fn py_err(self) -> pyo3::PyResult<T>;
}

impl<T> IntoPyResult<T> for Result<T, GeomError> {
    fn py_err(self) -> pyo3::PyResult<T> {
        self.map_err(to_py)
    }
}
