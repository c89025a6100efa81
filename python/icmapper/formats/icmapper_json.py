"""icmapper's own prediction file, version 1 (JSON; docs/eval.md, "Prediction files").

::

    {"format": "icmapper-predictions", "version": 1,
     "range": "60x30",                        # perception range of the predictions
     "method": str, "source": spec,           # optional, informative
     "frames": [
       {"sequence": name,                     # optional: the source sequence's name
        "token": str, "timestamp": seconds,   # at least one of the two names the frame
        "pose": [[4 x 4]],                    # optional: ego->world; checked against the source
        "instances": [
          {"class": "ped_crossing" | "divider" | "boundary",
           "score": float,
           "points": [[x, y], ...],           # ego frame (x forward, y left), metres; crossings
                                              # as rings (a repeated first point is dropped)
           "track_id": int >= 0,              # optional (all instances of a frame or none)
           "query": [float, ...]}]}]}         # optional query feature (all instances or none)

Floats are written with Python's shortest round-trip repr, so float32 points and queries read
back bit for bit.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from icmapper.data.types import CLASS_NAMES, PerceptionRange
from icmapper.formats.jsonio import field, write_json_atomic
from icmapper.formats.registry import PredictionFormat, register_format
from icmapper.formats.types import (
    PredictedFrame,
    PredictionFileError,
    PredictionSet,
    class_index,
    frame_arrays,
    frame_name,
    instance_points,
)

FORMAT_NAME = "icmapper-predictions"
FORMAT_VERSION = 1
NAME = "icmapper"


def sniff(data: Any) -> bool:
    return isinstance(data, dict) and data.get("format") == FORMAT_NAME


def _optional_ids(inst: list[dict], key: str, where: str) -> list[Any] | None:
    have = [key in d for d in inst]
    if not any(have):
        return None
    if not all(have):
        raise PredictionFileError(f"{where}: {key!r} given for some instances but not all")
    return [d[key] for d in inst]


def _frame(raw: Any, t: int, path: str) -> PredictedFrame:
    where = f"{path}: frame {t}"
    if not isinstance(raw, dict):
        raise PredictionFileError(f"{where}: expected a JSON object")
    seq = field(raw, "sequence", str, where) if "sequence" in raw else None
    token = field(raw, "token", str, where) if "token" in raw else None
    ts = float(field(raw, "timestamp", (int, float), where)) if "timestamp" in raw else None
    if token is None and ts is None:
        raise PredictionFileError(f"{where}: a frame needs a 'token' or a 'timestamp'")
    if ts is not None and not np.isfinite(ts):
        raise PredictionFileError(f"{where}: timestamp is not finite")
    where = f"{path}: frame {t} ({frame_name(seq, token, ts)})"
    pose = None
    if "pose" in raw:
        try:
            pose = np.asarray(raw["pose"], dtype=np.float64)
        except (TypeError, ValueError):
            raise PredictionFileError(f"{where}: pose is not a 4 x 4 matrix of numbers") from None
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
            raise PredictionFileError(f"{where}: pose must be a finite 4 x 4 matrix")
    inst = field(raw, "instances", list, where)
    classes, scores, points = [], [], []
    for j, d in enumerate(inst):
        w = f"{where}, instance {j}"
        c = class_index(field(d, "class", str, w), w)
        classes.append(c)
        scores.append(float(field(d, "score", (int, float), w)))
        points.append(instance_points(field(d, "points", list, w), c, w))
    cls, sc, pts = frame_arrays(classes, scores, points, where)
    tids = _optional_ids(inst, "track_id", where)
    track_ids = None
    if tids is not None:
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in tids):
            raise PredictionFileError(f"{where}: track ids must be integers >= 0")
        track_ids = np.asarray(tids, dtype=np.int64)
        if np.unique(track_ids).size != track_ids.size:
            raise PredictionFileError(f"{where}: track ids must be unique within a frame")
    qs = _optional_ids(inst, "query", where)
    queries = None
    if qs is not None:
        try:
            queries = np.asarray(qs, dtype=np.float32)
        except (TypeError, ValueError):
            raise PredictionFileError(f"{where}: queries must be lists of equal length") from None
        if queries.ndim != 2 or not np.all(np.isfinite(queries)):
            raise PredictionFileError(f"{where}: queries must be finite lists of equal length")
    return PredictedFrame(token, ts, seq, cls, sc, pts, pose, track_ids, queries)


def read(path: str, data: Any, range_name: str | None) -> PredictionSet:
    version = data.get("version")
    if version != FORMAT_VERSION:
        raise PredictionFileError(
            f"{path}: unknown {FORMAT_NAME} version {version!r} (this reader knows "
            f"{FORMAT_VERSION})"
        )
    file_range = str(data.get("range", "60x30"))
    try:
        PerceptionRange.from_name(file_range)
    except ValueError as exc:
        raise PredictionFileError(f"{path}: {exc}") from None
    if range_name is not None and range_name != file_range:
        raise PredictionFileError(
            f"{path}: the file's predictions are at range {file_range}, not {range_name}"
        )
    frames = [_frame(f, t, path) for t, f in enumerate(field(data, "frames", list, path))]
    dims = {f.queries.shape[1] for f in frames if f.queries is not None}
    if len(dims) > 1:
        raise PredictionFileError(f"{path}: query features of different sizes {sorted(dims)}")
    meta = {k: v for k, v in data.items() if k != "frames"}
    return PredictionSet(NAME, path, frames, file_range, "ego", meta)


def _instance(f: PredictedFrame, j: int) -> dict[str, Any]:
    d: dict[str, Any] = {
        "class": CLASS_NAMES[int(f.classes[j])],
        "score": float(f.scores[j]),
        "points": np.asarray(f.points[j], dtype=np.float64).tolist(),
    }
    if f.track_ids is not None:
        d["track_id"] = int(f.track_ids[j])
    if f.queries is not None:
        d["query"] = np.asarray(f.queries[j], dtype=np.float64).tolist()
    return d


def write(path: Path, preds: PredictionSet) -> None:
    """Writes ``preds`` as an icmapper prediction file (atomically)."""
    frames = []
    for f in preds.frames:
        d: dict[str, Any] = {}
        if f.sequence is not None:
            d["sequence"] = f.sequence
        if f.token is not None:
            d["token"] = f.token
        if f.timestamp is not None:
            d["timestamp"] = float(f.timestamp)
        if f.pose is not None:
            d["pose"] = np.asarray(f.pose, dtype=np.float64).tolist()
        d["instances"] = [_instance(f, j) for j in range(len(f))]
        frames.append(d)
    meta = {k: v for k, v in preds.meta.items() if k in ("method", "source")}
    out = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "range": preds.range_name, **meta}
    out["frames"] = frames
    write_json_atomic(path, out)


register_format(
    PredictionFormat(
        NAME,
        "icmapper's own JSON (docs/eval.md): tokens or timestamps, poses, track ids, queries",
        read=read,
        sniff=sniff,
        write=write,
    )
)
