"""Python-side geometry: the engine (``icmapper.geom``, Rust) against batched numpy forms.

``icmapper.geom`` takes the engine's function where the engine has one and keeps numpy only where
it has none or where numpy is measured faster. This program measures each such choice in one run
and prints the ratio (values are checked to agree before timing):

1. resampling a table of instances to 200 points (the evaluation protocol): ``geom.resample_many``
   (one engine call per row) vs the vectorised numpy resampler the evaluation used before (kept
   here as the reference: one ``searchsorted`` over the whole table);
2. exact Chamfer distance of paired 200-point sets (the evaluation's exact stage):
   ``geom.chamfer_pairs`` with the engine vs its numpy backend (``paired_nearest_sq``, batched);
3. Chamfer matrices of small sets (ground-truth id linking, 20-point pieces):
   ``geom.chamfer_matrix`` (engine) vs ``scipy.spatial.distance.cdist`` per pair (the former
   ``gt.chamfer``);
4. Chamfer distance of point clouds (the global-map CD metric): a k-d tree (scipy) vs
   ``geom.chamfer_distance`` (engine, all pairs) — ``geom.cloud_chamfer`` switches from the engine
   to the k-d tree above ``geom.CLOUD_ENGINE_PAIRS`` point pairs;
5. numpy-only forms (no engine equivalent), timed for reference: ``point_to_segments`` (tracker
   affinity) and ``paired_nearest_sq`` on the 41-point coarse sets (evaluation pruning bound).

Run: ``.venv/bin/python -m benchmarks python-geometry [--rows 20000] [--pairs 2000]
[--clouds 300 1000 3000 20000] [--repeat 3]``.
Medians of ``--repeat`` runs; single-threaded numpy is not enforced (set OMP_NUM_THREADS=1 for
stable numbers on a shared machine).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable

import numpy as np
from icmapper import geom
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist


def _median_time(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def numpy_resample(points: NDArray[np.float64], num: int, closed: NDArray[np.bool_]) -> NDArray:
    """The vectorised numpy resampler the evaluation used before (reference): points (N, n, 2),
    closed (N,) -> (N, num, 2); open rows at j / (num - 1), closed rows at j / num of the length."""
    n_rows, n = points.shape[:2]
    frac_open, frac_closed = np.linspace(0.0, 1.0, num), np.arange(num) / num  # (num,), (num,)
    tail = np.where(closed[:, None], points[:, 0], points[:, -1])  # (N, 2)
    ext = np.concatenate([points, tail[:, None]], axis=1)  # (N, n + 1, 2)
    seg = np.linalg.norm(np.diff(ext, axis=1), axis=-1)  # (N, n)
    cum = np.concatenate([np.zeros((n_rows, 1)), np.cumsum(seg, axis=1)], axis=1)  # (N, n + 1)
    length = cum[:, -1]  # (N,)
    target = np.where(closed[:, None], frac_closed[None], frac_open[None]) * length[:, None]
    shift = (np.arange(n_rows) * (length.max() + 1.0))[:, None]  # (N, 1)
    pos = np.searchsorted((cum[:, 1:] + shift).ravel(), (target + shift).ravel(), side="right")
    idx = np.minimum(pos.reshape(n_rows, num) - (np.arange(n_rows) * n)[:, None], n - 1)
    flat = idx + (np.arange(n_rows) * (n + 1))[:, None]  # (N, num) rows into ext
    seg_len = seg.ravel()[flat - np.arange(n_rows)[:, None]]  # (N, num)
    start = cum.ravel()[flat]  # (N, num)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.where(seg_len > 0, (target - start) / seg_len, 0.0), 0.0, 1.0)[..., None]
    ext_flat = ext.reshape(-1, 2)
    return ext_flat[flat] + t * (ext_flat[flat + 1] - ext_flat[flat])  # (N, num, 2)


def _cdist_chamfer(a: NDArray, b: NDArray) -> float:
    d = cdist(a, b)  # (n, m)
    return float((d.min(axis=1).mean() + d.min(axis=0).mean()) / 2.0)


def _kd_chamfer(a: NDArray, b: NDArray) -> float:
    """Chamfer distance by k-d tree (``geom.cloud_chamfer``'s path for large clouds)."""
    dab, _ = cKDTree(b).query(a)  # (n,)
    dba, _ = cKDTree(a).query(b)  # (m,)
    return 0.5 * (float(dab.mean()) + float(dba.mean()))


def _row(name: str, t_numpy: float, t_engine: float, numpy_label: str, engine_label: str) -> None:
    faster = "engine" if t_engine < t_numpy else "numpy"
    ratio = max(t_numpy, t_engine) / max(min(t_numpy, t_engine), 1e-12)
    print(
        f"{name:44s} {numpy_label} {t_numpy * 1e3:9.2f} ms   "
        f"{engine_label} {t_engine * 1e3:9.2f} ms   -> {faster} {ratio:.1f}x faster"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks python-geometry", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--rows", type=int, default=20_000, help="instances in the resampling table")
    ap.add_argument("--pairs", type=int, default=2_000, help="200-point pairs, exact Chamfer")
    ap.add_argument(
        "--clouds", type=int, nargs="+", default=[300, 1_000, 3_000, 20_000], help="cloud sizes"
    )
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    rep = args.repeat

    # 1. Resampling a table (20-point network instances -> 200 protocol points).
    pts = np.cumsum(rng.normal(size=(args.rows, 20, 2)), axis=1)  # (N, 20, 2)
    closed = rng.random(args.rows) < 0.3  # (N,)
    ref, ours = numpy_resample(pts, 200, closed), geom.resample_many(pts, 200, closed)
    diff = float(np.abs(ref - ours).max())
    t_np = _median_time(lambda: numpy_resample(pts, 200, closed), rep)
    t_en = _median_time(lambda: geom.resample_many(pts, 200, closed), rep)
    _row(f"resample {args.rows} x 20 -> 200 points", t_np, t_en, "numpy", "resample_many")
    print(f"{'':44s} largest difference {diff:.1e} m")

    # 2. Exact Chamfer of paired 200-point sets.
    a, b = ours[: args.pairs], ours[args.pairs : 2 * args.pairs]  # (P, 200, 2) each
    diff = float(np.abs(geom.chamfer_pairs(a, b, "numpy") - geom.chamfer_pairs(a, b)).max())
    t_np = _median_time(lambda: geom.chamfer_pairs(a, b, "numpy"), rep)
    t_en = _median_time(lambda: geom.chamfer_pairs(a, b, "engine"), rep)
    _row(f"chamfer_pairs {a.shape[0]} pairs of 200 points", t_np, t_en, "numpy", "engine")
    print(f"{'':44s} largest difference {diff:.1e} m")

    # 3. Chamfer matrices of small sets (GT piece linking: members x previous pieces).
    sets = [np.cumsum(rng.normal(size=(20, 2)), axis=0) for _ in range(40)]  # 40 x (20, 2)
    left, right = sets[:20], sets[20:]

    def cdist_matrix() -> NDArray:
        return np.array([[_cdist_chamfer(p, q) for q in right] for p in left])  # (20, 20)

    diff = float(np.abs(cdist_matrix() - geom.chamfer_matrix(left, right)).max())
    t_np = _median_time(cdist_matrix, rep * 10)
    t_en = _median_time(lambda: geom.chamfer_matrix(left, right), rep * 10)
    _row("chamfer matrix 20 x 20 sets of 20 points", t_np, t_en, "cdist", "engine")
    print(f"{'':44s} largest difference {diff:.1e} m")

    # 4. Large clouds (global-map CD: up to 200,000 points per class and side).
    for n in args.clouds:
        ca = rng.uniform(0, 500, size=(n, 2))  # (n, 2)
        cb = ca + rng.normal(0, 0.3, size=(n, 2))  # (n, 2)
        diff = abs(_kd_chamfer(ca, cb) - geom.chamfer_distance(ca, cb))
        t_kd = _median_time(lambda ca=ca, cb=cb: _kd_chamfer(ca, cb), rep)
        t_en = _median_time(lambda ca=ca, cb=cb: geom.chamfer_distance(ca, cb), rep)
        faster = "k-d tree" if t_kd < t_en else "engine"
        ratio = max(t_kd, t_en) / max(min(t_kd, t_en), 1e-12)
        print(
            f"{f'cloud chamfer {n} x {n} points':44s} k-d tree {t_kd * 1e3:9.2f} ms   "
            f"engine {t_en * 1e3:9.2f} ms   -> {faster} {ratio:.1f}x faster "
            f"(difference {diff:.1e} m)"
        )

    # 5. numpy-only forms.
    det, trk = pts[:50], pts[50:100]  # (50, 20, 2) each
    segs = geom.polyline_segments(trk, closed[50:100])  # (50, 20, 2, 2)
    t = _median_time(lambda: geom.point_to_segments(det, segs), rep)
    print(f"{'point_to_segments 50 x 50 sets of 20 points':44s} numpy {t * 1e3:9.2f} ms")
    coarse_a, coarse_b = a[:, ::5], b[:, ::5]  # (P, 40, 2)
    t = _median_time(lambda: geom.paired_nearest_sq(coarse_a, coarse_b), rep)
    label = f"paired_nearest_sq {a.shape[0]} pairs of 40 points"
    print(f"{label:44s} numpy {t * 1e3:9.2f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
