"""The run folder: the on-disk output of one mapping run, version 1 (see docs/eval.md).

::

    RUN_DIR/run.json        {"format": "icmapper-run", "version": 1, "method", "source", "range",
                             "sequences": [{"name", "predictions", "global_map", "num_frames"}]}
    RUN_DIR/<name>.npz      per-frame predictions of one sequence (np.savez, no pickle)
    RUN_DIR/<name>.icmap    the predicted global map (native map file), optional

``<name>.npz`` arrays: frame_index (T,) int64, timestamps (T,) float64, poses (T, 4, 4) float64
ego->world, counts (T,) int64 (predictions per frame), classes (N,) int64, scores (N,) float64,
points (N, 20, 2) float32 ego frame, track_ids (N,) int64 (>= 0, unique within a frame); N =
sum(counts), rows in frame order. Every file is written atomically; run.json last, so a folder
without it is an incomplete run. Ground truth is not stored: it is recomputed from ``source``.
"""

from __future__ import annotations

import json
import os
import re
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import atomic_path

FORMAT_NAME = "icmapper-run"
FORMAT_VERSION = 1
NUM_POINTS = 20
_NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")
_ARRAYS = (
    "frame_index",
    "timestamps",
    "poses",
    "counts",
    "classes",
    "scores",
    "points",
    "track_ids",
)


class RunFormatError(ValueError):
    """A run folder that is missing, incomplete, corrupt or of an unknown version."""


@dataclass
class FramePredictions:
    """The predictions of one frame.

    frame_index: index of the frame in the source sequence; pose (4, 4) float64 ego->world;
    classes (k,) int64; scores (k,) float64; points (k, 20, 2) float32 ego frame;
    track_ids (k,) int64 (>= 0, unique within the frame).
    """

    frame_index: int
    pose: NDArray[np.float64]
    classes: NDArray[np.int64]
    scores: NDArray[np.float64]
    points: NDArray[np.float32]
    track_ids: NDArray[np.int64]
    timestamp: float = 0.0

    def __len__(self) -> int:
        return int(np.asarray(self.classes).shape[0])


@dataclass
class RunSequence:
    """The stored predictions of one sequence (arrays as in the module docstring)."""

    name: str
    frame_index: NDArray[np.int64]
    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]
    counts: NDArray[np.int64]
    classes: NDArray[np.int64]
    scores: NDArray[np.float64]
    points: NDArray[np.float32]
    track_ids: NDArray[np.int64]
    global_map_path: Path | None

    def __len__(self) -> int:
        return int(self.frame_index.shape[0])

    def frame(self, t: int) -> FramePredictions:
        """The t-th stored frame."""
        start = int(self.counts[:t].sum())
        sl = slice(start, start + int(self.counts[t]))
        return FramePredictions(
            int(self.frame_index[t]),
            self.poses[t],
            self.classes[sl],
            self.scores[sl],
            self.points[sl],
            self.track_ids[sl],
            float(self.timestamps[t]),
        )


@dataclass
class Run:
    """A read run folder."""

    path: Path
    method: str
    source: str
    range_name: str
    sequences: list[RunSequence]


def _atomic_write(path: Path, write: Any) -> None:
    """Calls write(tmp_path) then renames the temp file onto path (``icmapper.atomic``)."""
    with atomic_path(path) as tmp:
        write(tmp)


def _check_frame(fp: FramePredictions, where: str) -> FramePredictions:
    k = len(fp)
    pose = np.asarray(fp.pose, dtype=np.float64)
    classes = np.asarray(fp.classes)
    scores = np.asarray(fp.scores, dtype=np.float64)
    points = np.asarray(fp.points)
    tids = np.asarray(fp.track_ids)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise ValueError(f"{where}: pose must be a finite (4, 4) matrix, got shape {pose.shape}")
    if classes.shape != (k,) or scores.shape != (k,) or tids.shape != (k,):
        raise ValueError(f"{where}: classes, scores and track_ids must all have shape ({k},)")
    if points.shape != (k, NUM_POINTS, 2):
        raise ValueError(
            f"{where}: points must have shape ({k}, {NUM_POINTS}, 2), got {points.shape}"
        )
    if not (np.issubdtype(classes.dtype, np.integer) and np.issubdtype(tids.dtype, np.integer)):
        raise TypeError(f"{where}: classes and track_ids must be integers")
    if k and (classes.min() < 0 or classes.max() > 2):
        raise ValueError(f"{where}: classes must be in {{0, 1, 2}}")
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(scores))):
        raise ValueError(f"{where}: points or scores contain NaN or inf")
    if k and tids.min() < 0:
        raise ValueError(f"{where}: track_ids must be >= 0")
    if np.unique(tids).size != k:
        raise ValueError(f"{where}: track_ids must be unique within a frame")
    return FramePredictions(
        int(fp.frame_index), pose, classes.astype(np.int64), scores,
        points.astype(np.float32), tids.astype(np.int64), float(fp.timestamp),
    )  # fmt: skip


