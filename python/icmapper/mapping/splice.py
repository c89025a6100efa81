"""Rule-based polyline editing: distances to a ring, overlap fractions, and splicing a new
observation into a stored polyline by projection (the overlapped part is replaced, the rest is
kept on either side: the engine's ``splice_polyline``, re-exported here). Shared by the
VMA-style and PolyMerge-style baselines, and by IC-Mapper for its fused polylines
(``MapperConfig.fused_merge``, ``splice_into``): a fused detection already combines the current
view with the instance's history, so it replaces the stretch of the instance it covers instead of
being averaged into it again.

Plain numpy and the engine; all inputs (n, 2) float64 in one frame (the world frame in the
baselines).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.geom import project_onto_polyline, splice_polyline

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

__all__ = [
    "FUSED_MERGES",
    "clip_to_detected",
    "inside_ring",
    "overlap_fraction",
    "ring_distance",
    "splice_into",
    "splice_polyline",
]

#: The rules of ``MapperConfig.fused_merge``.
FUSED_MERGES = ("splice", "fit")


def ring_distance(points: NDArray[np.floating], ring: NDArray[np.floating]) -> NDArray[np.float64]:
    """Distance (n,) from points (n, 2) to a closed ring (m, 2) (edges only, not the interior)."""
    r = np.asarray(ring, dtype=np.float64)
    return project_onto_polyline(points, np.concatenate([r, r[:1]]))[0]


def inside_ring(points: NDArray[np.floating], ring: NDArray[np.floating]) -> NDArray[np.bool_]:
    """Even-odd point-in-polygon test: points (n, 2), ring (m, 2) -> (n,) bool."""
    p = np.asarray(points, dtype=np.float64)
    r = np.asarray(ring, dtype=np.float64)
    a, b = r, np.roll(r, -1, axis=0)  # (m, 2) edges a -> b
    py = p[:, 1:2]  # (n, 1)
    crosses = (a[None, :, 1] > py) != (b[None, :, 1] > py)  # (n, m)
    dy = np.where(b[:, 1] - a[:, 1] == 0, 1e-300, b[:, 1] - a[:, 1])  # (m,)
    x_at = a[None, :, 0] + (py - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / dy  # (n, m)
    return (np.count_nonzero(crosses & (p[:, 0:1] < x_at), axis=1) % 2) == 1


def overlap_fraction(
    a: NDArray[np.floating], b: NDArray[np.floating], buffer: float, closed: bool = False
) -> float:
    """How much two instances overlap: the larger of (fraction of a's points within `buffer` of b)
    and (fraction of b's points within `buffer` of a). Closed rings also count points inside."""
    if closed:
        fa = np.mean((ring_distance(a, b) <= buffer) | inside_ring(a, b))
        fb = np.mean((ring_distance(b, a) <= buffer) | inside_ring(b, a))
    else:
        fa = np.mean(project_onto_polyline(a, b)[0] <= buffer)
        fb = np.mean(project_onto_polyline(b, a)[0] <= buffer)
    return float(max(fa, fb))


def splice_into(
    global_map: GlobalMap,
    target: int,
    world: NDArray[np.floating],
    overlap: float,
    frame: int,
) -> None:
    """Replaces global instance ``target``'s polyline by ``splice_polyline(stored, world,
    overlap)`` (world (n, 2) metres), in the engine (``GlobalMap.splice``). ValueError for
    degenerate geometry (the instance is unchanged)."""
    global_map.splice(int(target), world, overlap, frame)


def clip_to_detected(
    fused: NDArray[np.floating], detected: NDArray[np.floating], min_length: float = 1.0
) -> NDArray[np.float64]:
    """The stretch of a fused polyline (n, 2) between the projections of its detection's (k, 2)
    two ends, as n points evenly spaced along it (``MapperConfig.fused_clip``): the fusion's
    extension beyond what was detected left out. The whole fused polyline when that stretch is
    shorter than ``min_length`` metres."""
    f = np.asarray(fused, dtype=np.float64)
    d = np.asarray(detected, dtype=np.float64)
    _, s = project_onto_polyline(d[[0, -1]], f)  # arc lengths of the detection's ends on f
    a, b = float(s.min()), float(s.max())
    if b - a < min_length:
        return f.copy()
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(f, axis=0), axis=1))])  # (n,)
    t = np.linspace(a, b, len(f))  # (n,)
    return np.stack([np.interp(t, cum, f[:, 0]), np.interp(t, cum, f[:, 1])], axis=1)
