//! `vectorise`: argument conversion, the GIL released around the engine's vectoriser, results as
//! numpy arrays. No algorithm lives here (see `icmap_geom::vectorise`).

use icmap_geom::vectorise::{vectorise as vectorise_core, VectoriseParams};
use numpy::ndarray::Array3;
use numpy::prelude::*;
use numpy::{PyArray1, PyArray3, PyReadonlyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::errors::IntoPyResult;

/// `(classes (N,) int64, scores (N,) float32, points (N, P, 2) float32)`.
type Instances<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray1<f32>>,
    Bound<'py, PyArray3<f32>>,
);

/// Instances of one frame from class probabilities `(K, X, Y)` float32 (see `_icmap.pyi`).
#[pyfunction]
#[pyo3(signature = (
    prob, half_x, half_y, *, upsample = 4, threshold = 0.5, min_length = 2.0, min_area = 2.0,
    shrink = 0.9, rectangularity = 0.6, corner_tolerance = 2.0, hull_simplify = 0.5,
    max_hole = 2.0, simplify = 0.2, through = 45.0, spur = 4.0, ridge_classes = vec![1],
    ridge_threshold = 0.3, ridge_sigma = 0.6, ridge_curvature = 0.22, num_points = 20,
    edge_margin = 1.5, edge_span = 3.0, bend = 45.0, band = 1.8, parallel = true
))]
#[allow(clippy::too_many_arguments)]
pub fn vectorise<'py>(
    py: Python<'py>,
    prob: PyReadonlyArray3<'py, f32>,
    half_x: f64,
    half_y: f64,
    upsample: usize,
    threshold: f64,
    min_length: f64,
    min_area: f64,
    shrink: f64,
    rectangularity: f64,
    corner_tolerance: f64,
    hull_simplify: f64,
    max_hole: f64,
    simplify: f64,
    through: f64,
    spur: f64,
    ridge_classes: Vec<i64>,
    ridge_threshold: f64,
    ridge_sigma: f64,
    ridge_curvature: f64,
    num_points: usize,
    edge_margin: f64,
    edge_span: f64,
    bend: f64,
    band: f64,
    parallel: bool,
) -> PyResult<Instances<'py>> {
    let ridge_classes = ridge_classes
        .into_iter()
        .map(|k| {
            usize::try_from(k).map_err(|_| {
                PyValueError::new_err(format!(
                    "invalid parameter `ridge_classes`: class indices are >= 0, got {k}"
                ))
            })
        })
        .collect::<PyResult<Vec<usize>>>()?;
    let params = VectoriseParams {
        upsample,
        threshold,
        min_length,
        min_area,
        shrink,
        rectangularity,
        corner_tolerance,
        hull_simplify,
        max_hole,
        simplify,
        through,
        spur,
        ridge_classes,
        ridge_threshold,
        ridge_sigma,
        ridge_curvature,
        num_points,
        edge_margin,
        edge_span,
        bend,
        band,
    };
    let view = prob.as_array();
    let shape = [view.shape()[0], view.shape()[1], view.shape()[2]];
    let data: Vec<f32> = match view.as_slice() {
        Some(s) => s.to_vec(),
        None => view.iter().copied().collect(),
    };
    let out = py
        .detach(|| vectorise_core(&data, shape, half_x, half_y, &params, parallel))
        .py_err()?;
    let n = out.len();
    let p = out.num_points;
    let flat: Vec<f32> = out.points.iter().flat_map(|q| [q[0], q[1]]).collect();
    let points = Array3::from_shape_vec((n, p, 2), flat).map_err(|e| {
        pyo3::exceptions::PyRuntimeError::new_err(format!("vectorise: inconsistent sizes: {e}"))
    })?;
    Ok((
        PyArray1::from_vec(py, out.classes),
        PyArray1::from_vec(py, out.scores),
        points.into_pyarray(py),
    ))
}
