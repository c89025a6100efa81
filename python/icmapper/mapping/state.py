"""Saving and resuming a ``Mapper`` mid-sequence.

``save_state(mapper, path)`` writes the native global map file ``path`` and the sidecar
``<path>.state.npz`` (plain numpy arrays, no pickle, format ``STATE_VERSION``): the tracking buffer
(ids, classes, world points, queries, ages, hits), the next track id, the track aliases, the
crossing rule's complete-view counts (``mapping.crossings``), the pose of the last merge
(``MapperConfig.min_travel``), the untracked id counter, the stats, the SHA-256 of the map file
(ties the pair together) and the detection source's memory when it has one (``state_dict()``,
e.g. ``NetworkDetector``). Both files are written atomically.

``resume(mapper, path)`` restores all of it, so the continuation is identical to the
uninterrupted run; without a sidecar it loads the map only (see ``resume``).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from icmapper.mapping.stats import STAGES, MapperStats
from icmapper.mapping.tracker import Track

if TYPE_CHECKING:  # the mapper imports this module; it is the one edge between them
    from icmapper.mapping.mapper import Mapper

#: Format version of the sidecar (``<map>.state.npz``).
STATE_VERSION = 4  # 2: the crossing rule's view counts; 3: the absorbed counter; 4: the pose
# of the last merge (``min_travel``) and the split / stubs / still counters
#: Integer counters of ``MapperStats`` stored in the sidecar, in order.
STAT_COUNTS = (
    "frames", "inserted", "merged", "reidentified", "aliased", "split", "absorbed", "stubs",
    "still", "merge_failures"
)  # fmt: skip
#: Arrays every sidecar holds (besides ``source.*``, the detection source's state).
_STATE_KEYS = (
    "version", "map_sha256", "source_kind", "next_id", "untracked", "stats_counts",
    "stats_seconds", "stats_failures", "alias", "crossing_counts", "merge_pose", "track_ids",
    "track_cls", "track_age", "track_hits", "track_counts", "track_points", "track_has_query",
    "track_queries",
)  # fmt: skip


def state_path(map_path: str | Path) -> Path:
    """The sidecar of a saved map: ``<map_path>.state.npz``."""
    p = Path(map_path)
    return p.with_name(p.name + ".state.npz")


def save_state(mapper: Mapper, path: str | Path) -> None:
    """Saves everything the mapper's next step depends on (see the module docstring)."""
    path = Path(path)
    sidecar = state_path(path)
    arrays = _state_arrays(mapper)
    mapper.global_map.save(path)
    arrays["map_sha256"] = np.array(_sha256(path))
    fd, tmp = tempfile.mkstemp(prefix=sidecar.name + ".", suffix=".tmp", dir=sidecar.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, sidecar)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def resume(mapper: Mapper, path: str | Path) -> None:
    """Continues a saved run on ``mapper``.

    With the sidecar of ``save_state``: restores the map, the tracking buffer, the aliases, the
    counters, the stats and the detector memory, so the continuation is identical to the
    uninterrupted run (the mapper must be built with the same source, networks and config).
    Without a sidecar (a map saved with ``global_map.save``): loads the map only, clears the
    buffer and the detector memory and starts new ids above the map's largest id. A bad map file
    or sidecar raises ValueError naming the file; nothing changes then.
    """
    from icmapper._icmap import GlobalMap

    path = Path(path)
    sidecar = state_path(path)
    if not sidecar.exists():
        gmap = GlobalMap.load(str(path))
        mapper.source.reset()
        mapper.tracker.reset()
        ids = gmap.ids()
        mapper.tracker.reserve_ids(int(ids.max()) + 1 if len(ids) else 0)
        mapper.restore(gmap, alias={})
        return
    state = _read_state(sidecar)
    try:
        tracks, restore = _parse_state(mapper, state, path)
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"mapper state {sidecar}: {exc}") from None
    gmap = GlobalMap.load(str(path))
    src_state = {k[7:]: v for k, v in state.items() if k.startswith("source.")}
    source: Any = mapper.source
    if hasattr(source, "load_state_dict"):
        old = source.state_dict() if hasattr(source, "state_dict") else None
        try:
            source.load_state_dict(src_state)
        except (ValueError, KeyError, TypeError) as exc:
            if old is not None:
                source.load_state_dict(old)
            raise ValueError(f"mapper state {sidecar}: {exc}") from None
    else:
        source.reset()
    mapper.tracker.restore(tracks, restore["next_id"])
    mapper.restore(
        gmap,
        alias=restore["alias"],
        untracked=restore["untracked"],
        stats=restore["stats"],
        crossing_counts=restore["crossing_counts"],
        merge_pose=restore["merge_pose"],
    )


