"""Map NMS: a clean-up of a finished global map, offered to every method alike.

With ``MapperConfig.map_nms`` the map a method returns at the end of a sequence is cleaned before
it is written and evaluated, in two steps:

1. duplicates: every instance that lies on a same-class neighbour over most of its length becomes
   part of it (``absorb.absorb_pairs`` over every instance, with the ``absorb_*`` settings), as
   GlobalMapNet's map NMS keeps one of overlapping global instances;
2. stubs across lanes: a divider shorter than ``stub_length`` that crosses a longer divider at more
   than ``stub_angle`` degrees is removed (lane lines do not cross each other; such stubs are
   skeleton pieces where the detector blurs neighbouring lines together).

It works on the finished map only, so per-frame predictions (AP, tracking) do not change.
IC-Mapper absorbs online as part of its own merge rule (``MapperConfig.absorb``); this setting is
the generic form, so that a comparison can give every method the same clean-up and report with
and without it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.mapping.config import MapperConfig

#: Class index of dividers (the class whose instances never cross each other).
DIVIDER = 1


def map_nms(global_map: GlobalMap, config: MapperConfig) -> int:
    """Cleans the whole map in place (module docstring); returns how many instances went."""
    from icmapper.mapping.absorb import absorb_pairs

    pairs = absorb_pairs(global_map, [int(i) for i in global_map.ids()], config)
    stubs = stubs_across(global_map, config.stub_length, config.stub_angle)
    for i in stubs:
        global_map.remove(i)
    return len(pairs) + len(stubs)


def _tangent(line: object, point: object) -> NDArray[np.float64]:
    """The unit direction (2,) of shapely ``line`` at ``point`` (over +-1 m)."""
    d = line.project(point)  # type: ignore[attr-defined]
    a = np.asarray(line.interpolate(max(d - 1.0, 0.0)).coords[0])  # type: ignore[attr-defined]
    b = np.asarray(line.interpolate(min(d + 1.0, line.length)).coords[0])  # type: ignore[attr-defined]
    t = b - a  # (2,)
    return t / max(float(np.linalg.norm(t)), 1e-12)


def crosses_longer(line: object, others: list[object], angle: float) -> bool:
    """Whether shapely ``line`` crosses one of the longer shapely lines ``others`` at more than
    ``angle`` degrees (lane lines do not cross each other)."""
    for other in others:
        if other.length <= line.length or not line.crosses(other):  # type: ignore[attr-defined]
            continue
        at = line.intersection(other).representative_point()  # type: ignore[attr-defined]
        cos = abs(float(_tangent(line, at) @ _tangent(other, at)))
        if np.degrees(np.arccos(min(cos, 1.0))) > angle:
            return True
    return False


def stubs_across(global_map: GlobalMap, max_length: float, angle: float) -> list[int]:
    """Ids of the dividers shorter than ``max_length`` metres that cross a longer divider at more
    than ``angle`` degrees (ascending; none when ``max_length`` is 0)."""
    from shapely.geometry import LineString

    if max_length <= 0:
        return []
    lines = {}
    for i in global_map.ids().tolist():
        cls, pts = global_map.get(int(i))
        if cls == DIVIDER:
            lines[int(i)] = LineString(np.asarray(pts))
    return sorted(
        a
        for a, la in lines.items()
        if la.length < max_length
        and crosses_longer(la, [lb for b, lb in lines.items() if b != a], angle)
    )


def _dividers_near(
    global_map: GlobalMap, points: NDArray[np.float64], skip: int = -1
) -> dict[int, object]:
    """The stored dividers (id -> shapely line) whose geometry meets the box of ``points`` (n, 2)
    world, but ``skip``."""
    from shapely.geometry import LineString

    lo, hi = points.min(axis=0), points.max(axis=0)  # (2,)
    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    out: dict[int, object] = {}
    for i in global_map.query((float(centre[0]), float(centre[1]), 0.0), tuple(half), 0.1):
        cls, pts = global_map.get(int(i))
        if cls == DIVIDER and int(i) != skip:
            out[int(i)] = LineString(np.asarray(pts))
    return out


def is_stub(
    global_map: GlobalMap,
    points: NDArray[np.float64],
    max_length: float,
    angle: float,
    skip: int = -1,
) -> bool:
    """Whether a divider with world ``points`` (n, 2) is a stub across the lanes of
    ``global_map``: shorter than ``max_length`` metres and crossing a longer stored divider (but
    ``skip``, its own id when stored) at more than ``angle`` degrees (IC-Mapper's rule,
    ``MapperConfig.drop_stubs``; False when ``max_length`` is 0)."""
    from shapely.geometry import LineString

    pts = np.asarray(points, dtype=np.float64)  # (n, 2)
    line = LineString(pts)
    if max_length <= 0 or not line.length < max_length:
        return False
    return crosses_longer(line, list(_dividers_near(global_map, pts, skip).values()), angle)


def drop_stubs(
    global_map: GlobalMap, touched: list[int], max_length: float, angle: float
) -> list[int]:
    """Removes the stubs across lanes (``is_stub``) among the dividers ``touched`` (this step's
    inserts and merges) and their stored neighbours: a stub stored before the line it crosses,
    or one a merge left across a line (IC-Mapper's rule, ``MapperConfig.drop_stubs``). Returns
    the ids removed, ascending."""
    if max_length <= 0:
        return []
    candidates: set[int] = set()
    for i in set(touched):
        if i in global_map and global_map.get(i)[0] == DIVIDER:
            candidates.add(i)
            candidates.update(_dividers_near(global_map, np.asarray(global_map.get(i)[1])))
    gone = [
        i
        for i in sorted(candidates)
        if is_stub(global_map, np.asarray(global_map.get(i)[1]), max_length, angle, skip=i)
    ]
    for i in gone:
        global_map.remove(i)
    return gone
