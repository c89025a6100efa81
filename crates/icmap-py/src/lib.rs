//! PyO3 binding of icmap-geom (argument conversion, GIL release, error mapping only).
use pyo3::prelude::*;

#[pymodule]
fn _icmap(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