class RunWriter:
    """Writes a run folder: ``add_sequence`` per sequence, then ``close()`` writes run.json.

    Also a context manager (run.json is written on a clean exit only).
    """

    def __init__(self, run_dir: str | os.PathLike, method: str, source: str, rng: Any) -> None:
        """rng: a PerceptionRange (or its name, e.g. "60x30")."""
        self.path = Path(run_dir)
        self.path.mkdir(parents=True, exist_ok=True)
        if (self.path / "run.json").exists():
            raise FileExistsError(f"{self.path / 'run.json'} exists: refusing to overwrite a run")
        self.method, self.source = str(method), str(source)
        self.range_name = rng if isinstance(rng, str) else rng.name
        self._entries: list[dict[str, Any]] = []

    def add_sequence(
        self, name: str, frames: list[FramePredictions], global_map: Any | None = None
    ) -> None:
        """Writes <name>.npz (and <name>.icmap via global_map.save when given)."""
        if not _NAME_RE.match(name) or any(e["name"] == name for e in self._entries):
            raise ValueError(f"bad or duplicate sequence name {name!r} (use [A-Za-z0-9_.-])")
        checked = [_check_frame(f, f"sequence {name!r} frame {i}") for i, f in enumerate(frames)]
        k = [len(f) for f in checked]
        arrays = {
            "frame_index": np.array([f.frame_index for f in checked], dtype=np.int64),
            "timestamps": np.array([f.timestamp for f in checked], dtype=np.float64),
            "poses": np.stack([f.pose for f in checked]) if checked else np.zeros((0, 4, 4)),
            "counts": np.array(k, dtype=np.int64),
            "classes": np.concatenate([f.classes for f in checked] + [np.zeros(0, np.int64)]),
            "scores": np.concatenate([f.scores for f in checked] + [np.zeros(0)]),
            "points": np.concatenate(
                [f.points for f in checked] + [np.zeros((0, NUM_POINTS, 2), np.float32)]
            ),
            "track_ids": np.concatenate([f.track_ids for f in checked] + [np.zeros(0, np.int64)]),
        }
        pred_file = f"{name}.npz"

        def write_npz(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

        _atomic_write(self.path / pred_file, write_npz)
        map_file = None
        if global_map is not None:
            map_file = f"{name}.icmap"
            _atomic_write(self.path / map_file, lambda tmp: global_map.save(str(tmp)))
        self._entries.append(
            {"name": name, "predictions": pred_file, "global_map": map_file,
             "num_frames": len(checked)}
        )  # fmt: skip

    def close(self) -> None:
        """Writes run.json (the run is complete from then on)."""
        meta = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "method": self.method,
            "source": self.source,
            "range": self.range_name,
            "sequences": self._entries,
        }
        _atomic_write(
            self.path / "run.json", lambda tmp: tmp.write_text(json.dumps(meta, indent=1))
        )

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type: Any, *_: Any) -> None:
        if exc_type is None:
            self.close()


