"""Every function of the geometry engine that takes an (n, 2) point array, as one table of calls
with the other arguments filled in: what the input-contract and hardening tests feed bad points
through. An entry point added to the engine is added here once and every such test covers it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from icmapper import GlobalMap, geom

#: The pose (x, y, yaw) of the patch the clipping calls use.
POSE = (1.0, 2.0, 0.3)


def point_entry_points(line: Any, ring: Any) -> dict[str, Callable[[Any], Any]]:
    """Name -> call(points): each engine function with ``points`` in one argument and the rest
    filled from ``line`` (a good open polyline (m, 2)) and ``ring`` (a good crossing ring (k, 2)).
    The map calls act on a fresh map holding ``line`` (id 0, a divider) and ``ring`` (id 1)."""

    def a_map() -> GlobalMap:
        m = GlobalMap()
        m.insert(1, line)
        m.insert(0, ring)
        return m

    return {
        "resample": lambda p: geom.resample(p, 10),
        "resample_closed": lambda p: geom.resample(p, 10, closed=True),
        "resample_spacing": lambda p: geom.resample_spacing(p, 1.0),
        "clip_to_patch": lambda p: geom.clip_to_patch(p, POSE, (5, 5)),
        "clip_to_patch_closed": lambda p: geom.clip_to_patch(p, POSE, (5, 5), closed=True),
        "fit_curve": lambda p: geom.fit_curve(p),
        "merge_polyline_global": lambda p: geom.merge_polyline(p, line),
        "merge_polyline_detected": lambda p: geom.merge_polyline(line, p),
        "polygon_union_one": lambda p: geom.polygon_union([p]),
        "polygon_union_two": lambda p: geom.polygon_union([ring, p]),
        "polygon_union_three": lambda p: geom.polygon_union([ring, p, ring + 1.0]),
        "chamfer_distance": lambda p: geom.chamfer_distance(line, p),
        "chamfer_matrix": lambda p: geom.chamfer_matrix([line], [p]),
        "insert_divider": lambda p: a_map().insert(1, p),
        "insert_crossing": lambda p: a_map().insert(0, p),
        "insert_with_id": lambda p: a_map().insert_with_id(9, 2, p),
        "merge_divider": lambda p: a_map().merge(0, p),
        "merge_crossing": lambda p: a_map().merge(1, p),
        "replace": lambda p: a_map().replace(0, p),
        "splice_polyline_stored": lambda p: geom.splice_polyline(p, line, 0.5),
        "splice_polyline_new": lambda p: geom.splice_polyline(line, p, 0.5),
        "splice": lambda p: a_map().splice(0, p, 0.5),
    }
