"""Absorption after the merge (step 7 of the mapper's pipeline, an extension): an instance this
step inserted or merged into and a same-class neighbour it lies on over most of its length become
one (``GlobalMap.absorb``, native); the tracks of the absorbed instance map into the kept one from
then on. ``absorb_pairs`` owns the per-class gates (``absorb_gate``; ``absorb_boundary_gate`` for
boundaries), for this step and for every method's map NMS (``mapping.map_nms``). No I/O.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from icmapper.data.types import MapClass
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap


def absorb_pairs(
    global_map: GlobalMap, ids: list[int], config: MapperConfig
) -> list[tuple[int, int]]:
    """``GlobalMap.absorb`` of ``ids`` with the gate of their class: boundaries with
    ``absorb_boundary_gate`` (two views of one kerb lie up to 1.5 m apart in the coarse BEV; no
    two kerbs of a road lie that close), the other classes with ``absorb_gate`` (lane lines lie
    3 m apart). An instance only absorbs neighbours of its own class, so the two calls are the
    per-class rule. Returns the (absorbed, kept) pairs in order."""
    bounds: list[int] = []
    others: list[int] = []
    for i in ids:
        (bounds if int(global_map.get(i)[0]) == MapClass.BOUNDARY else others).append(i)
    pairs: list[tuple[int, int]] = []
    for group, gate in ((others, config.absorb_gate), (bounds, config.absorb_boundary_gate)):
        if group:
            pairs += global_map.absorb(group, gate, config.absorb_overlap, config.absorb_tolerance)
    return pairs


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
    pairs = absorb_pairs(global_map, sorted(set(touched)), config)
    for gone, into in pairs:
        for track, target in alias.items():
            if target == gone:
                alias[track] = into
        alias[gone] = into
        crossings.absorbed(gone, into)
    return len(pairs)
