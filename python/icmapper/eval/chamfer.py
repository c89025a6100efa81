"""Chamfer distances between map instances, as the evaluation protocol defines them.

Protocol (StreamMapNet / IC-Mapper): both instances are resampled to ``NUM_SAMPLES = 200`` points
evenly spaced by arc length (a closed crossing along its closed contour, the start point not
repeated) and ``chamfer = (sum of nearest distances a->b + sum of nearest distances b->a) / (2 N)``,
i.e. the mean of the two directed mean nearest distances. The geometry itself (resampling, exact
Chamfer, paired nearest distances) is ``icmapper.geom``'s; this module adds the pruning.

Speed: the metrics only need the exact Chamfer distance of pairs that can lie under the largest
threshold / gate. :func:`sparse_chamfer` therefore prunes candidate pairs with two *provable* lower
bounds (bounding-box distance, and a coarse 41-point Chamfer with exact error terms, see
:func:`chamfer_lower_bound`) and computes the exact 200-point distance only for the survivors. A
pruned pair is guaranteed to have a Chamfer distance above ``max_dist``, so every decision of the
metrics is the same as with the dense matrix. This module does no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.geom import chamfer_pairs, paired_directed_means, resample_many

__all__ = [
    "COARSE_INDEX",
    "NUM_SAMPLES",
    "Resampled",
    "chamfer_lower_bound",
    "chamfer_pairs",
    "group_pairs",
    "sparse_chamfer",
]

#: Points per instance in the evaluation protocol.
NUM_SAMPLES = 200
#: Indices (into the 200 samples) of the coarse subset used for the lower bound.
COARSE_INDEX = np.r_[np.arange(0, NUM_SAMPLES, 5), NUM_SAMPLES - 1]  # (41,)
# Each fine sample k is attributed to the coarse sample nearest in index: (200,) positions into
# COARSE_INDEX, and the fraction of fine samples attributed to each coarse sample: (41,).
_ASSIGN = np.abs(np.arange(NUM_SAMPLES)[:, None] - COARSE_INDEX[None, :]).argmin(axis=1)
_COARSE_WEIGHT = np.bincount(_ASSIGN, minlength=COARSE_INDEX.size) / NUM_SAMPLES
_ROWS = 4096  # instances per resampling chunk: (4096, 200, 2) float64 = 13 MB
#: Margin (metres) added to the pruning tests: the bounds stay conservative whatever the
#: round-off of the sampling (pruning only decides which pairs get an exact distance).
_PRUNE_SLACK = 1e-9


# Arc-length offset (in sample spacings) of every fine sample from its coarse sample.
_OFFSET = np.abs(np.arange(NUM_SAMPLES) - COARSE_INDEX[_ASSIGN])  # (200,)


@dataclass
class Resampled:
    """Instances prepared for Chamfer evaluation.

    points (N, n, 2) float64 raw instances, closed (N,) bool; coarse (N, 41, 2): the protocol
    samples of index COARSE_INDEX; err_mean / err_max (N,): bounds of the mean / max distance of a
    fine sample to its attributed coarse sample (arc offset x spacing >= Euclidean); lo / hi (N, 2)
    bounding boxes of the raw vertices (they contain every sample). The 200-point samples are
    made on demand (:meth:`fine_rows`, :attr:`fine`) — unless ``sampled``: then ``points`` are
    already the (N, 200, 2) samples (:meth:`from_samples`) and are used as they are.
    """

    points: NDArray[np.float64]
    closed: NDArray[np.bool_]
    coarse: NDArray[np.float64]
    err_mean: NDArray[np.float64]
    err_max: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    sampled: bool = False

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @staticmethod
    def from_points(points: NDArray[np.floating], closed: bool | NDArray[np.bool_]) -> Resampled:
        """points (N, n, 2) raw instances (any n >= 1); closed bool or (N,) bool."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[-1] != 2 or pts.shape[1] < 1:
            raise ValueError(f"points must have shape (N, n, 2) with n >= 1, got {pts.shape}")
        closed_rows = np.broadcast_to(np.asarray(closed, dtype=bool), (pts.shape[0],)).copy()
        coarse = np.empty((pts.shape[0], COARSE_INDEX.size, 2))  # (N, 41, 2)
        for s0 in range(0, pts.shape[0], _ROWS):  # the 200 samples of a chunk, then the subset
            rows = slice(s0, s0 + _ROWS)
            fine = resample_many(pts[rows], NUM_SAMPLES, closed_rows[rows])  # (r, 200, 2)
            coarse[rows] = fine[:, COARSE_INDEX]
        ring_gap = np.linalg.norm(pts[:, 0] - pts[:, -1], axis=-1)  # (N,)
        length = np.linalg.norm(np.diff(pts, axis=1), axis=-1).sum(axis=1)  # (N,)
        length = length + np.where(closed_rows, ring_gap, 0.0)
        spacing = length / np.where(closed_rows, NUM_SAMPLES, NUM_SAMPLES - 1)  # (N,)
        if pts.shape[0] == 0:
            lo = hi = np.zeros((0, 2))
        else:
            lo, hi = pts.min(axis=1), pts.max(axis=1)  # (N, 2)
        return Resampled(
            pts, closed_rows, coarse, spacing * _OFFSET.mean(), spacing * _OFFSET.max(), lo, hi
        )

    @staticmethod
    def from_samples(samples: NDArray[np.floating]) -> Resampled:
        """Instances already sampled to the protocol's points, used as they are (no second
        resampling; GAP): samples (N, 200, 2). The coarse points are the samples of index
        COARSE_INDEX and the error terms the exact distances of every sample to its coarse one."""
        fine = np.asarray(samples, dtype=np.float64)
        if fine.ndim != 3 or fine.shape[1:] != (NUM_SAMPLES, 2):
            raise ValueError(f"samples must have shape (N, {NUM_SAMPLES}, 2), got {fine.shape}")
        coarse = fine[:, COARSE_INDEX]  # (N, 41, 2)
        err = np.linalg.norm(fine - coarse[:, _ASSIGN], axis=-1)  # (N, 200)
        if fine.shape[0] == 0:
            lo = hi = np.zeros((0, 2))
            err_mean = err_max = np.zeros(0)
        else:
            lo, hi = fine.min(axis=1), fine.max(axis=1)  # (N, 2)
            err_mean, err_max = err.mean(axis=1), err.max(axis=1)  # (N,)
        return Resampled(
            fine, np.zeros(fine.shape[0], dtype=bool), coarse, err_mean, err_max, lo, hi, True
        )

    def fine_rows(self, rows: NDArray[np.int64]) -> NDArray[np.float64]:
        """The 200 protocol samples of the given rows -> (len(rows), 200, 2)."""
        if self.sampled:
            return self.points[rows]
        return resample_many(self.points[rows], NUM_SAMPLES, self.closed[rows])

    @property
    def fine(self) -> NDArray[np.float64]:
        """All rows' 200 protocol samples (N, 200, 2)."""
        return self.fine_rows(np.arange(len(self)))


