"""Rule-based polyline editing: distances and arc-length projections onto a polyline, overlap
fractions, and splicing a new observation into a stored polyline by projection (the overlapped
part is replaced, the rest is kept on either side). Shared by the VMA-style and PolyMerge-style
baselines, and by IC-Mapper for its fused polylines (``MapperConfig.fused_merge``,
``splice_into``): a fused detection already combines the current view with the instance's history,
so it replaces the stretch of the instance it covers instead of being averaged into it again.

Plain numpy; all inputs (n, 2) float64 in one frame (the world frame in the baselines).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.geom import project_onto_polyline

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

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


def orient_like(stored: NDArray[np.float64], new: NDArray[np.float64]) -> NDArray[np.float64]:
    """`new` (q, 2) reversed if needed so that it runs in the direction of `stored` (m, 2)."""
    _, s = project_onto_polyline(new, stored)  # (q,)
    length = float(np.sum(np.linalg.norm(np.diff(stored, axis=0), axis=1)))
    tol = 1e-6 * max(length, 1.0)
    if s[-1] - s[0] > tol:
        return new
    if s[0] - s[-1] > tol:
        return new[::-1]
    # Both ends project to the same place (new lies beyond one end of stored): the end of new
    # nearer to stored's end it continues must come first (after the end) or last (before start).
    if s.mean() >= length / 2:
        forward = np.linalg.norm(new[0] - stored[-1]) <= np.linalg.norm(new[-1] - stored[-1])
    else:
        forward = np.linalg.norm(new[-1] - stored[0]) <= np.linalg.norm(new[0] - stored[0])
    return new if forward else new[::-1]


def splice_polyline(
    stored: NDArray[np.floating], new: NDArray[np.floating], overlap: float
) -> NDArray[np.float64]:
    """Splices a new observation into a stored polyline by projection.

    stored (m, 2), new (q, 2), both with >= 2 points. `new` is oriented like `stored`; stored points
    within `overlap` metres of `new` are substituted by it; the stored points before the projection
    of new's start and after the projection of its end are kept (concatenation). Returns (r, 2).
    """
    p = np.asarray(stored, dtype=np.float64)
    q = orient_like(p, np.asarray(new, dtype=np.float64))
    covered = project_onto_polyline(p, q)[0] <= overlap  # (m,)
    _, s_q = project_onto_polyline(q[[0, -1]], p)  # (2,) where new starts / ends along stored
    s_p = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])  # (m,)
    before = p[(s_p <= s_q[0]) & ~covered]
    after = p[(s_p > s_q[1]) & ~covered]
    return np.concatenate([before, q, after])


def splice_into(
    global_map: GlobalMap,
    target: int,
    world: NDArray[np.floating],
    overlap: float,
    frame: int,
) -> None:
    """Replaces global instance ``target``'s polyline by ``splice_polyline(stored, world,
    overlap)`` (world (n, 2) metres). ValueError (from the engine) for degenerate geometry."""
    _, stored = global_map.get(int(target))
    new = splice_polyline(np.asarray(stored, np.float64), np.asarray(world, np.float64), overlap)
    global_map.replace(int(target), new, frame)
