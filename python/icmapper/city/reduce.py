"""The city map from drive maps: a balanced tree of pairwise ``merge_map`` calls in drive order,
((d0 + d1) + (d2 + d3)) + ..., so that in-process and Ray runs merge the same pairs in the same
order and give the same map. Each merge's inputs are native map bytes (what Ray moves between
workers)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def tree_reduce(items: list[T], merge: Callable[[T, T], T]) -> T:
    """Pairwise reduction: level by level, item 2i merged with item 2i+1 (an odd last item is
    carried up). ValueError on an empty list."""
    if not items:
        raise ValueError("tree_reduce: nothing to merge")
    level = list(items)
    while len(level) > 1:
        nxt = [merge(level[i], level[i + 1]) for i in range(0, len(level) - 1, 2)]
        if len(level) % 2:
            nxt.append(level[-1])
        level = nxt
    return level[0]


def merge_bytes(
    a: bytes, b: bytes, gate: float, min_overlap: float, tolerance: float = 3.0
) -> bytes:
    """Map ``b`` merged into map ``a`` (both native bytes) -> native bytes of the result
    (``GlobalMap.merge_map`` with ``gate``, ``min_overlap`` and ``tolerance``, metres / share)."""
    from icmapper._icmap import GlobalMap

    left = GlobalMap.from_bytes(a)
    left.merge_map(GlobalMap.from_bytes(b), gate=gate, min_overlap=min_overlap, tolerance=tolerance)
    return left.to_bytes()