def _state_arrays(mapper: Mapper) -> dict[str, NDArray[Any]]:
    """The sidecar's arrays (all but ``map_sha256``)."""
    tracks = mapper.tracker.tracks
    counts = np.array([len(t.points) for t in tracks], np.int64)  # (t,)
    pts = [np.asarray(t.points, np.float64).reshape(-1, 2) for t in tracks]
    has_q = np.array([t.query is not None for t in tracks], bool)  # (t,)
    dims = {int(np.asarray(t.query).shape[0]) for t in tracks if t.query is not None}
    if len(dims) > 1:
        raise ValueError(f"save_state: tracks have queries of different sizes {sorted(dims)}")
    dim = dims.pop() if dims else 0
    queries = np.zeros((len(tracks), dim), np.float32)  # (t, D)
    for i, t in enumerate(tracks):
        if t.query is not None:
            queries[i] = t.query
    st = mapper.stats
    arrays: dict[str, NDArray[Any]] = {
        "version": np.array(STATE_VERSION, np.int64),
        "source_kind": np.array(type(mapper.source).__name__),
        "next_id": np.array(mapper.tracker.next_id, np.int64),
        "untracked": np.array(mapper.untracked_next, np.int64),
        "stats_counts": np.array([getattr(st, n) for n in STAT_COUNTS], np.int64),
        "stats_seconds": np.array([st.seconds.get(n, 0.0) for n in STAGES], np.float64),
        "stats_failures": np.array(st.failures, dtype=str).reshape(-1),
        "alias": np.array(sorted(mapper.alias.items()), np.int64).reshape(-1, 2),  # (a, 2)
        "crossing_counts": np.array(sorted(mapper.crossings.counts.items()), np.int64).reshape(
            -1, 2
        ),  # (c, 2): instance id, complete views
        "merge_pose": np.array(mapper.merge_pose or (), np.float64),  # (3,) x, y, yaw or (0,)
        "track_ids": np.array([t.id for t in tracks], np.int64),  # (t,)
        "track_cls": np.array([t.cls for t in tracks], np.int64),
        "track_age": np.array([t.age for t in tracks], np.int64),
        "track_hits": np.array([t.hits for t in tracks], np.int64),
        "track_counts": counts,
        "track_points": np.concatenate(pts) if pts else np.zeros((0, 2)),  # (sum n, 2)
        "track_has_query": has_q,
        "track_queries": queries,
    }
    source: Any = mapper.source
    if hasattr(source, "state_dict"):
        for key, val in source.state_dict().items():
            arrays["source." + key] = np.asarray(val)
    return arrays


