"""MapTR's and MapTRv2's result file ``nuscmap_results.json``.

As ``CustomNuScenesLocalMapDataset._format_bbox`` writes it (hustvl/MapTR, branch maptrv2 at
e03f097, ``projects/mmdet3d_plugin/datasets/nuscenes_map_dataset.py``; the Argoverse 2 dataset
class writes the same layout)::

    {"meta": {modality},
     "results": [{"sample_token": TOKEN,
                  "vectors": [{"pts": [[x, y], ...], "pts_num": n,
                               "cls_name": "divider" | "ped_crossing" | "boundary"
                                           | "centerline",
                               "type": int,                 # MapTR's own label order
                               "confidence_level": float}, ...]}, ...]}

MapTR's class order (``map_classes = ['divider', 'ped_crossing', 'boundary']``) is not icmapper's:
classes are read from ``cls_name``. ``centerline`` (MapTRv2's optional fourth class) is not a class
icmapper maps: such instances are left out. Points: on nuScenes, MapTR builds its local map around
``lidar2global`` (``vectorize_local_map``), so points are in the LIDAR_TOP frame (x right,
y forward) and are converted with the scene's LIDAR_TOP calibration; on Argoverse 2 the lidar frame
is the ego frame (their comment: "av2 lidar2global the same as ego2global"); on synthetic sources
points are taken as ego-frame points. TOKEN as in the StreamMapNet format.
"""

from __future__ import annotations

from typing import Any

from icmapper.formats.jsonio import field
from icmapper.formats.registry import PredictionFormat, register_format
from icmapper.formats.types import (
    PredictedFrame,
    PredictionFileError,
    PredictionSet,
    class_index,
    frame_arrays,
    instance_points,
)

NAME = "maptr"
#: MapTRv2 classes icmapper does not map (left out when reading).
IGNORED_CLASSES = ("centerline",)


def sniff(data: Any) -> bool:
    res = data.get("results") if isinstance(data, dict) else None
    return (
        isinstance(res, list)
        and "format" not in data
        and all(isinstance(r, dict) and "sample_token" in r for r in res[:5])
    )


def _frame(raw: Any, t: int, path: str) -> PredictedFrame:
    token = str(field(raw, "sample_token", str, f"{path}: result {t}"))
    where = f"{path}: token {token!r}"
    classes, scores, pts = [], [], []
    for j, v in enumerate(field(raw, "vectors", list, where)):
        w = f"{where}, vector {j}"
        name = field(v, "cls_name", str, w)
        if name in IGNORED_CLASSES:
            continue
        c = class_index(name, w)
        raw_pts = field(v, "pts", list, w)
        n = v.get("pts_num", len(raw_pts))
        if isinstance(n, bool) or not isinstance(n, int) or not 2 <= n <= len(raw_pts):
            raise PredictionFileError(f"{w}: pts_num {n!r} does not fit {len(raw_pts)} points")
        classes.append(c)
        scores.append(field(v, "confidence_level", (int, float), w))
        pts.append(instance_points(raw_pts[:n], c, w))
    cls, sc, p = frame_arrays(classes, scores, pts, where)
    return PredictedFrame(token, None, None, cls, sc, p)


def read(path: str, data: Any, range_name: str | None) -> PredictionSet:
    frames = [_frame(r, t, path) for t, r in enumerate(field(data, "results", list, path))]
    seen: set[str] = set()
    for f in frames:
        if f.token in seen:
            raise PredictionFileError(f"{path}: token {f.token!r} appears twice")
        seen.add(str(f.token))
    meta = data.get("meta", {})
    return PredictionSet(NAME, path, frames, range_name or "60x30", "lidar", {"meta": meta})


register_format(
    PredictionFormat(
        NAME,
        "MapTR / MapTRv2 nuscmap_results.json (by sample token; nuScenes points in the lidar "
        "frame)",
        read=read,
        sniff=sniff,
    )
)
