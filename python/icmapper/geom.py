"""The geometry of the Python side: the native engine's functions (``icmapper._icmap``, Rust
``icmap-geom``) and the few batched numpy forms the engine has no equivalent for.

Every Python module takes its geometry from here (resampling, Chamfer distances, point-to-segment
distances): one function per concept, so that the metrics, the ground truth and the tracker cannot
drift apart. It holds no I/O and no knowledge of classes, datasets or metrics.

Engine functions (re-exported; conversion, validation and GIL release happen in the extension).
Inputs are ``(n, 2)`` array-likes of a real dtype (float64/float32 read directly, integers and
nested sequences converted); outputs are float64 numpy arrays. A ``pose`` is ``(x, y, yaw)`` ego ->
world, ``half_extents`` is ``(hx, hy)`` along the ego axes. Bad input raises ``ValueError``
(values, shapes), ``TypeError`` (dtypes, types), never returns garbage. See ``_icmap.pyi`` for the
full typed contract.

resample(points (n, 2), n, closed=False) -> (n, 2)
    Exactly ``n`` points evenly spaced by arc length.
resample_spacing(points (n, 2), spacing=1.0, closed=False) -> (m, 2)
    Points about ``spacing`` metres apart.
clip_to_patch(points (n, 2), pose, half_extents, margin=0.0, closed=False) -> list[(m, 2)]
    Pieces inside the oriented patch, same frame as the input (closed: ``[ring]`` or ``[]``).
fit_curve(points (n, 2), s=0.5, spacing=1.0) -> (m, 2)
    Smoothing cubic spline with scipy ``splprep(s=s)`` semantics, evaluated ~``spacing`` apart.
merge_polyline(global_pts (n, 2), detected_pts (d, 2), s=0.5, spacing=1.0) -> (m, 2)
    IC-Mapper Algorithm 2: reorder, concatenate, fit; keeps the global direction.
splice_polyline(stored (m, 2), new (q, 2), overlap) -> (r, 2)
    The stretch of ``stored`` that ``new`` covers (points within ``overlap``) replaced by it.
polygon_union(rings: list[(n_i, 2)]) -> list[(m, 2)]
    Outer rings of the union, counter-clockwise, largest first.
chamfer_distance(a (n, 2), b (m, 2)) -> float
    (mean nearest distance a->b + mean b->a) / 2.
chamfer_matrix(a: (A, n, 2) | list[(n_i, 2)], b: ...) -> (A, B)
    All pairwise Chamfer distances.
GlobalMap
    The global vector map store (also ``icmapper.GlobalMap``).

Python functions (below; numpy, and the engine where it is faster — measured by
``benchmarks/bench_python_geometry.py``, figures in BENCHMARKS.md):

resample_many(points (N, n, 2), n_out, closed) -> (N, n_out, 2)
    ``resample`` over a table of instances; also total on degenerate rows (zero length).
signed_ring_area(ring (n, 2)) -> float
    Shoelace area of a ring, positive counter-clockwise.
arc_lengths(points (n, 2)) -> (n,);  points_at_lengths(points (n, 2), s (m,)) -> (m, 2)
    Cumulative arc length of one polyline; its points at given arc lengths (clamped to the ends).
chamfer_pairs(a (P, n, 2), b (P, m, 2)) -> (P,)
    ``chamfer_distance`` of paired sets (a[p], b[p]).
paired_nearest_sq(a (P, n, 2), b (P, m, 2)) -> ((P, n), (P, m))
    Squared nearest distances both ways of paired sets (numpy).
paired_directed_means(a (P, n, 2), b (P, m, 2), weights=None) -> ((P,), (P,))
    The two mean nearest distances of paired sets (optionally weighted): the Chamfer terms that
    ``chamfer_pairs`` (numpy) and the evaluation's lower bound (``eval.chamfer``) both use.
cloud_chamfer(a (n, 2), b (m, 2)) -> float
    ``chamfer_distance`` for clouds of any size (a k-d tree instead of all pairs when large).
polyline_segments(points (B, m, 2), closed (B,)) -> (B, m, 2, 2);
point_to_segments(points (A, n, 2), segments (B, m, 2, 2)) -> (A, B, n)
    Segments of polylines/rings; distance of every point to the nearest segment of each set.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from icmapper._icmap import (
    GlobalMap,
    chamfer_distance,
    chamfer_matrix,
    clip_to_patch,
    fit_curve,
    merge_polyline,
    polygon_union,
    resample,
    resample_spacing,
    splice_polyline,
)

__all__ = [
    "GlobalMap",
    "arc_lengths",
    "chamfer_distance",
    "chamfer_matrix",
    "chamfer_pairs",
    "clip_to_patch",
    "cloud_chamfer",
    "fit_curve",
    "merge_polyline",
    "paired_nearest_sq",
    "point_to_segments",
    "points_at_lengths",
    "polygon_union",
    "polyline_segments",
    "resample",
    "resample_many",
    "resample_spacing",
    "signed_ring_area",
    "splice_polyline",
]


def _point_sets(x: ArrayLike, name: str, ndim: int = 3) -> NDArray[np.float64]:
    """x as float64 with shape (..., 2) of ``ndim`` dimensions, else ValueError naming ``name``."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != ndim or arr.shape[-1] != 2:
        want = {2: "(n, 2)", 3: "(N, n, 2)"}[ndim]
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


