"""StreamMapNet's and MapTracker's submission file ``submission_vector.json``.

As ``BaseMapDataset.format_results`` writes it (yuantianyuan01/StreamMapNet at 4c7aaf4,
``plugin/datasets/base_dataset.py``; woodfrog/maptracker at ee8321f, same file)::

    {"meta": {"use_lidar": false, "use_camera": true, ..., "output_format": "vector"},
     "results": {TOKEN: {"vectors": [[[x, y], ...], ...],   # ego frame, metres (denormalised)
                         "scores": [float, ...],
                         "labels": [int, ...],             # cat2id: 0 ped_crossing, 1 divider,
                                                           # 2 boundary
                         "prop"/"props": [bool, ...],      # ignored
                         "track_vectors", "track_scores", "track_labels": ...}}}  # MapTracker;
                                                           # ignored
TOKEN: the nuScenes sample token, or the Argoverse 2 lidar timestamp in nanoseconds as a string
(both repositories' converters). Every vector has 20 points; crossings are closed rings, their
20th point repeating the first (``closed_ring``). The file has
no poses, no track ids and no query features; its range is not recorded (60x30 unless
``file:PATH:streammapnet:100x50``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from icmapper.formats.jsonio import field, write_json_atomic
from icmapper.formats.registry import PredictionFormat, register_format
from icmapper.formats.types import (
    PredictedFrame,
    PredictionFileError,
    PredictionSet,
    frame_arrays,
    instance_points,
    ring_without_points,
)

NAME = "streammapnet"
#: The ``meta`` StreamMapNet's and MapTracker's configs write (camera-only, vector output).
META = {
    "use_lidar": False,
    "use_camera": True,
    "use_radar": False,
    "use_map": False,
    "use_external": False,
    "output_format": "vector",
}


def sniff(data: Any) -> bool:
    return isinstance(data, dict) and isinstance(data.get("results"), dict) and "format" not in data


def _frame(token: str, raw: Any, path: str) -> PredictedFrame:
    where = f"{path}: token {token!r}"
    vectors = field(raw, "vectors", list, where)
    scores = field(raw, "scores", list, where)
    labels = field(raw, "labels", list, where)
    if not len(vectors) == len(scores) == len(labels):
        raise PredictionFileError(
            f"{where}: {len(vectors)} vectors, {len(scores)} scores and {len(labels)} labels"
        )
    classes, pts = [], []
    for j, (v, lab) in enumerate(zip(vectors, labels, strict=True)):
        w = f"{where}, instance {j}"
        if isinstance(lab, bool) or not isinstance(lab, int) or not 0 <= lab <= 2:
            raise PredictionFileError(
                f"{w}: label {lab!r} is not one of 0 ped_crossing, 1 divider, 2 boundary"
            )
        classes.append(lab)
        pts.append(instance_points(v, lab, w))
    if not all(isinstance(s, int | float) and not isinstance(s, bool) for s in scores):
        raise PredictionFileError(f"{where}: scores must be numbers")
    cls, sc, p = frame_arrays(classes, [float(s) for s in scores], pts, where)
    return PredictedFrame(token, None, None, cls, sc, p)


def read(path: str, data: Any, range_name: str | None) -> PredictionSet:
    meta = data.get("meta", {})
    if isinstance(meta, dict) and meta.get("output_format", "vector") != "vector":
        raise PredictionFileError(
            f"{path}: output_format {meta.get('output_format')!r}; only vector submissions hold "
            "map instances"
        )
    results = field(data, "results", dict, path)
    frames = [_frame(str(tok), raw, path) for tok, raw in results.items()]
    return PredictionSet(NAME, path, frames, range_name or "60x30", "ego", {"meta": meta})


def closed_ring(points: np.ndarray) -> np.ndarray:
    """A crossing ring (n, 2) -> (n, 2) as StreamMapNet's own results hold it: n - 1 points of
    the ring, then the first point again (they sample a polygon with ``np.linspace(0, length,
    n)`` along its closed exterior, so the last sample is the first). The point that shapes the
    ring least is left out (``ring_without_points``); reading the file back keeps the n - 1 and
    inserts one on the longest edge (``instance_points``), so the shape survives the trip."""
    ring = ring_without_points(points, points.shape[0] - 1)  # (n - 1, 2)
    return np.concatenate([ring, ring[:1]])  # (n, 2)


def write(path: Path, preds: PredictionSet) -> None:
    """Writes ``preds`` as a submission file: one entry per frame token (every frame needs one);
    every vector has 20 points, crossings as closed rings whose last point repeats the first
    (``closed_ring``)."""
    results: dict[str, Any] = {}
    for f in preds.frames:
        if f.token is None:
            raise ValueError(f"{f.name()}: the streammapnet format names frames by token")
        if f.token in results:
            raise ValueError(f"{f.name()}: token {f.token!r} appears twice")
        vecs = [
            (closed_ring(f.points[j]) if f.classes[j] == 0 else f.points[j].astype(np.float64))
            for j in range(len(f))
        ]
        results[f.token] = {
            "vectors": [v.tolist() for v in vecs],
            "scores": [float(s) for s in f.scores],
            "labels": [int(c) for c in f.classes],
        }
    write_json_atomic(path, {"meta": dict(META), "results": results})


register_format(
    PredictionFormat(
        NAME,
        "StreamMapNet / MapTracker submission_vector.json (results by token; no poses, no ids)",
        read=read,
        sniff=sniff,
        write=write,
    )
)
