"""How clean a global map is: instance counts against the ground truth, pieces and duplicates.

The Chamfer-based map metrics (``eval.globalmap``) barely see a map in pieces: ten stubs along a
lane line sit as close to it as one clean instance. A mapping engineer counts instances. Per class,
over the sequences' global maps (world frame, ``(cls, points (n, 2), closed)``):

- ``count``: the map's instances and the ground truth's, and their ratio (1: one map instance per
  ground-truth instance);
- ``pieces``: for each ground-truth instance that the map covers at all, how many map instances
  cover a stretch of it (mean; 1 is clean). The ground truth is sampled every ``STEP`` metres;
  a map instance of the class covers it when at least ``min_cover`` metres of its samples lie
  within ``gate`` of the map instance (inside it, for a crossing): pieces end to end and copies
  side by side both count. ``split``: the share of covered ground-truth instances with two
  pieces or more; ``missed``: the share of all with none;
- ``duplicates``: the share of map instances that lie on another map instance of the class over
  most of their length (more than ``DUPLICATE_SHARE`` of their samples within ``gate`` of it, or
  inside it for crossings; of two instances that lie on each other, the shorter one, or the later
  one at equal length, is the duplicate);
- ``stray``: the share of map instances of which at most half lies within ``gate`` of the ground
  truth of its class (stubs across lanes, phantom kerbs);
- ``folded``: the share of line instances (not crossings) that turn back and lie on themselves
  over more than ``min_cover`` metres: samples within ``gate`` of another sample of the same
  instance at least ``FOLD_GAP`` metres further along it (a line drawn forth and back looks
  like one clean line to every other measure here). NaN for crossings.

Pure numpy + scipy (k-d trees); no I/O.
"""

from __future__ import annotations

from collections.abc import Sequence as Seq
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.detection import CLASS_NAMES
from icmapper.eval.globalmap import dense_sample

#: Sampling step (metres) of the instances.
STEP = 0.5
#: Default distance (metres) within which a sample lies on an instance (the middle AP threshold
#: at 60x30).
GATE = 1.0
#: Default length (metres) of a ground-truth instance a map instance must own to be one of its
#: pieces.
MIN_COVER = 2.0
#: Share of an instance's samples that must lie on another one for it to be a duplicate.
DUPLICATE_SHARE = 0.5
#: Arc length (metres) between two samples of one line beyond which lying within the gate of each
#: other means the line turned back (more than twice the gate: a curve cannot).
FOLD_GAP = 4.0

Item = tuple[int, NDArray[np.floating], bool]