# ---------------------------------------------------------------------------------------------
# Arc length


def resample_many(
    points: ArrayLike, n_out: int, closed: bool | ArrayLike = False
) -> NDArray[np.float64]:
    """Resamples every row of a table to ``n_out`` points evenly spaced by arc length.

    points: (N, n, 2), n >= 1; closed: bool or (N,) bool. Row i is ``resample(points[i], n_out,
    closed[i])`` (the engine): an open row from its first to its last point inclusive (arc
    positions j L / (n_out - 1)), a closed row along its closed contour (j L / n_out, the start
    not repeated). Also total where the engine refuses: a row of zero length (or a single point)
    gives ``n_out`` copies of its first point; ``n_out`` = 1 (open) gives the first point, a closed
    row with ``n_out`` < 3 takes every third point of ``3 n_out``. Returns (N, n_out, 2) float64.
    ValueError (naming the row) on NaN/inf or a bad shape.
    """
    pts = _point_sets(points, "resample_many: points")
    num = int(n_out)
    if num < 1:
        raise ValueError(f"resample_many: n_out must be >= 1, got {n_out}")
    if pts.shape[1] < 1 and pts.shape[0] > 0:
        raise ValueError(f"resample_many: rows need at least 1 point, got shape {pts.shape}")
    closed_rows = np.broadcast_to(np.asarray(closed, dtype=bool), (pts.shape[0],))
    out = np.empty((pts.shape[0], num, 2))  # (N, n_out, 2)
    if pts.shape[0] == 0:
        return out
    if not np.all(np.isfinite(pts)):
        bad = int(np.flatnonzero(~np.isfinite(pts).all(axis=(1, 2)))[0])
        raise ValueError(f"resample_many: row {bad} contains NaN or inf")
    # Zero length: no segment (open) nor closing edge (closed) has a non-zero length.
    moves = np.any(pts[:, 1:] != pts[:, :-1], axis=(1, 2))  # (N,)
    for i in range(pts.shape[0]):
        row = np.ascontiguousarray(pts[i])  # (n, 2)
        try:
            if not moves[i]:
                out[i] = row[0]
            elif closed_rows[i]:
                out[i] = resample(row, num, True) if num >= 3 else resample(row, 3 * num, True)[::3]
            else:
                out[i] = resample(row, num, False) if num >= 2 else row[:1]
        except ValueError as exc:
            raise ValueError(f"resample_many: row {i}: {exc}") from None
    return out