def _parse_state(
    mapper: Mapper, z: dict[str, NDArray[Any]], map_path: Path
) -> tuple[list[Track], dict[str, Any]]:
    """Validates the sidecar arrays and builds the tracker buffer and counters from them."""
    # (_read_state refused another scalar version already; here a malformed one is refused)
    version = int(_int_array(z, "version", ndim=0))
    if version != STATE_VERSION:
        raise ValueError(f"format version {version}, this build reads {STATE_VERSION}")
    if str(z["map_sha256"]) != _sha256(map_path):
        raise ValueError(f"it was not saved with the map file {map_path} (checksum differs)")
    kind = str(z["source_kind"])
    if kind != type(mapper.source).__name__:
        raise ValueError(
            f"saved with a {kind} source, this mapper has a {type(mapper.source).__name__}"
        )
    has_src = any(k.startswith("source.") for k in z)
    if has_src != hasattr(mapper.source, "load_state_dict"):
        raise ValueError("the detection source state does not fit this mapper's source")
    ids, cls = _int_array(z, "track_ids"), _int_array(z, "track_cls")
    age, hits = _int_array(z, "track_age"), _int_array(z, "track_hits")
    counts = _int_array(z, "track_counts")
    t = len(ids)
    has_q = z["track_has_query"]
    queries, pts = z["track_queries"], z["track_points"]
    for name, arr in (("track_cls", cls), ("track_age", age), ("track_hits", hits),
                      ("track_counts", counts), ("track_has_query", has_q)):  # fmt: skip
        if arr.shape != (t,):
            raise ValueError(f"{name} has shape {arr.shape}, expected ({t},)")
    if has_q.dtype != bool or queries.ndim != 2 or queries.shape[0] != t:
        raise ValueError(f"track_queries {queries.shape} / has_query do not fit {t} tracks")
    if queries.dtype != np.float32 or not np.all(np.isfinite(queries)):
        raise ValueError("track_queries must be finite float32")
    if pts.dtype != np.float64 or pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"track_points must be (n, 2) float64, got {pts.shape} {pts.dtype}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("track_points contain NaN or inf")
    if np.any(counts < 1) or int(counts.sum()) != len(pts):
        raise ValueError(f"track_counts (sum {int(counts.sum())}) do not fit {len(pts)} points")
    if len(set(ids.tolist())) != t or np.any(age < 0) or np.any(hits < 1):
        raise ValueError("duplicate track ids, negative ages or hits < 1")
    offsets = np.concatenate([[0], np.cumsum(counts)])
    tracks = [
        Track(
            int(ids[i]),
            int(cls[i]),
            pts[offsets[i] : offsets[i + 1]].copy(),  # (n, 2) world
            queries[i].copy() if has_q[i] else None,  # (D,)
            int(age[i]),
            int(hits[i]),
        )
        for i in range(t)
    ]
    alias = _int_array(z, "alias", ndim=2)
    if alias.shape[1:] != (2,):
        raise ValueError(f"alias must be (a, 2), got {alias.shape}")
    crossing = _int_array(z, "crossing_counts", ndim=2)
    if crossing.shape[1:] != (2,) or np.any(crossing < 0):
        raise ValueError(f"crossing_counts must be (c, 2) and >= 0, got {crossing.shape}")
    merge_pose = z["merge_pose"]
    if merge_pose.dtype != np.float64 or merge_pose.shape not in ((0,), (3,)):
        raise ValueError(f"merge_pose must be (3,) or (0,) float64, got {merge_pose.shape}")
    if not np.all(np.isfinite(merge_pose)):
        raise ValueError("merge_pose contains NaN or inf")
    counts_s = _int_array(z, "stats_counts")
    seconds = z["stats_seconds"]
    if counts_s.shape != (len(STAT_COUNTS),) or seconds.shape != (len(STAGES),):
        raise ValueError(f"stats arrays have shapes {counts_s.shape}, {seconds.shape}")
    failures = z["stats_failures"]
    if failures.ndim != 1 or failures.dtype.kind != "U":
        raise ValueError("stats_failures must be a 1-d string array")
    stats: MapperStats = MapperStats(
        seconds={n: float(v) for n, v in zip(STAGES, seconds, strict=True)},
        failures=[str(f) for f in failures],
        **{n: int(v) for n, v in zip(STAT_COUNTS, counts_s, strict=True)},
    )
    restore = {
        "next_id": int(_int_array(z, "next_id", ndim=0)),
        "untracked": int(_int_array(z, "untracked", ndim=0)),
        "alias": {int(a): int(b) for a, b in alias},
        "crossing_counts": {int(a): int(b) for a, b in crossing},
        "merge_pose": tuple(float(v) for v in merge_pose) if len(merge_pose) else None,
        "stats": stats,
    }
    return tracks, restore


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _read_state(sidecar: Path) -> dict[str, NDArray[Any]]:
    """All arrays of a sidecar (ValueError naming the file if it is not a readable npz)."""
    try:
        with np.load(sidecar, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError) as exc:
        raise ValueError(f"mapper state {sidecar} is not a valid state file: {exc}") from None
    version = out.get("version")
    if version is not None and version.shape == () and int(version) != STATE_VERSION:
        raise ValueError(
            f"mapper state {sidecar}: format version {int(version)}, this build reads "
            f"{STATE_VERSION} (map again from the start, or load the map alone without its sidecar)"
        )
    missing = set(_STATE_KEYS) - set(out)
    if missing:
        raise ValueError(f"mapper state {sidecar}: missing arrays {sorted(missing)}")
    return out


def _int_array(z: dict[str, NDArray[Any]], key: str, ndim: int = 1) -> NDArray[np.int64]:
    arr = z[key]
    if arr.dtype != np.int64 or arr.ndim != ndim:
        raise ValueError(f"{key} must be a {ndim}-d int64 array, got {arr.shape} {arr.dtype}")
    return arr
