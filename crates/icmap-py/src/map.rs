//! `GlobalMap`: the core store behind a `RwLock` in a frozen pyclass, so one map can be shared by
//! several Python threads; every lock is taken with the GIL released.

use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

use icmap_geom as geom;
use icmap_geom::{MapClass, MapConfig, Patch};
use numpy::{PyArray1, PyArray2};
use pyo3::exceptions::{PyKeyError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyInt};

use crate::convert::{
    bbox_arg, extents_arg, frame_arg, int_arg, matrix_to_py, n_points_arg, points3_f32_to_py,
    points_arg, points_to_py, pose_arg, vec_to_py,
};
use crate::errors::IntoPyResult;
use geom::merge_map::MergeMapParams;
use geom::persist_v2::Encoding;
use pyo3::pybacked::PyBackedBytes;
use pyo3::types::PyBytes;

/// The global vector map (world frame): instances with bookkeeping and a spatial index.
#[pyclass(frozen, module = "icmapper._icmap", name = "GlobalMap")]
pub struct PyGlobalMap {
    inner: RwLock<geom::GlobalMap>,
}

fn poisoned() -> PyErr {
    PyRuntimeError::new_err("the map's lock was poisoned by an earlier panic; the map is unusable")
}

/// An instance id argument: a non-negative int; any other int is an unknown id (KeyError).
fn id_arg(obj: &Bound<'_, PyAny>) -> PyResult<u64> {
    if let Ok(id) = obj.extract::<u64>() {
        return Ok(id);
    }
    // Any other integer (negative or too large; Python or numpy): not an instance id.
    if obj.is_instance_of::<PyInt>() || obj.extract::<i128>().is_ok() {
        return Err(PyKeyError::new_err(format!(
            "no instance with id {obj} in the map"
        )));
    }
    Err(PyTypeError::new_err(format!(
        "an instance id must be an int, got {}",
        obj.get_type().name()?
    )))
}

/// A class argument: an int naming one of the classes (`ValueError` for another int).
fn class_arg(obj: &Bound<'_, PyAny>) -> PyResult<MapClass> {
    MapClass::try_from(int_arg(obj, "cls")?).py_err()
}

/// A drive id: an int in 0..=2**32 - 1.
fn drive_arg(obj: &Bound<'_, PyAny>) -> PyResult<u32> {
    if obj.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err("drive must be an int, got bool"));
    }
    if let Ok(d) = obj.extract::<u32>() {
        return Ok(d);
    }
    if obj.extract::<i128>().is_ok() {
        return Err(PyValueError::new_err(format!(
            "drive must be in 0..=2**32 - 1, got {obj}"
        )));
    }
    Err(PyTypeError::new_err(format!(
        "drive must be an int, got {}",
        obj.get_type().name()?
    )))
}

fn encoding_arg(compact: bool) -> Encoding {
    if compact {
        Encoding::Compact
    } else {
        Encoding::Exact
    }
}

impl PyGlobalMap {
    fn read(&self) -> PyResult<RwLockReadGuard<'_, geom::GlobalMap>> {
        self.inner.read().map_err(|_| poisoned())
    }
    fn write(&self) -> PyResult<RwLockWriteGuard<'_, geom::GlobalMap>> {
        self.inner.write().map_err(|_| poisoned())
    }

    /// Runs `f`, an edit of instance `id` with `n_new` new points. Such an edit of an instance of
    /// a few hundred points takes microseconds, of which releasing and re-taking the GIL would be
    /// a noticeable share: when the map's lock is free at once and the instance and the new
    /// points stay within `GIL_HELD_MERGE_POINTS`, it runs with the GIL held. Larger edits, and
    /// any edit that would have to wait for another thread, release the GIL.
    fn edit_small(
        &self,
        py: Python<'_>,
        id: u64,
        n_new: usize,
        f: impl FnOnce(&mut geom::GlobalMap) -> geom::Result<()> + Send,
    ) -> PyResult<()> {
        if n_new <= GIL_HELD_MERGE_POINTS {
            if let Ok(mut map) = self.inner.try_write() {
                let small = map
                    .get(id)
                    .is_none_or(|inst| inst.points.len() + n_new <= GIL_HELD_MERGE_POINTS);
                if small {
                    return f(&mut map).py_err();
                }
            }
        }
        py.detach(|| f(&mut *self.write()?).py_err())
    }
}