def project_onto_polyline(
    points: ArrayLike, poly: ArrayLike, tie_tol: float = 0.0
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nearest point of an open polyline for each point (numpy, batched over the points).

    points (n, 2), poly (m, 2) with m >= 1 -> (dist (n,), s (n,)): the distance to the polyline
    and the arc length (metres from poly[0]) of the nearest point on it. Among segments within
    ``tie_tol`` of the nearest distance the first one (smallest arc length) is taken.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
    if q.shape[0] == 0:
        raise ValueError("project_onto_polyline: the polyline has no points")
    if q.shape[0] == 1:
        return np.linalg.norm(p - q[0], axis=1), np.zeros(p.shape[0])
    a, ab = q[:-1], np.diff(q, axis=0)  # (m-1, 2)
    seg_len = np.linalg.norm(ab, axis=1)  # (m-1,)
    s0 = np.concatenate([[0.0], np.cumsum(seg_len)])[:-1]  # (m-1,)
    denom = np.maximum(seg_len**2, 1e-18)  # (m-1,)
    t = np.clip(np.einsum("nmk,mk->nm", p[:, None, :] - a[None], ab) / denom, 0.0, 1.0)  # (n, m-1)
    d = np.linalg.norm(p[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=2)  # (n, m-1)
    j = np.argmax(d <= d.min(axis=1, keepdims=True) + tie_tol, axis=1)  # (n,) first near-best
    rows = np.arange(p.shape[0])
    return d[rows, j], s0[j] + t[rows, j] * seg_len[j]


def signed_ring_area(ring: ArrayLike) -> float:
    """Area enclosed by a ring (n, 2) (first point not repeated; shoelace): positive when the ring
    runs counter-clockwise, negative clockwise."""
    r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
    x, y = r[:, 0], r[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def arc_lengths(points: ArrayLike) -> NDArray[np.float64]:
    """Cumulative arc length at every vertex of an (n, 2) polyline -> (n,), starting at 0."""
    pts = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)  # (n - 1,)
    return np.concatenate([[0.0], np.cumsum(seg)])


def points_at_lengths(points: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
    """Points of an (n, 2) polyline at the arc lengths s (m,) (metres from points[0], clamped to
    the ends; linear interpolation) -> (m, 2) float64. For evenly spaced points use ``resample``."""
    pts = np.asarray(points, dtype=np.float64)
    cum = arc_lengths(pts)  # (n,)
    return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)


# ---------------------------------------------------------------------------------------------
# Chamfer distances


def paired_nearest_sq(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Squared nearest distances of paired point sets, both ways (numpy, batched).

    a (P, n, 2), b (P, m, 2) float64 -> (a->b (P, n), b->a (P, m)). Computed as
    ``|a|^2 + |b|^2 - 2 a.b`` after centring each pair on a's mean (error ~1e-14 m at map scales);
    may be very slightly negative: clip at 0 before a square root.
    """
    centre = a.mean(axis=1, keepdims=True)  # (P, 1, 2): centring keeps the expansion accurate
    a = a - centre
    b = b - centre
    d = np.matmul(a, b.transpose(0, 2, 1))  # (P, n, m)
    d *= -2.0
    d += (a * a).sum(-1)[:, :, None]
    d += (b * b).sum(-1)[:, None, :]
    return d.min(axis=2), d.min(axis=1)


def paired_directed_means(
    a: NDArray[np.float64], b: NDArray[np.float64], weights: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Mean nearest distances of paired point sets, both ways (numpy, batched): the two terms of
    the Chamfer distance, ``chamfer = (a->b + b->a) / 2``.

    a (P, n, 2), b (P, m, 2) float64 -> (a->b (P,), b->a (P,)). weights: (n,) weights of the
    points (then n == m; e.g. the arc-length share of coarse samples) for a weighted mean instead
    of the plain one."""
    ab, ba = paired_nearest_sq(a, b)  # (P, n), (P, m)
    dab, dba = np.sqrt(np.maximum(ab, 0.0)), np.sqrt(np.maximum(ba, 0.0))
    if weights is None:
        return dab.mean(axis=1), dba.mean(axis=1)
    return dab @ weights, dba @ weights


_PAIR_CHUNK = 16  # pairs per numpy batch: (16, 200, 200) float64 = 5 MB, stays in cache


def chamfer_pairs(a: ArrayLike, b: ArrayLike, backend: str = "engine") -> NDArray[np.float64]:
    """Chamfer distance of paired point sets: a (P, n, 2), b (P, m, 2) -> (P,) float64, entry p
    ``chamfer_distance(a[p], b[p])``.

    backend: "engine" (one engine call per pair; the faster, see BENCHMARKS.md) or "numpy"
    (``paired_nearest_sq`` in batches; kept for the benchmark). Same values to ~1e-14 m.
    """
    a = _point_sets(a, "chamfer_pairs: a")
    b = _point_sets(b, "chamfer_pairs: b")
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"chamfer_pairs: {a.shape[0]} sets in a, {b.shape[0]} in b")
    out = np.empty(a.shape[0])  # (P,)
    if backend == "engine":
        for p in range(a.shape[0]):
            out[p] = chamfer_distance(a[p], b[p])
        return out
    if backend != "numpy":
        raise ValueError(f"unknown Chamfer backend {backend!r}; expected 'engine' or 'numpy'")
    for s in range(0, a.shape[0], _PAIR_CHUNK):
        mab, mba = paired_directed_means(a[s : s + _PAIR_CHUNK], b[s : s + _PAIR_CHUNK])
        out[s : s + _PAIR_CHUNK] = 0.5 * (mab + mba)
    return out


#: ``cloud_chamfer`` uses the engine's all-pairs ``chamfer_distance`` up to this many point pairs
#: (n m) and a k-d tree above (the crossover measured by benchmarks/bench_python_geometry.py).
CLOUD_ENGINE_PAIRS = 1_000_000


def cloud_chamfer(a: ArrayLike, b: ArrayLike) -> float:
    """``chamfer_distance`` for point clouds of any size: a (n, 2), b (m, 2), both non-empty and
    finite -> (mean nearest distance a->b + mean b->a) / 2. A second form of the same distance
    because the engine's (and ``paired_directed_means``') all-pairs cost n m is too much for large
    clouds.

    Up to ``CLOUD_ENGINE_PAIRS`` point pairs the engine's all-pairs ``chamfer_distance``; above,
    nearest neighbours by k-d tree (scipy, O((n + m) log) instead of n m: ~20x faster at 20,000
    points each, BENCHMARKS.md). Exact either way (same value to round-off).
    """
    pa = _point_sets(a, "cloud_chamfer: a", ndim=2)
    pb = _point_sets(b, "cloud_chamfer: b", ndim=2)
    if pa.shape[0] * pb.shape[0] <= CLOUD_ENGINE_PAIRS:
        return float(chamfer_distance(pa, pb))
    from scipy.spatial import cKDTree

    for name, p in (("a", pa), ("b", pb)):
        if not np.all(np.isfinite(p)):
            raise ValueError(f"cloud_chamfer: point set {name} contains NaN or inf")
    dab, _ = cKDTree(pb).query(pa)  # (n,)
    dba, _ = cKDTree(pa).query(pb)  # (m,)
    return 0.5 * (float(dab.mean()) + float(dba.mean()))


# ---------------------------------------------------------------------------------------------
# Point-to-segment distances


def polyline_segments(points: ArrayLike, closed: bool | ArrayLike) -> NDArray[np.float64]:
    """Segments of point sequences: points (B, m, 2), closed bool or (B,) -> (B, m, 2, 2) as
    (start, end). Segment j joins point j to point j + 1; the last one closes a ring (point m-1 to
    point 0) and is degenerate (the last point to itself) for an open polyline."""
    pts = _point_sets(points, "polyline_segments: points")
    closed_rows = np.broadcast_to(np.asarray(closed, dtype=bool), (pts.shape[0],))
    nxt = np.roll(pts, -1, axis=1)  # (B, m, 2)
    nxt[~closed_rows, -1] = pts[~closed_rows, -1]
    return np.stack([pts, nxt], axis=2)  # (B, m, 2, 2)


def point_to_segments(points: ArrayLike, segments: ArrayLike) -> NDArray[np.float64]:
    """Distance of every point to the nearest segment of every segment set (numpy, batched).

    points (A, n, 2), segments (B, m, 2, 2) as (start, end) (``polyline_segments``) -> (A, B, n)
    float64: out[a, b, i] = min_j dist(points[a, i], segment j of set b). Degenerate segments
    (start == end) count as points. Memory: works through chunks of A (about 2M point-segment pairs
    at a time).
    """
    p = _point_sets(points, "point_to_segments: points")
    seg = np.asarray(segments, dtype=np.float64)
    if seg.ndim != 4 or seg.shape[2:] != (2, 2):
        raise ValueError(
            f"point_to_segments: segments must have shape (B, m, 2, 2), got {seg.shape}"
        )
    num_b, m = seg.shape[:2]
    n = p.shape[1]
    out = np.empty((p.shape[0], num_b, n))  # (A, B, n)
    if m == 0:
        if out.size:
            raise ValueError("point_to_segments: segment sets must not be empty")
        return out
    sx, sy = seg[None, :, None, :, 0, 0], seg[None, :, None, :, 0, 1]  # (1, B, 1, m)
    dx = seg[None, :, None, :, 1, 0] - sx  # (1, B, 1, m)
    dy = seg[None, :, None, :, 1, 1] - sy
    dd = np.maximum(dx * dx + dy * dy, 1e-18)  # (1, B, 1, m)
    rows = max(1, 2_000_000 // max(1, num_b * n * m))  # chunk of A
    for r0 in range(0, p.shape[0], rows):
        px = p[r0 : r0 + rows, None, :, None, 0]  # (a, 1, n, 1)
        py = p[r0 : r0 + rows, None, :, None, 1]
        rx, ry = px - sx, py - sy  # (a, B, n, m)
        t = np.clip((rx * dx + ry * dy) / dd, 0.0, 1.0)  # (a, B, n, m)
        ox, oy = rx - t * dx, ry - t * dy  # (a, B, n, m)
        out[r0 : r0 + rows] = np.sqrt((ox * ox + oy * oy).min(axis=3))  # (a, B, n)
    return out
