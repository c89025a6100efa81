"""Map NMS: a clean-up of a finished global map, offered to every method alike.

With ``MapperConfig.map_nms`` the map a method returns at the end of a sequence is cleaned of
duplicates before it is written and evaluated: every instance that lies on a same-class
neighbour over most of its length becomes part of it (``GlobalMap.absorb`` over every instance,
with the ``absorb_*`` settings), as GlobalMapNet's map NMS keeps one of overlapping global
instances. It works on the finished map only, so per-frame predictions (AP, tracking) do not
change. IC-Mapper absorbs online as part of its own merge rule (``MapperConfig.absorb``); this
setting is the generic form, so that a comparison can give every method the same clean-up and
report with and without it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.mapping.config import MapperConfig


def map_nms(global_map: GlobalMap, config: MapperConfig) -> int:
    """Absorbs the duplicates of the whole map in place; returns how many instances went."""
    ids = [int(i) for i in global_map.ids()]
    pairs = global_map.absorb(
        ids, config.absorb_gate, config.absorb_overlap, config.absorb_tolerance
    )
    return len(pairs)
