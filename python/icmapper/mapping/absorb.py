"""Absorption after the merge (step 7 of the mapper's pipeline, an extension): an instance this
step inserted or merged into and a same-class neighbour it lies on over most of its length become
one (``GlobalMap.absorb``, native); the tracks of the absorbed instance map into the kept one from
then on. No I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap


def absorb_touched(
    global_map: GlobalMap,
    crossings: CrossingMerger,
    alias: dict[int, int],
    config: MapperConfig,
    touched: list[int],
) -> int:
    """Lets the ``touched`` instances absorb the same-class neighbours they lie on, or be absorbed
    by them; ``alias`` (track id -> instance id) and the crossing rule's counts follow in place.
    Returns how many instances were absorbed (0 when ``config.absorb`` is off)."""
    if not config.absorb or not touched:
        return 0
    pairs = global_map.absorb(
        sorted(set(touched)), config.absorb_gate, config.absorb_overlap, config.absorb_tolerance
    )
    for gone, into in pairs:
        for track, target in alias.items():
            if target == gone:
                alias[track] = into
        alias[gone] = into
        crossings.absorbed(gone, into)
    return len(pairs)
