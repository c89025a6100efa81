//! Module-level geometry functions: convert, release the GIL, call the core, convert back.

use icmap_geom as geom;
use icmap_geom::Patch;
use numpy::PyArray2;
use pyo3::prelude::*;

use crate::convert::{
    extents_arg, matrix_to_py, n_arg, point_sets_arg, points_arg, points_to_py, pose_arg,
};
use crate::errors::IntoPyResult;
use pyo3::marker::Ungil;

/// Runs `op` on points with the GIL released; its points as an `(N, 2)` array, or its error.
fn points_op<'py>(
    py: Python<'py>,
    op: impl Ungil + FnOnce() -> geom::Result<Vec<geom::Point>>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let out = py.detach(op).py_err()?;
    Ok(points_to_py(py, &out))
}

fn list_of_arrays<'py>(
    py: Python<'py>,
    parts: &[Vec<geom::Point>],
) -> Vec<Bound<'py, PyArray2<f64>>> {
    parts.iter().map(|p| points_to_py(py, p)).collect()
}

/// Exactly `n` points evenly spaced by arc length (closed: along the contour, first not repeated).
#[pyfunction]
#[pyo3(signature = (points, n, closed = false))]
pub fn resample<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    #[pyo3(from_py_with = n_arg)] n: usize,
    closed: bool,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let pts = points_arg(points, "points")?;
    points_op(py, || geom::resample(&pts, n, closed))
}

/// A module function `name(points, a = default, b = default)` of one point array and two
/// settings whose core function `geom::name(&points, a, b)` returns points: the conversion of
/// `points`, then `points_op`.
macro_rules! points_and_two_settings {
    ($(#[doc = $doc:tt])* $name:ident($a:ident: $ta:ident = $da:tt, $b:ident: $tb:ident = $db:tt)) => {
        $(#[doc = $doc])*
        #[pyfunction]
        #[pyo3(signature = (points, $a = $da, $b = $db))]
        pub fn $name<'py>(
            py: Python<'py>,
            points: &Bound<'py, PyAny>,
            $a: $ta,
            $b: $tb,
        ) -> PyResult<Bound<'py, PyArray2<f64>>> {
            let pts = points_arg(points, "points")?;
            points_op(py, || geom::$name(&pts, $a, $b))
        }
    };
}

points_and_two_settings! {
    /// Points about `spacing` apart by arc length.
    resample_spacing(spacing: f64 = 1.0, closed: bool = false)
}

/// The parts of `points` inside the patch of `pose`, same frame as the input.
#[pyfunction]
#[pyo3(signature = (points, pose, half_extents, margin = 0.0, closed = false))]
pub fn clip_to_patch<'py>(
    py: Python<'py>,
    points: &Bound<'py, PyAny>,
    pose: &Bound<'py, PyAny>,
    half_extents: &Bound<'py, PyAny>,
    margin: f64,
    closed: bool,
) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
    let pts = points_arg(points, "points")?;
    let pose = pose_arg(pose)?;
    let [hx, hy] = extents_arg(half_extents)?;
    let patch = Patch::new(pose, hx, hy, margin).py_err()?;
    let min = if closed { 3 } else { 2 };
    geom::validate_points(&pts, min, "points").py_err()?;
    let parts = py.detach(|| {
        if closed {
            let ring = geom::clip_polygon(&pts, &patch);
            if ring.is_empty() {
                Vec::new()
            } else {
                vec![ring]
            }
        } else {
            geom::clip_polyline(&pts, &patch)
        }
    });
    Ok(list_of_arrays(py, &parts))
}

/// Splices a new open polyline into a stored one by projection: stored points within `overlap`
/// metres of `new` are replaced by it, the rest kept before and after it (`new` oriented like
/// `stored`).
#[pyfunction]
#[pyo3(signature = (stored, new, overlap))]
pub fn splice_polyline<'py>(
    py: Python<'py>,
    stored: &Bound<'py, PyAny>,
    new: &Bound<'py, PyAny>,
    overlap: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let a = points_arg(stored, "stored")?;
    let b = points_arg(new, "new")?;
    points_op(py, || geom::splice_polyline(&a, &b, overlap))
}

points_and_two_settings! {
    /// Smoothing cubic spline fit (scipy `splprep(s=s)` semantics), evaluated about `spacing` apart.
    fit_curve(s: f64 = 0.5, spacing: f64 = 1.0)
}

/// Merges a detected polyline into a global one (Algorithm 2); keeps the global direction.
#[pyfunction]
#[pyo3(signature = (global_pts, detected_pts, s = 0.5, spacing = 1.0))]
pub fn merge_polyline<'py>(
    py: Python<'py>,
    global_pts: &Bound<'py, PyAny>,
    detected_pts: &Bound<'py, PyAny>,
    s: f64,
    spacing: f64,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let g = points_arg(global_pts, "global_pts")?;
    let d = points_arg(detected_pts, "detected_pts")?;
    points_op(py, || geom::merge_polyline(&g, &d, s, spacing))
}

/// Union of closed rings: outer rings, counter-clockwise, largest area first.
#[pyfunction]
pub fn polygon_union<'py>(
    py: Python<'py>,
    rings: &Bound<'py, PyAny>,
) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
    let rings = point_sets_arg(rings, "rings")?;
    let out = py.detach(|| geom::polygon_union(&rings)).py_err()?;
    Ok(list_of_arrays(py, &out))
}

/// (mean nearest distance a->b + mean nearest distance b->a) / 2.
#[pyfunction]
pub fn chamfer_distance(
    py: Python<'_>,
    a: &Bound<'_, PyAny>,
    b: &Bound<'_, PyAny>,
) -> PyResult<f64> {
    let a = points_arg(a, "a")?;
    let b = points_arg(b, "b")?;
    py.detach(|| geom::chamfer_distance(&a, &b)).py_err()
}

/// All pairwise Chamfer distances, `(A, B)` float64.
#[pyfunction]
pub fn chamfer_matrix<'py>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    b: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let a = point_sets_arg(a, "a")?;
    let b = point_sets_arg(b, "b")?;
    let (na, nb) = (a.len(), b.len());
    let out = py.detach(|| geom::chamfer_matrix(&a, &b)).py_err()?;
    matrix_to_py(py, out, na, nb)
}
