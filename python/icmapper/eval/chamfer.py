"""Chamfer distances between map instances, as the evaluation protocol defines them (numpy).

Protocol (StreamMapNet / IC-Mapper): both instances are resampled to ``NUM_SAMPLES = 200`` points
evenly spaced by arc length (a closed crossing along its closed contour, the start point not
repeated) and ``chamfer = (sum of nearest distances a->b + sum of nearest distances b->a) / (2 N)``,
i.e. the mean of the two directed mean nearest distances.

Speed: the metrics only need the exact Chamfer distance of pairs that can lie under the largest
threshold / gate. :func:`sparse_chamfer` therefore prunes candidate pairs with two *provable* lower
bounds (bounding-box distance, and a coarse 41-point Chamfer with exact error terms, see
:func:`chamfer_lower_bound`) and computes the exact 200-point distance only for the survivors. A
pruned pair is guaranteed to have a Chamfer distance above ``max_dist``, so every decision of the
metrics is the same as with the dense matrix. This module does no I/O.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: Points per instance in the evaluation protocol.
NUM_SAMPLES = 200
#: Indices (into the 200 samples) of the coarse subset used for the lower bound.
COARSE_INDEX = np.r_[np.arange(0, NUM_SAMPLES, 5), NUM_SAMPLES - 1]  # (41,)
# Each fine sample k is attributed to the coarse sample nearest in index: (200,) positions into
# COARSE_INDEX, and the fraction of fine samples attributed to each coarse sample: (41,).
_ASSIGN = np.abs(np.arange(NUM_SAMPLES)[:, None] - COARSE_INDEX[None, :]).argmin(axis=1)
_COARSE_WEIGHT = np.bincount(_ASSIGN, minlength=COARSE_INDEX.size) / NUM_SAMPLES
_CHUNK = 16  # pairs per exact batch: (16, 200, 200) float64 = 5 MB, stays in cache


def resample(
    points: NDArray[np.floating], num: int = NUM_SAMPLES, closed: bool | NDArray[np.bool_] = False
) -> NDArray[np.float64]:
    """Resamples polylines to ``num`` points evenly spaced by arc length (vectorised).

    points: (N, n, 2) with n >= 1; closed: bool or (N,) bool — a closed row is resampled along its
    closed contour (num points at arc positions k * L / num), an open row from its first to its
    last point inclusive. A row of zero length gives ``num`` copies of its first point.
    Returns (N, num, 2) float64.
    """
    return resample_at(points, np.linspace(0.0, 1.0, num), np.arange(num) / num, closed)


def resample_at(
    points: NDArray[np.floating],
    frac_open: NDArray[np.float64],
    frac_closed: NDArray[np.float64],
    closed: bool | NDArray[np.bool_] = False,
) -> NDArray[np.float64]:
    """Points at arc-length fractions (frac_open (m,) for open rows, frac_closed (m,) for closed
    rows, of the closed contour's length) of polylines (N, n, 2) -> (N, m, 2) float64."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[-1] != 2 or pts.shape[1] < 1:
        raise ValueError(f"points must have shape (N, n, 2) with n >= 1, got {pts.shape}")
    closed_rows = np.broadcast_to(np.asarray(closed, dtype=bool), (pts.shape[0],))
    out = np.empty((pts.shape[0], frac_open.shape[0], 2))
    step = 2048  # rows per chunk: temporaries stay in cache
    for s0 in range(0, pts.shape[0], step):
        out[s0 : s0 + step] = _resample_chunk(
            pts[s0 : s0 + step], frac_open, frac_closed, closed_rows[s0 : s0 + step]
        )
    return out


def _resample_chunk(
    pts: NDArray[np.float64],
    frac_open: NDArray[np.float64],
    frac_closed: NDArray[np.float64],
    closed_rows: NDArray[np.bool_],
) -> NDArray[np.float64]:
    n_rows, n = pts.shape[:2]
    num = frac_open.shape[0]
    # Closing point: the first point for closed rows, a zero-length repeat of the last otherwise.
    tail = np.where(closed_rows[:, None], pts[:, 0], pts[:, -1])  # (N, 2)
    ext = np.concatenate([pts, tail[:, None]], axis=1)  # (N, n + 1, 2)
    seg = np.linalg.norm(np.diff(ext, axis=1), axis=-1)  # (N, n)
    cum = np.concatenate([np.zeros((n_rows, 1)), np.cumsum(seg, axis=1)], axis=1)  # (N, n + 1)
    length = cum[:, -1]  # (N,)
    frac = np.where(closed_rows[:, None], frac_closed[None], frac_open[None])  # (N, num)
    target = frac * length[:, None]  # (N, num)
    # Segment of every target, by one searchsorted with each row shifted into its own interval.
    shift = (np.arange(n_rows) * (length.max() + 1.0))[:, None]  # (N, 1)
    pos = np.searchsorted((cum[:, 1:] + shift).ravel(), (target + shift).ravel(), side="right")
    idx = np.minimum(pos.reshape(n_rows, num) - (np.arange(n_rows) * n)[:, None], n - 1)  # (N, num)
    flat = idx + (np.arange(n_rows) * (n + 1))[:, None]  # (N, num) rows into ext
    seg_len = seg.ravel()[flat - np.arange(n_rows)[:, None]]  # (N, num): seg has n per row
    start = cum.ravel()[flat]  # (N, num)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(seg_len > 0, (target - start) / seg_len, 0.0)  # (N, num)
    t = np.clip(t, 0.0, 1.0)[..., None]  # (N, num, 1)
    ext_flat = ext.reshape(-1, 2)
    p0 = ext_flat[flat]  # (N, num, 2)
    p1 = ext_flat[flat + 1]  # (N, num, 2)
    return p0 + t * (p1 - p0)  # (N, num, 2)


# Arc-length offset (in sample spacings) of every fine sample from its coarse sample.
_OFFSET = np.abs(np.arange(NUM_SAMPLES) - COARSE_INDEX[_ASSIGN])  # (200,)


@dataclass
class Resampled:
    """Instances prepared for Chamfer evaluation.

    points (N, n, 2) float64 raw instances, closed (N,) bool; coarse (N, 41, 2): the protocol
    samples of index COARSE_INDEX; err_mean / err_max (N,): bounds of the mean / max distance of a
    fine sample to its attributed coarse sample (arc offset x spacing >= Euclidean); lo / hi (N, 2)
    bounding boxes of the raw vertices (they contain every sample). The 200-point samples are
    made on demand (:meth:`fine_rows`, :attr:`fine`).
    """

    points: NDArray[np.float64]
    closed: NDArray[np.bool_]
    coarse: NDArray[np.float64]
    err_mean: NDArray[np.float64]
    err_max: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @staticmethod
    def from_points(points: NDArray[np.floating], closed: bool | NDArray[np.bool_]) -> Resampled:
        """points (N, n, 2) raw instances (any n >= 1); closed bool or (N,) bool."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 3 or pts.shape[-1] != 2 or pts.shape[1] < 1:
            raise ValueError(f"points must have shape (N, n, 2) with n >= 1, got {pts.shape}")
        closed_rows = np.broadcast_to(np.asarray(closed, dtype=bool), (pts.shape[0],)).copy()
        frac_open = np.linspace(0.0, 1.0, NUM_SAMPLES)[COARSE_INDEX]  # (41,)
        frac_closed = (np.arange(NUM_SAMPLES) / NUM_SAMPLES)[COARSE_INDEX]  # (41,)
        coarse = resample_at(pts, frac_open, frac_closed, closed_rows)  # (N, 41, 2)
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

    def fine_rows(self, rows: NDArray[np.int64]) -> NDArray[np.float64]:
        """The 200 protocol samples of the given rows -> (len(rows), 200, 2)."""
        return resample(self.points[rows], NUM_SAMPLES, self.closed[rows])

    @property
    def fine(self) -> NDArray[np.float64]:
        """All rows' 200 protocol samples (N, 200, 2)."""
        return resample(self.points, NUM_SAMPLES, self.closed)


def _directed_min_sq(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """a (P, n, 2), b (P, m, 2) -> squared nearest distances a->b (P, n) and b->a (P, m)."""
    centre = a.mean(axis=1, keepdims=True)  # (P, 1, 2): centring keeps the expansion accurate
    a = a - centre
    b = b - centre
    d = np.matmul(a, b.transpose(0, 2, 1))  # (P, n, m)
    d *= -2.0
    d += (a * a).sum(-1)[:, :, None]
    d += (b * b).sum(-1)[:, None, :]
    return d.min(axis=2), d.min(axis=1)


#: Backend of the exact stage: "numpy", "engine" (icmapper.geom.chamfer_matrix, Rust) or "auto"
#: (the engine when it imports, else numpy). "auto" because the engine measured faster in the
#: benchmark (python -m icmapper.eval.bench; BENCHMARKS.md). Both give the same values (1e-14).
BACKEND = "auto"


def chamfer_pairs(
    a: NDArray[np.float64], b: NDArray[np.float64], backend: str | None = None
) -> NDArray[np.float64]:
    """Exact Chamfer distance of paired point sets: a (P, n, 2), b (P, m, 2) -> (P,) float64."""
    backend = BACKEND if backend is None else backend
    if backend == "auto":
        backend = "engine" if _engine_available() else "numpy"
    if backend == "engine":
        return _chamfer_pairs_engine(a, b)
    if backend != "numpy":
        raise ValueError(f"unknown Chamfer backend {backend!r}; expected 'numpy' or 'engine'")
    out = np.empty(a.shape[0])
    for s in range(0, a.shape[0], _CHUNK):
        ab, ba = _directed_min_sq(a[s : s + _CHUNK], b[s : s + _CHUNK])
        out[s : s + _CHUNK] = 0.5 * (
            np.sqrt(np.maximum(ab, 0.0)).mean(axis=1) + np.sqrt(np.maximum(ba, 0.0)).mean(axis=1)
        )
    return out


@functools.lru_cache(maxsize=1)
def _engine_available() -> bool:
    try:
        from icmapper.geom import chamfer_matrix as engine_matrix

        engine_matrix(np.zeros((1, 2, 2)), np.ones((1, 2, 2)))
    except Exception:  # extension missing, or built without this function
        return False
    return True


def _chamfer_pairs_engine(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """chamfer_pairs through the Rust engine, one (1, B) call per pair (a, b as above)."""
    from icmapper.geom import chamfer_matrix as engine_matrix

    out = np.empty(a.shape[0])
    for p in range(a.shape[0]):
        out[p] = engine_matrix(a[p : p + 1], b[p : p + 1])[0, 0]
    return out


def chamfer_matrix(a: NDArray[np.floating], b: NDArray[np.floating]) -> NDArray[np.float64]:
    """Dense exact Chamfer matrix of point sets a (A, n, 2) and b (B, m, 2) -> (A, B).

    The points are used as given (resample first for the protocol). Reference implementation.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ia, ib = np.meshgrid(np.arange(len(a)), np.arange(len(b)), indexing="ij")
    return chamfer_pairs(a[ia.ravel()], b[ib.ravel()]).reshape(len(a), len(b))


def chamfer_lower_bound(
    a: Resampled, ia: NDArray[np.int64], b: Resampled, ib: NDArray[np.int64]
) -> NDArray[np.float64]:
    """A provable lower bound of the 200-point Chamfer distance of pairs (a[ia], b[ib]) -> (P,).

    With c(x) the coarse sample attributed to fine sample x and S_b the fine samples of b:
    d(x, S_b) >= d(c(x), coarse_b) - |x - c(x)| - err_max_b (triangle inequality twice), so
    mean_x d(x, S_b) >= sum_j w_j d(coarse_a_j, coarse_b) - err_mean_a - err_max_b; likewise the
    other direction; the bound is the mean of the two.
    """
    out = np.empty(ia.shape[0])
    step = 256
    for s in range(0, ia.shape[0], step):
        ja, jb = ia[s : s + step], ib[s : s + step]
        ab, ba = _directed_min_sq(a.coarse[ja], b.coarse[jb])  # (p, 41), (p, 41)
        mab = np.sqrt(np.maximum(ab, 0.0)) @ _COARSE_WEIGHT  # (p,)
        mba = np.sqrt(np.maximum(ba, 0.0)) @ _COARSE_WEIGHT  # (p,)
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

    a, b: prepared instances; key_a (A,), key_b (B,) int64 group keys (frame and class).
    Returns ia (P,), ib (P,), dist (P,) for exactly the pairs with chamfer <= max_dist, sorted by
    ia then ib. Pairs left out provably have chamfer > max_dist.
    """
    ia, ib = group_pairs(np.asarray(key_a), np.asarray(key_b))
    # 1. Bounding-box distance <= set distance <= chamfer.
    gap = np.maximum(np.maximum(a.lo[ia] - b.hi[ib], b.lo[ib] - a.hi[ia]), 0.0)  # (P, 2)
    keep = np.einsum("pi,pi->p", gap, gap) <= max_dist * max_dist
    ia, ib = ia[keep], ib[keep]
    # 2. Coarse lower bound.
    keep = chamfer_lower_bound(a, ia, b, ib) <= max_dist
    ia, ib = ia[keep], ib[keep]
    # 3. Exact distances of the survivors (samples made for the rows involved only).
    ua, inv_a = np.unique(ia, return_inverse=True)
    ub, inv_b = np.unique(ib, return_inverse=True)
    fa, fb = a.fine_rows(ua), b.fine_rows(ub)  # (ua, 200, 2), (ub, 200, 2)
    dist = np.empty(ia.shape[0])
    step = 4096  # pairs per gather: bounded memory
    for s0 in range(0, ia.shape[0], step):
        sl = slice(s0, s0 + step)
        dist[sl] = chamfer_pairs(fa[inv_a[sl]], fb[inv_b[sl]], backend)
    keep = dist <= max_dist
    return ia[keep], ib[keep], dist[keep]