/// Largest merge (stored plus detected points) that `merge` runs without releasing the GIL
/// (about 10 microseconds of work; see `merge`).
const GIL_HELD_MERGE_POINTS: usize = 512;

#[pymethods]
impl PyGlobalMap {
    /// An empty map; `smoothing` is the curve-fit `s` used on merge, `spacing` the stored point
    /// spacing in metres.
    #[new]
    #[pyo3(signature = (smoothing = 0.5, spacing = 1.0))]
    fn new(smoothing: f64, spacing: f64) -> PyResult<Self> {
        let map = geom::GlobalMap::new(MapConfig { smoothing, spacing }).py_err()?;
        Ok(PyGlobalMap {
            inner: RwLock::new(map),
        })
    }

    #[getter]
    fn smoothing(&self, py: Python<'_>) -> PyResult<f64> {
        py.detach(|| Ok(self.read()?.config().smoothing))
    }

    #[getter]
    fn spacing(&self, py: Python<'_>) -> PyResult<f64> {
        py.detach(|| Ok(self.read()?.config().spacing))
    }

    fn __len__(&self, py: Python<'_>) -> PyResult<usize> {
        py.detach(|| Ok(self.read()?.len()))
    }

    fn __contains__(&self, py: Python<'_>, id: &Bound<'_, PyAny>) -> PyResult<bool> {
        let Ok(id) = id.extract::<u64>() else {
            return Ok(false);
        };
        py.detach(|| Ok(self.read()?.contains(id)))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        let (n, cfg) = py.detach(|| {
            let m = self.read()?;
            Ok::<_, PyErr>((m.len(), m.config()))
        })?;
        Ok(format!(
            "GlobalMap(len={n}, smoothing={}, spacing={})",
            cfg.smoothing, cfg.spacing
        ))
    }