def _inside(xy: NDArray[np.float64], ring: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Even-odd point-in-polygon: xy (M, 2), ring (n, 2) (first point not repeated) -> (M,)."""
    a = ring  # (n, 2)
    b = np.roll(ring, -1, axis=0)  # (n, 2)
    x, y = xy[:, None, 0], xy[:, None, 1]  # (M, 1)
    crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)  # (M, n)
    dy = np.where(b[:, 1] == a[:, 1], 1e-300, b[:, 1] - a[:, 1])  # (n,)
    x_at = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / dy  # (M, n)
    return (crosses & (x < x_at)).sum(axis=1) % 2 == 1


class _Shape:
    """One instance prepared for the tests: its samples every ``STEP`` metres (m, 2), its raw
    points (n, 2), whether it is closed, its bounding box and a k-d tree of its samples."""

    def __init__(self, points: NDArray[np.floating], closed: bool) -> None:
        from scipy.spatial import cKDTree

        self.raw = np.asarray(points, np.float64)
        self.closed = bool(closed)
        self.samples = dense_sample(self.raw, self.closed, STEP)  # (m, 2)
        self.lo, self.hi = self.samples.min(0), self.samples.max(0)
        self.tree = cKDTree(self.samples)

    def near(self, xy: NDArray[np.float64], gate: float) -> NDArray[np.bool_]:
        """Which points xy (M, 2) lie within ``gate`` of the instance (or inside a closed one)."""
        out = np.zeros(len(xy), bool)
        box = np.all((xy >= self.lo - gate) & (xy <= self.hi + gate), axis=1)  # (M,)
        if not box.any():
            return out
        d, _ = self.tree.query(xy[box], distance_upper_bound=gate)
        hit = np.isfinite(d)
        if self.closed and len(self.raw) >= 3:
            hit |= _inside(xy[box], self.raw)
        out[box] = hit
        return out


def _class_items(items: Seq[Item], c: int) -> list[_Shape]:
    return [_Shape(p, closed) for cls, p, closed in items if int(cls) == c]


def _sequence_class(
    pred: list[_Shape], gt: list[_Shape], gate: float, min_cover: float
) -> dict[str, list[Any]]:
    """Per ground-truth instance its pieces, per map instance whether it is a duplicate and
    whether it is stray, for one class of one sequence (``fragmentation`` pools them)."""
    pieces = [sum(int(p.near(g.samples, gate).sum() * STEP >= min_cover) for p in pred) for g in gt]
    duplicate = []
    for i, a in enumerate(pred):
        dup = False
        for j, b in enumerate(pred):
            if j == i or np.any(a.lo > b.hi + gate) or np.any(b.lo > a.hi + gate):
                continue
            if b.near(a.samples, gate).mean() <= DUPLICATE_SHARE:
                continue
            mutual = a.near(b.samples, gate).mean() > DUPLICATE_SHARE
            la, lb = len(a.samples), len(b.samples)
            if not mutual or la < lb or (la == lb and i > j):
                dup = True
                break
        duplicate.append(dup)
    stray = []
    for a in pred:
        on = np.zeros(len(a.samples), bool)
        for g in gt:
            on |= g.near(a.samples, gate)
        stray.append(bool(on.mean() <= 0.5))
    folded = [_folded_length(a, gate) > min_cover for a in pred if not a.closed]
    return {"pieces": pieces, "duplicate": duplicate, "stray": stray, "folded": folded}


def _folded_length(a: _Shape, gate: float) -> float:
    """Metres of the open instance ``a`` lying within ``gate`` of a stretch of itself at least
    ``FOLD_GAP`` metres away along it (samples every ``STEP`` metres by arc length)."""
    near = a.tree.query_ball_point(a.samples, gate)  # per sample, its neighbours' indices
    gap = FOLD_GAP / STEP
    back = [any(abs(j - i) > gap for j in nb) for i, nb in enumerate(near)]
    return float(np.sum(back)) * STEP


def fragmentation(
    pred: Seq[Seq[Item]],
    gt: Seq[Seq[Item]],
    gate: float = GATE,
    min_cover: float = MIN_COVER,
) -> dict:
    """The clean-map measures (module docstring) over sequences: pred[s], gt[s] are the global
    maps of sequence s as ``(cls, points (n, 2) world, closed)`` (extra tuple members ignored).

    Returns {"count": {class: {"map", "gt", "ratio"}}, "pieces": {class: mean}, "split": {class:
    share}, "missed": {class: share}, "duplicates": {class: share}, "stray": {class: share},
    "folded": {class: share}, "gate", "min_cover"}; a ratio or mean with nothing to average is
    NaN.
    """
    if len(pred) != len(gt):
        raise ValueError(f"fragmentation: {len(pred)} predicted maps for {len(gt)} sequences")
    if not (gate > 0 and np.isfinite(gate)) or not (min_cover >= 0 and np.isfinite(min_cover)):
        raise ValueError(
            f"fragmentation: need gate > 0 and min_cover >= 0, got {gate}, {min_cover}"
        )
    keys = ("count", "pieces", "split", "missed", "duplicates", "stray", "folded")
    out: dict = {k: {} for k in keys}
    for c, name in enumerate(CLASS_NAMES):
        n_pred = n_gt = 0
        pieces: list[int] = []
        dup: list[bool] = []
        stray: list[bool] = []
        folded: list[bool] = []
        for ps, gs in zip(pred, gt, strict=True):
            mine = _class_items([p[:3] for p in ps], c)
            truth = _class_items([g[:3] for g in gs], c)
            raw = _sequence_class(mine, truth, gate, min_cover)
            n_pred, n_gt = n_pred + len(mine), n_gt + len(truth)
            pieces += raw["pieces"]
            dup += raw["duplicate"]
            stray += raw["stray"]
            folded += raw["folded"]
        covered = [p for p in pieces if p > 0]
        out["count"][name] = {
            "map": n_pred, "gt": n_gt, "ratio": n_pred / n_gt if n_gt else float("nan"),
        }  # fmt: skip
        out["pieces"][name] = float(np.mean(covered)) if covered else float("nan")
        out["split"][name] = float(np.mean([p >= 2 for p in covered])) if covered else float("nan")
        out["missed"][name] = float(np.mean([p == 0 for p in pieces])) if pieces else float("nan")
        out["duplicates"][name] = float(np.mean(dup)) if dup else float("nan")
        out["stray"][name] = float(np.mean(stray)) if stray else float("nan")
        out["folded"][name] = float(np.mean(folded)) if folded else float("nan")
    out["gate"], out["min_cover"] = float(gate), float(min_cover)
    return out
