//! Conversion of Python arguments (array-likes, poses, extents, ids) into core types, and of core
//! results into numpy arrays. Shape/dtype problems raise ValueError/TypeError naming the argument.

use icmap_geom::{Point, Pose2};
use numpy::ndarray::{Array2, Array3, ArrayView2};
use numpy::prelude::*;
use numpy::{PyArray1, PyArray2, PyArray3, PyReadonlyArray2, PyUntypedArray};
use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};

use crate::errors::IntoPyResult;

/// numpy `dtype.kind` codes accepted as coordinates: signed/unsigned integers and floats.
const REAL_KINDS: &[u8] = b"iuf";

fn rows_to_points<T: Copy + Into<f64>>(view: ArrayView2<'_, T>) -> Vec<Point> {
    view.outer_iter()
        .map(|r| Point::new(r[0].into(), r[1].into()))
        .collect()
}

fn shape_str(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(|d| d.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Any array-like (ndarray of a real dtype, nested sequences) as a numpy array of float64, after
/// checking its dtype kind. `name` names the argument in error messages.
fn as_f64_array<'py>(obj: &Bound<'py, PyAny>, name: &str) -> PyResult<Bound<'py, PyUntypedArray>> {
    let py = obj.py();
    if obj.is_instance_of::<pyo3::types::PyString>() || obj.is_instance_of::<pyo3::types::PyBytes>()
    {
        return Err(PyTypeError::new_err(format!(
            "{name} must be an array of coordinates, got {}",
            obj.get_type().name()?
        )));
    }
    let np = numpy::get_array_module(py)?;
    let arr = np.call_method1("asarray", (obj,))?;
    let arr = arr.cast_into::<PyUntypedArray>().map_err(|_| {
        PyTypeError::new_err(format!("{name} could not be converted to a numpy array"))
    })?;
    let dtype = arr.dtype();
    if !REAL_KINDS.contains(&dtype.kind()) {
        return Err(PyTypeError::new_err(format!(
            "{name} must have a real numeric dtype (float64, float32 or integer), got dtype {}",
            dtype.str()?
        )));
    }
    if dtype.kind() == b'f' && dtype.is_equiv_to(&numpy::dtype::<f64>(py)) {
        return Ok(arr);
    }
    Ok(arr
        .call_method1("astype", ("float64",))?
        .cast_into::<PyUntypedArray>()?)
}

/// An `(n, 2)` array-like as points (float64/float32 fast paths, any real dtype otherwise).
pub fn points_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Point>> {
    let check = |shape: &[usize]| -> PyResult<()> {
        if shape.len() != 2 || shape[1] != 2 {
            return Err(PyValueError::new_err(format!(
                "{name} must have shape (n, 2), got shape {}",
                shape_str(shape)
            )));
        }
        Ok(())
    };
    // The two fast paths copy the array's rows while holding the GIL, with nothing in between
    // that could run Python code, so no Python code can change the array meanwhile; reading it
    // without rust-numpy's dynamic borrow tracking (`readonly()`: a global borrow table updated
    // on every call) is then sound, and that tracking is a measurable share of a small merge.
    // (Native code that writes into the array while it has released the GIL would race with
    // `readonly()` just the same: that tracking only knows of rust-numpy's own borrows.)
    if let Ok(a) = obj.cast::<PyArray2<f64>>() {
        check(a.shape())?;
        // SAFETY: see above; the view lives only during the copy.
        return Ok(rows_to_points(unsafe { a.as_array() }));
    }
    if let Ok(a) = obj.cast::<PyArray2<f32>>() {
        check(a.shape())?;
        // SAFETY: as for float64.
        return Ok(rows_to_points(unsafe { a.as_array() }));
    }
    let arr = as_f64_array(obj, name)?;
    check(arr.shape())?;
    let typed: PyReadonlyArray2<'_, f64> = arr.cast_into::<PyArray2<f64>>()?.readonly();
    Ok(rows_to_points(typed.as_array()))
}

/// A list of point sets: an `(A, n, 2)` array or a sequence of `(n_i, 2)` array-likes.
pub fn point_sets_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<Vec<Vec<Point>>> {
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for (i, item) in obj.try_iter()?.enumerate() {
            out.push(points_arg(&item?, &format!("{name}[{i}]"))?);
        }
        return Ok(out);
    }
    let arr = as_f64_array(obj, name)?;
    let shape = arr.shape().to_vec();
    if shape.len() != 3 || shape[2] != 2 {
        return Err(PyValueError::new_err(format!(
            "{name} must be an (A, n, 2) array or a list of (n, 2) arrays, got shape {}",
            shape_str(&shape)
        )));
    }
    let typed = arr.cast_into::<numpy::PyArray3<f64>>()?;
    let ro = typed.readonly();
    let view = ro.as_array();
    Ok(view.outer_iter().map(rows_to_points).collect())
}

