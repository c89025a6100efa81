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
    out = []
    for a, la in lines.items():
        if la.length >= max_length:
            continue
        for b, lb in lines.items():
            if b == a or lb.length <= la.length or not la.crosses(lb):
                continue
            at = la.intersection(lb).representative_point()
            cos = abs(float(_tangent(la, at) @ _tangent(lb, at)))
            if np.degrees(np.arccos(min(cos, 1.0))) > angle:
                out.append(a)
                break
    return sorted(out)