def chamfer_lower_bound(
    a: Resampled, ia: NDArray[np.int64], b: Resampled, ib: NDArray[np.int64]
) -> NDArray[np.float64]:
    """A provable lower bound of the 200-point Chamfer distance of pairs (a[ia], b[ib]) -> (P,).
    Not a second Chamfer: ``geom.paired_directed_means`` of the coarse samples, minus their
    sampling error, so that pruning needs no 200-point distance.

    With c(x) the coarse sample attributed to fine sample x and S_b the fine samples of b:
    d(x, S_b) >= d(c(x), coarse_b) - |x - c(x)| - err_max_b (triangle inequality twice), so
    mean_x d(x, S_b) >= sum_j w_j d(coarse_a_j, coarse_b) - err_mean_a - err_max_b; likewise the
    other direction; the bound is the mean of the two.
    """
    out = np.empty(ia.shape[0])
    step = 256
    for s in range(0, ia.shape[0], step):
        ja, jb = ia[s : s + step], ib[s : s + step]
        # (p,), (p,): the coarse Chamfer terms, each coarse sample weighted by its share
        mab, mba = paired_directed_means(a.coarse[ja], b.coarse[jb], _COARSE_WEIGHT)
        slack = a.err_mean[ja] + b.err_max[jb] + b.err_mean[jb] + a.err_max[ja]  # (p,)
        out[s : s + step] = 0.5 * (mab + mba - slack)
    return out


def group_pairs(
    key_a: NDArray[np.int64], key_b: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All pairs (i, j) with key_a[i] == key_b[j] (e.g. same frame and class).

    Returns ia (P,), ib (P,) int64, sorted by i then j.
    """
    order_b = np.argsort(key_b, kind="stable")  # (B,)
    sorted_b = key_b[order_b]
    start = np.searchsorted(sorted_b, key_a, side="left")  # (A,)
    stop = np.searchsorted(sorted_b, key_a, side="right")  # (A,)
    count = stop - start  # (A,)
    ia = np.repeat(np.arange(key_a.shape[0]), count)  # (P,)
    # position within each run: global arange minus the run's first output position
    first = np.repeat(np.cumsum(count) - count, count)  # (P,)
    ib = order_b[np.repeat(start, count) + np.arange(ia.shape[0]) - first]  # (P,)
    return ia.astype(np.int64), ib.astype(np.int64)


def sparse_chamfer(
    a: Resampled,
    key_a: NDArray[np.int64],
    b: Resampled,
    key_b: NDArray[np.int64],
    max_dist: float,
    backend: str | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Exact Chamfer distances of all same-key pairs whose distance is <= max_dist.

    a, b: prepared instances; key_a (A,), key_b (B,) int64 group keys (frame and class);
    backend: of the exact stage (``geom.chamfer_pairs``; None: the engine).
    Returns ia (P,), ib (P,), dist (P,) for exactly the pairs with chamfer <= max_dist, sorted by
    ia then ib. Pairs left out provably have chamfer > max_dist.
    """
    ia, ib = group_pairs(np.asarray(key_a), np.asarray(key_b))
    # 1. Bounding-box distance <= set distance <= chamfer.
    gap = np.maximum(np.maximum(a.lo[ia] - b.hi[ib], b.lo[ib] - a.hi[ia]), 0.0)  # (P, 2)
    reach = max_dist + _PRUNE_SLACK
    keep = np.einsum("pi,pi->p", gap, gap) <= reach * reach
    ia, ib = ia[keep], ib[keep]
    # 2. Coarse lower bound.
    keep = chamfer_lower_bound(a, ia, b, ib) <= reach
    ia, ib = ia[keep], ib[keep]
    # 3. Exact distances of the survivors (samples made for the rows involved only).
    ua, inv_a = np.unique(ia, return_inverse=True)
    ub, inv_b = np.unique(ib, return_inverse=True)
    fa, fb = a.fine_rows(ua), b.fine_rows(ub)  # (ua, 200, 2), (ub, 200, 2)
    dist = np.empty(ia.shape[0])
    step = 4096  # pairs per gather: bounded memory
    for s0 in range(0, ia.shape[0], step):
        sl = slice(s0, s0 + step)
        dist[sl] = chamfer_pairs(fa[inv_a[sl]], fb[inv_b[sl]], backend or "engine")
    keep = dist <= max_dist
    return ia[keep], ib[keep], dist[keep]