/// A fixed-length sequence of finite-or-not floats (validated by the core).
fn floats_arg<const N: usize>(
    obj: &Bound<'_, PyAny>,
    name: &str,
    what: &str,
) -> PyResult<[f64; N]> {
    if obj.is_instance_of::<pyo3::types::PyString>() {
        return Err(PyTypeError::new_err(format!(
            "{name} must be a sequence {what}, got str"
        )));
    }
    let v: Vec<f64> = obj.extract().map_err(|_| {
        PyTypeError::new_err(format!(
            "{name} must be a sequence of numbers {what}, got {}",
            obj.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default()
        ))
    })?;
    v.as_slice().try_into().map_err(|_| {
        PyValueError::new_err(format!(
            "{name} must have {N} values {what}, got {}",
            v.len()
        ))
    })
}

/// `(x, y, yaw)` as a pose.
pub fn pose_arg(obj: &Bound<'_, PyAny>) -> PyResult<Pose2> {
    let [x, y, yaw] = floats_arg::<3>(obj, "pose", "(x, y, yaw)")?;
    Pose2::new(x, y, yaw).py_err()
}

/// `(hx, hy)` half extents (sign checked by the core).
pub fn extents_arg(obj: &Bound<'_, PyAny>) -> PyResult<[f64; 2]> {
    floats_arg::<2>(obj, "half_extents", "(hx, hy)")
}

/// A region `(xmin, ymin, xmax, ymax)` (NaN and order checked by the core).
pub fn bbox_arg(obj: &Bound<'_, PyAny>) -> PyResult<[f64; 4]> {
    floats_arg::<4>(obj, "bbox", "(xmin, ymin, xmax, ymax)")
}

/// Points as an `(n, 2)` float64 array.
pub fn points_to_py<'py>(py: Python<'py>, pts: &[Point]) -> Bound<'py, PyArray2<f64>> {
    let mut arr = Array2::<f64>::zeros((pts.len(), 2));
    for (mut row, p) in arr.outer_iter_mut().zip(pts) {
        row[0] = p.x;
        row[1] = p.y;
    }
    arr.into_pyarray(py)
}

/// Points as a `(k, n, 2)` float32 array (`pts.len() == k * n`).
pub fn points3_f32_to_py<'py>(
    py: Python<'py>,
    pts: &[Point],
    k: usize,
    n: usize,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let flat: Vec<f32> = pts.iter().flat_map(|p| [p.x as f32, p.y as f32]).collect();
    let arr = Array3::from_shape_vec((k, n, 2), flat).map_err(internal)?;
    Ok(arr.into_pyarray(py))
}

/// A flat row-major vector as a `(rows, cols)` array.
pub fn matrix_to_py<T: numpy::Element>(
    py: Python<'_>,
    v: Vec<T>,
    rows: usize,
    cols: usize,
) -> PyResult<Bound<'_, PyArray2<T>>> {
    Ok(Array2::from_shape_vec((rows, cols), v)
        .map_err(internal)?
        .into_pyarray(py))
}

/// An inconsistency between core results and their documented sizes (a bug, not user input).
fn internal(err: impl std::fmt::Display) -> PyErr {
    pyo3::exceptions::PyRuntimeError::new_err(format!(
        "icmap-geom returned inconsistent sizes: {err}"
    ))
}

/// A vector as a 1-D array.
pub fn vec_to_py<T: numpy::Element>(py: Python<'_>, v: Vec<T>) -> Bound<'_, PyArray1<T>> {
    PyArray1::from_vec(py, v)
}

/// An integer argument (a Python int or anything with `__index__`, e.g. numpy ints). `TypeError`
/// naming the argument for anything else; `ValueError` naming it when the int does not fit in 64
/// bits (pyo3's own `OverflowError` names neither the argument nor the limit).
pub fn int_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<i64> {
    match obj.extract::<i64>() {
        Ok(v) => Ok(v),
        Err(e) if e.is_instance_of::<PyOverflowError>(obj.py()) => Err(PyValueError::new_err(
            format!("invalid parameter `{name}`: must fit in a signed 64-bit integer, got {obj}"),
        )),
        Err(_) => Err(PyTypeError::new_err(format!(
            "expected an int for `{name}`, got {}",
            obj.get_type().name()?
        ))),
    }
}

/// A count argument: [`int_arg`], and not negative (the core checks its own bounds).
pub fn count_arg(obj: &Bound<'_, PyAny>, name: &str) -> PyResult<usize> {
    let n = int_arg(obj, name)?;
    usize::try_from(n).map_err(|_| {
        PyValueError::new_err(format!("invalid parameter `{name}`: must be >= 0, got {n}"))
    })
}

/// `n` of `resample` (for `#[pyo3(from_py_with)]`).
pub fn n_arg(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    count_arg(obj, "n")
}

/// `n_points` of `sample_patch`.
pub fn n_points_arg(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    count_arg(obj, "n_points")
}

/// A `frame` number.
pub fn frame_arg(obj: &Bound<'_, PyAny>) -> PyResult<i64> {
    int_arg(obj, "frame")
}
