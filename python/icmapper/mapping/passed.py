"""What a polyline observation may change in the map: not the stretch the car has passed.

A detection covers the whole perception range, and every merge rule of the project lets the
newest observation win where it overlaps the stored instance. Driving forward, a stretch of a
line is seen first far ahead, then beside the car, then far behind, so its last view, the one the
map would keep, is from the rear edge of the range, where detections are the least accurate
(on the synthetic validation drives the mean point error of the detector's dividers is 0.43 m
20-30 m behind the car against 0.25 m within 10 m). The stored stretch behind the car was
written by a nearer view.

``fresh_runs`` therefore leaves out of an observation the points that lie more than ``behind``
metres behind the ego *and* on the stored instance already (within ``COVER`` metres of it,
projecting inside it): the car has passed them and the map holds a nearer view. Points behind
the car that the instance does not cover yet (an extension beyond its ends, a stretch farther
than ``COVER`` from it) still merge. What is left is split into contiguous runs, each merged on
its own.

``COVER`` is 3 m. With 1 m, the views' points more than 1 m beside the instance were merged:
with the oracle's detections on a synthetic city (`sim-city:val:0:8`, `oracle:low`) a track
that alternated between parallel lines drew them into a zigzag (single-drive mCD 0.617 m). With
no limit at all (every passed point inside the instance left out), the learned detector's
boundaries on the validation drives came out worse (Post-Track CD_bound 0.432 -> 0.460 m); 3 m
does neither (0.616 m; 0.440 m).

"Behind" is along the ego's heading: a car reversing passes stretches ahead of its heading, and
the rule then keeps the stretch it is reversing into as the map holds it (its first views still
merge where the instance lacks them).

Used by every method that merges polylines (``MapperConfig.merge_behind``, shared so that a
comparison applies the same rule to all); crossings keep their own rule (``mapping.crossings``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.geom import project_onto_polyline
from icmapper.mapping.splice import splice_into, splice_polyline

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

#: Metres within which a point of the observation lies on the stored instance.
COVER = 3.0


def fresh_runs(
    ego: NDArray[np.floating],
    world: NDArray[np.floating],
    stored: NDArray[np.floating],
    behind: float,
) -> list[NDArray[np.float64]]:
    """The parts of a polyline observation that merge into the stored instance, longest first.

    ego (n, 2) and world (n, 2): the observation in the ego frame (x forward) and in the world
    frame; stored (m, 2) world: the instance's polyline. ``behind`` (m, > 0; 0 keeps everything):
    points with ego x < -behind that lie within ``COVER`` of the stored polyline, projecting
    between its ends, are left out. Returns (k, 2) float64 world runs of at least 2 points (an
    empty list when nothing is left); the whole observation when nothing is left out.
    """
    w = np.asarray(world, dtype=np.float64)  # (n, 2)
    e = np.asarray(ego, dtype=np.float64)  # (n, 2)
    if e.shape != w.shape or e.ndim != 2 or e.shape[1] != 2:
        raise ValueError(f"fresh_runs: ego {e.shape} and world {w.shape} must both be (n, 2)")
    passed = e[:, 0] < -behind if behind > 0 else np.zeros(len(e), bool)  # (n,)
    if not passed.any():
        return [w]
    s_ = np.asarray(stored, dtype=np.float64)  # (m, 2)
    dist, s = project_onto_polyline(w[passed], s_)  # (p,), (p,)
    length = float(np.linalg.norm(np.diff(s_, axis=0), axis=1).sum())
    drop = np.zeros(len(w), bool)  # (n,)
    drop[passed] = (dist <= COVER) & (s > 0.0) & (s < length)
    if not drop.any():
        return [w]
    # contiguous runs of kept points: boundaries where `keep` changes
    keep = ~drop
    edges = np.flatnonzero(np.diff(np.concatenate([[0], keep.astype(np.int8), [0]])))  # (2r,)
    runs = [w[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]
    return sorted(runs, key=len, reverse=True)


def lies_beside(
    view: NDArray[np.floating], stored: NDArray[np.floating], gate: float, margin: float = 1.0
) -> bool:
    """Whether a polyline view (n, 2) runs beside its stored instance (m, 2) instead of on it:
    more than half of the view's points that project inside the stored line (more than
    ``margin`` metres from either end) lie farther than ``gate`` metres from it, and at least 3
    do. The view then shows another line (a neighbouring lane's): spliced or fitted into the
    instance, it would draw the two lines as one weaving between them. Same frame for both."""
    s_ = np.asarray(stored, dtype=np.float64)
    if len(s_) < 2:
        return False
    dist, s = project_onto_polyline(np.asarray(view, dtype=np.float64), s_)  # (n,), (n,)
    length = float(np.linalg.norm(np.diff(s_, axis=0), axis=1).sum())
    inner = (s > margin) & (s < length - margin)  # (n,)
    return bool(inner.sum() >= 3 and np.mean(dist[inner] > gate) > 0.5)


def merge_view(
    global_map: GlobalMap,
    target: int,
    ego: NDArray[np.floating],
    world: NDArray[np.floating],
    behind: float,
    frame: int,
    splice_overlap: float | None = None,
) -> None:
    """Merges a polyline view (ego (n, 2) and world (n, 2), the same points) into instance
    ``target`` of the map: its ``fresh_runs`` one after the other, each by the engine's curve fit
    (``GlobalMap.merge``), or spliced in (``GlobalMap.splice``) when ``splice_overlap`` is given.
    ValueError for degenerate geometry (the runs before it stay merged)."""
    stored = global_map.get(int(target))[1]
    for run in fresh_runs(ego, world, stored, behind):
        if splice_overlap is None:
            global_map.merge(int(target), run, frame)
        else:
            splice_into(global_map, target, run, splice_overlap, frame)


def splice_view(
    stored: NDArray[np.floating],
    ego: NDArray[np.floating],
    world: NDArray[np.floating],
    behind: float,
    overlap: float,
) -> NDArray[np.float64]:
    """The stored polyline (m, 2) world with a view (ego and world (n, 2), the same points)
    spliced in by ``splice.splice_polyline`` (the VMA and PolyMerge rules): its ``fresh_runs``
    one after the other -> (k, 2) float64 world."""
    new = np.asarray(stored, dtype=np.float64)
    for run in fresh_runs(ego, world, new, behind):
        new = splice_polyline(new, run, overlap)
    return new