    /// Inserts a new instance observed at `frame`; returns its id.
    #[pyo3(signature = (cls, points, frame = 0))]
    fn insert(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = class_arg)] cls: MapClass,
        points: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<u64> {
        let pts = points_arg(points, "points")?;
        py.detach(|| self.write()?.insert(cls, &pts, frame).py_err())
    }

    /// Inserts with a caller-chosen id (ValueError if the id exists).
    #[pyo3(signature = (id, cls, points, frame = 0))]
    fn insert_with_id(
        &self,
        py: Python<'_>,
        id: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = class_arg)] cls: MapClass,
        points: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<()> {
        let id: u64 = id.extract().map_err(|_| {
            PyValueError::new_err(format!(
                "id must be a non-negative integer below 2**64, got {id}"
            ))
        })?;
        let pts = points_arg(points, "points")?;
        py.detach(|| self.write()?.insert_with_id(id, cls, &pts, frame).py_err())
    }

    /// Merges a detection (world frame) into instance `id` by its class rule.
    #[pyo3(signature = (id, points, frame = 0))]
    fn merge(
        &self,
        py: Python<'_>,
        id: &Bound<'_, PyAny>,
        points: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<()> {
        let id = id_arg(id)?;
        let pts = points_arg(points, "points")?;
        self.edit_small(py, id, pts.len(), |map| map.merge(id, &pts, frame))
    }

    /// Merges many detections at `frame` (`points[i]` into `ids[i]`): the same map as calling
    /// `merge` for each in order, with the merges of different instances computed in parallel
    /// and the GIL released. Returns, per item, None or the exception `merge` would have raised
    /// (an item that fails does not affect the others). Argument errors (lengths, shapes,
    /// dtypes) raise before anything is merged.
    #[pyo3(signature = (ids, points, frame = 0))]
    fn merge_many<'py>(
        &self,
        py: Python<'py>,
        ids: &Bound<'py, PyAny>,
        points: &Bound<'py, PyAny>,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<Vec<Option<Bound<'py, PyAny>>>> {
        if ids.len().is_ok_and(|n| n >= 4) {
            geom::store::wake_merge_workers(); // they wake while the arguments are converted
        }
        // Per item: the id, or the KeyError of an int that cannot be an instance id.
        let mut id_list: Vec<Result<u64, PyErr>> = Vec::new();
        for item in ids
            .try_iter()
            .map_err(|_| PyTypeError::new_err("ids must be a sequence of ints (instance ids)"))?
        {
            let item = item?;
            id_list.push(match id_arg(&item) {
                Err(e) if !e.is_instance_of::<PyKeyError>(py) => return Err(e),
                other => other,
            });
        }
        let sets = crate::convert::point_sets_arg(points, "points")?;
        if sets.len() != id_list.len() {
            return Err(PyValueError::new_err(format!(
                "ids and points must have the same length, got {} ids and {} point sets",
                id_list.len(),
                sets.len()
            )));
        }
        // Ids that are not valid instance ids (negative ints) fail on their own, as `merge` would.
        let items: Vec<(u64, &[geom::Point])> = id_list
            .iter()
            .zip(&sets)
            .filter_map(|(id, pts)| id.as_ref().ok().map(|&id| (id, pts.as_slice())))
            .collect();
        let results = py.detach(|| Ok::<_, PyErr>(self.write()?.merge_many(&items, frame)))?;
        let mut out: Vec<Option<Bound<'py, PyAny>>> = Vec::with_capacity(id_list.len());
        let mut next = results.into_iter();
        for id in id_list {
            let err = match id {
                Err(e) => Some(e),
                Ok(_) => next.next().and_then(|r| r.err()).map(crate::errors::to_py),
            };
            out.push(err.map(|e| e.into_value(py).into_bound(py).into_any()));
        }
        Ok(out)
    }

    /// Replaces the geometry of instance `id` (world frame) as a new observation at `frame`,
    /// keeping its bookkeeping (for merge rules implemented outside the store).
    #[pyo3(signature = (id, points, frame = 0))]
    fn replace(
        &self,
        py: Python<'_>,
        id: &Bound<'_, PyAny>,
        points: &Bound<'_, PyAny>,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<()> {
        let id = id_arg(id)?;
        let pts = points_arg(points, "points")?;
        py.detach(|| self.write()?.replace(id, &pts, frame).py_err())
    }

    /// Cuts the polyline instance `id` to its stored points `start..stop` (no resampling, no new
    /// observation): a clean-up of a finished map.
    fn trim(
        &self,
        py: Python<'_>,
        id: &Bound<'_, PyAny>,
        start: usize,
        stop: usize,
    ) -> PyResult<()> {
        let id = id_arg(id)?;
        py.detach(|| self.write()?.trim(id, start, stop).py_err())
    }

    /// Splices the open polyline `points` (world frame) into instance `id`: the stretch it covers
    /// (stored points within `overlap` metres) is replaced, the rest kept on either side; a new
    /// observation at `frame`. Small splices run with the GIL held, as small merges do
    /// (`edit_small`).
    #[pyo3(signature = (id, points, overlap = 0.5, frame = 0))]
    fn splice(
        &self,
        py: Python<'_>,
        id: &Bound<'_, PyAny>,
        points: &Bound<'_, PyAny>,
        overlap: f64,
        #[pyo3(from_py_with = frame_arg)] frame: i64,
    ) -> PyResult<()> {
        let id = id_arg(id)?;
        let pts = points_arg(points, "points")?;
        self.edit_small(py, id, pts.len(), |map| {
            map.splice(id, &pts, overlap, frame)
        })
    }

    /// Removes instance `id` (KeyError if absent).
    fn remove(&self, py: Python<'_>, id: &Bound<'_, PyAny>) -> PyResult<()> {
        let id = id_arg(id)?;
        py.detach(|| self.write()?.remove(id).py_err().map(|_| ()))
    }

    /// `(cls, points (n, 2) float64)` of instance `id` (KeyError if absent).
    fn get<'py>(
        &self,
        py: Python<'py>,
        id: &Bound<'py, PyAny>,
    ) -> PyResult<(i64, Bound<'py, PyArray2<f64>>)> {
        let id = id_arg(id)?;
        let (cls, pts) = py.detach(|| {
            let m = self.read()?;
            let inst = m.get(id).ok_or(geom::GeomError::UnknownId(id)).py_err()?;
            Ok::<_, PyErr>((i64::from(inst.class.index()), inst.points.clone()))
        })?;
        Ok((cls, points_to_py(py, &pts)))
    }

    /// Bookkeeping of instance `id`: dict(id, cls, closed, first_frame, last_frame, observations,
    /// n_points, drives).
    fn info<'py>(&self, py: Python<'py>, id: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyDict>> {
        let id = id_arg(id)?;
        let inst = py.detach(|| {
            let m = self.read()?;
            let inst = m.get(id).ok_or(geom::GeomError::UnknownId(id)).py_err()?;
            Ok::<_, PyErr>((
                inst.id,
                i64::from(inst.class.index()),
                inst.closed,
                inst.first_frame,
                inst.last_frame,
                inst.observations,
                inst.points.len(),
                m.drives(id).to_vec(),
            ))
        })?;
        let d = PyDict::new(py);
        d.set_item("id", inst.0)?;
        d.set_item("cls", inst.1)?;
        d.set_item("closed", inst.2)?;
        d.set_item("first_frame", inst.3)?;
        d.set_item("last_frame", inst.4)?;
        d.set_item("observations", inst.5)?;
        d.set_item("n_points", inst.6)?;
        d.set_item("drives", inst.7)?;
        Ok(d)
    }

    /// Records that drive `drive` (an int in 0..=2**32 - 1) observed every instance now in the map.
    #[pyo3(signature = (drive, ids = None))]
    fn tag_drive(
        &self,
        py: Python<'_>,
        drive: &Bound<'_, PyAny>,
        ids: Option<Vec<u64>>,
    ) -> PyResult<()> {
        let drive = drive_arg(drive)?;
        py.detach(|| {
            let mut map = self.write()?;
            match ids {
                None => {
                    map.tag_drive(drive);
                    Ok(())
                }
                Some(ids) => map.tag_drive_of(drive, &ids).py_err(),
            }
        })
    }

    /// Merges every instance of `other` into this map (see `icmap_geom::merge_map`): returns
    /// dict(merged, inserted, absorbed). `other` is unchanged; the GIL is released.
    #[pyo3(signature = (other, gate = 1.5, min_overlap = 0.5, tolerance = 3.0))]
    fn merge_map<'py>(
        &self,
        py: Python<'py>,
        other: &Bound<'py, PyGlobalMap>,
        gate: f64,
        min_overlap: f64,
        tolerance: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let params = MergeMapParams {
            gate,
            min_overlap,
            tolerance,
        };
        let other: &PyGlobalMap = other.get();
        let stats = py.detach(|| {
            if std::ptr::eq(self, other) {
                let snapshot = self.read()?.clone();
                return self.write()?.merge_map(&snapshot, params).py_err();
            }
            // The two locks are always taken in address order, so that `a.merge_map(b)` and
            // `b.merge_map(a)` in two threads cannot deadlock.
            if (self as *const Self) < (other as *const Self) {
                let mut mine = self.write()?;
                let theirs = other.read()?;
                mine.merge_map(&theirs, params).py_err()
            } else {
                let theirs = other.read()?;
                let mut mine = self.write()?;
                mine.merge_map(&theirs, params).py_err()
            }
        })?;
        let d = PyDict::new(py);
        d.set_item("merged", stats.merged)?;
        d.set_item("inserted", stats.inserted)?;
        d.set_item("absorbed", stats.absorbed)?;
        Ok(d)
    }

    /// Absorbs the duplicates around the instances `ids` (see `icmap_geom::absorb`): returns the
    /// `(absorbed, into)` pairs in order. Unknown ids are skipped; the GIL is released.
    #[pyo3(signature = (ids, gate = 1.0, min_overlap = 0.5, tolerance = 3.0))]
    fn absorb(
        &self,
        py: Python<'_>,
        ids: Vec<u64>,
        gate: f64,
        min_overlap: f64,
        tolerance: f64,
    ) -> PyResult<Vec<(u64, u64)>> {
        let params = MergeMapParams {
            gate,
            min_overlap,
            tolerance,
        };
        py.detach(|| self.write()?.absorb(&ids, params).py_err())
    }

    /// The native map file's contents (format 2; `compact`: coordinates on a 0.1 mm grid).
    #[pyo3(signature = (compact = false))]
    fn to_bytes<'py>(&self, py: Python<'py>, compact: bool) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = py.detach(|| {
            Ok::<_, PyErr>(geom::persist_v2::to_bytes(
                &*self.read()?,
                encoding_arg(compact),
            ))
        })?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// A map from the contents of a map file (bytes-like; format 1 or 2).
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: PyBackedBytes) -> PyResult<Self> {
        let map = py.detach(|| geom::persist_v2::from_bytes(&data)).py_err()?;
        Ok(PyGlobalMap {
            inner: RwLock::new(map),
        })
    }

    /// All ids, ascending, `(k,)` uint64.
    fn ids<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<u64>>> {
        let ids = py.detach(|| Ok::<_, PyErr>(self.read()?.ids()))?;
        Ok(vec_to_py(py, ids))
    }

    /// Ids (ascending, `(k,)` uint64) of the instances intersecting the patch of `pose`.
    #[pyo3(signature = (pose, half_extents, margin = 0.0))]
    fn query<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        half_extents: &Bound<'py, PyAny>,
        margin: f64,
    ) -> PyResult<Bound<'py, PyArray1<u64>>> {
        let pose = pose_arg(pose)?;
        let [hx, hy] = extents_arg(half_extents)?;
        let patch = Patch::new(pose, hx, hy, margin).py_err()?;
        let ids = py.detach(|| Ok::<_, PyErr>(self.read()?.query(&patch)))?;
        Ok(vec_to_py(py, ids))
    }

    /// Every instance in the (expanded) patch clipped and sampled to `n_points` in the ego frame:
    /// `(ids (k,) uint64, cls (k,) int64, pts (k, n_points, 2) float32, mask (k, n_points) bool)`.
    #[pyo3(signature = (pose, half_extents, margin = 20.0, n_points = 20))]
    #[allow(clippy::type_complexity)]
    fn sample_patch<'py>(
        &self,
        py: Python<'py>,
        pose: &Bound<'py, PyAny>,
        half_extents: &Bound<'py, PyAny>,
        margin: f64,
        #[pyo3(from_py_with = n_points_arg)] n_points: usize,
    ) -> PyResult<(
        Bound<'py, PyArray1<u64>>,
        Bound<'py, PyArray1<i64>>,
        Bound<'py, numpy::PyArray3<f32>>,
        Bound<'py, PyArray2<bool>>,
    )> {
        let pose = pose_arg(pose)?;
        let [hx, hy] = extents_arg(half_extents)?;
        let patch = Patch::new(pose, hx, hy, margin).py_err()?;
        let s = py.detach(|| self.read()?.sample_patch(&patch, n_points).py_err())?;
        let k = s.ids.len();
        let cls: Vec<i64> = s.classes.iter().map(|c| i64::from(c.index())).collect();
        let pts = points3_f32_to_py(py, &s.points, k, s.n_points)?;
        let mask = matrix_to_py(py, s.mask, k, s.n_points)?;
        Ok((vec_to_py(py, s.ids), vec_to_py(py, cls), pts, mask))
    }

    /// Writes the map file atomically (`str` or `os.PathLike`; format 2, `compact`: coordinates
    /// on a 0.1 mm grid).
    #[pyo3(signature = (path, compact = false))]
    fn save(&self, py: Python<'_>, path: PathBuf, compact: bool) -> PyResult<()> {
        py.detach(|| geom::persist_v2::save(&*self.read()?, &path, encoding_arg(compact)).py_err())
    }

    /// Reads a map file, format 1 or 2 (ValueError naming the file if it is not a valid map
    /// file, OSError if it cannot be read); with `bbox = (xmin, ymin, xmax, ymax)` only the
    /// instances whose bounding box meets it (a format-2 file is not read whole).
    #[staticmethod]
    #[pyo3(signature = (path, bbox = None))]
    fn load(py: Python<'_>, path: PathBuf, bbox: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let region = bbox.map(bbox_arg).transpose()?;
        let map = py
            .detach(|| match region {
                None => geom::persist_v2::load(&path),
                Some(r) => geom::persist_v2::load_region(&path, r),
            })
            .py_err()?;
        Ok(PyGlobalMap {
            inner: RwLock::new(map),
        })
    }

    /// Writes the map as a GeoJSON FeatureCollection (atomically).
    fn to_geojson(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| geom::geojson::write_geojson(&*self.read()?, &path).py_err())
    }
}