def _load_npz(path: Path, num_frames: int) -> dict[str, NDArray]:
    if not path.is_file():
        raise RunFormatError(f"{path}: missing predictions file")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [a for a in _ARRAYS if a not in z.files]
            if missing:
                raise RunFormatError(f"{path}: missing arrays {missing}")
            data = {a: z[a] for a in _ARRAYS}
    except RunFormatError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise RunFormatError(f"{path}: unreadable or truncated ({exc})") from None
    t = data["frame_index"].shape[0]
    n = int(data["counts"].sum()) if data["counts"].size else 0
    shapes = {
        "frame_index": (t,), "timestamps": (t,), "poses": (t, 4, 4), "counts": (t,),
        "classes": (n,), "scores": (n,), "points": (n, NUM_POINTS, 2), "track_ids": (n,),
    }  # fmt: skip
    for a, shape in shapes.items():
        if data[a].shape != shape:
            raise RunFormatError(f"{path}: array {a!r} has shape {data[a].shape}, expected {shape}")
    if t != num_frames:
        raise RunFormatError(f"{path}: {t} frames stored, run.json says {num_frames}")
    if data["counts"].size and data["counts"].min() < 0:
        raise RunFormatError(f"{path}: negative count")
    ints = ("frame_index", "counts", "classes", "track_ids")
    for a in ints:
        if not np.issubdtype(data[a].dtype, np.integer):
            raise RunFormatError(f"{path}: array {a!r} must be integer, got {data[a].dtype}")
    frame_of_row = np.repeat(np.arange(t), data["counts"])  # (N,)
    for a in ("poses", "timestamps"):
        bad = ~np.isfinite(data[a].reshape(t, -1)).all(axis=1)
        if bad.any():
            raise RunFormatError(f"{path}: frame {int(np.argmax(bad))}: {a} contain NaN or inf")
    checks = {
        "points contain NaN or inf": ~np.isfinite(data["points"]).all(axis=(1, 2)),
        "scores contain NaN or inf": ~np.isfinite(data["scores"]),
        "class outside {0, 1, 2}": (data["classes"] < 0) | (data["classes"] > 2),
        "negative track id": data["track_ids"] < 0,
    }
    for what, bad in checks.items():
        if bad.any():
            raise RunFormatError(f"{path}: frame {int(frame_of_row[np.argmax(bad)])}: {what}")
    key = frame_of_row * (int(data["track_ids"].max(initial=0)) + 1) + data["track_ids"]
    uniq, cnt = np.unique(key, return_counts=True)
    if (cnt > 1).any():
        f = int(frame_of_row[np.flatnonzero(key == uniq[np.argmax(cnt > 1)])[0]])
        raise RunFormatError(f"{path}: frame {f}: duplicate track id")
    for a in ints:
        data[a] = data[a].astype(np.int64)
    data["points"] = data["points"].astype(np.float32)
    return data


def read_run(run_dir: str | os.PathLike) -> Run:
    """Reads and validates a run folder; RunFormatError names the file (and frame) at fault."""
    path = Path(run_dir)
    meta_path = path / "run.json"
    if not meta_path.is_file():
        raise RunFormatError(f"{meta_path}: missing (not a run folder, or an incomplete run)")
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunFormatError(f"{meta_path}: unreadable or truncated ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise RunFormatError(f"{meta_path}: not an {FORMAT_NAME!r} file")
    if meta.get("version") != FORMAT_VERSION:
        raise RunFormatError(
            f"{meta_path}: unknown version {meta.get('version')!r} (this reader knows "
            f"{FORMAT_VERSION})"
        )
    try:
        method, source, range_name = str(meta["method"]), str(meta["source"]), str(meta["range"])
        entries = list(meta["sequences"])
        seqs = []
        for e in entries:
            name = str(e["name"])
            if not _NAME_RE.match(name) or not _NAME_RE.match(str(e["predictions"])):
                raise RunFormatError(f"{meta_path}: bad sequence entry {e!r}")
            data = _load_npz(path / str(e["predictions"]), int(e["num_frames"]))
            gm = e.get("global_map")
            gm_path = None
            if gm is not None:
                if not _NAME_RE.match(str(gm)):
                    raise RunFormatError(f"{meta_path}: bad global_map entry {gm!r}")
                gm_path = path / str(gm)
                if not gm_path.is_file():
                    raise RunFormatError(f"{gm_path}: missing global map file")
            seqs.append(RunSequence(name=name, global_map_path=gm_path, **data))
    except (KeyError, TypeError) as exc:
        raise RunFormatError(f"{meta_path}: malformed ({exc!r})") from None
    return Run(path, method, source, range_name, seqs)
