"""Long-run mapping: resident memory over a 10,000-frame drive (oracle detections, IC-Mapper with
positional association) through one synthetic city, sampled along the way. Once the map stops
growing (the drive keeps looping over mapped streets), memory must stay flat: no per-frame leak in
the engine, the tracker or the mapper.

``python -m benchmarks longrun [--frames 10000] [--every 500] [--city 10000]``

Prints frames, map instances, stored map points and resident memory (MB, /proc/self/statm) at
every sample, then the trend of memory over the second half of the run (when the map has nearly
stopped growing): the least-squares slope of RSS against frames over every sample of that half,
in MB per 1,000 frames with its standard error, beside the map's growth in stored points — not
the difference of two end points, which the allocator's swings (several MB either way) decide.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def rss_mb() -> float:
    """Resident set size of this process in MB (Linux)."""
    with open("/proc/self/statm", encoding="ascii") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv: list[str] | None = None) -> int:
    from icmapper.data.sim import drive, generate_city, nuscenes_rig
    from icmapper.data.types import Sequence
    from icmapper.mapping.mapper import Mapper

    ap = argparse.ArgumentParser(prog="python -m benchmarks longrun", description=__doc__)
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--every", type=int, default=500)
    ap.add_argument("--city", type=int, default=10_000)
    args = ap.parse_args(argv)
    world = generate_city(args.city)
    ts, poses = drive(world, 0, duration_s=args.frames / 2.0)
    seq = Sequence(f"long-{args.city}", "sim", world, ts, poses, nuscenes_rig((32, 88)))
    mapper = Mapper.with_oracle(seq, noise="low", seed=0)
    mapper.source.detect(seq.frame(0, with_images=False))  # precomputes the drive's ground truth
    rows = []
    t0 = time.perf_counter()
    for i in range(len(seq)):
        mapper.step(seq.frame(i, with_images=False))
        if i % args.every == 0 or i == len(seq) - 1:
            gm = mapper.global_map
            pts = sum(gm.info(int(j))["n_points"] for j in gm.ids())
            rows.append((i + 1, len(gm), pts, rss_mb(), time.perf_counter() - t0))
    print(f"{len(seq)} frames of sim city {args.city}, oracle:low, IC-Mapper (positional)")
    print(f"{'frames':>7} {'instances':>9} {'points':>8} {'RSS MB':>8} {'seconds':>8}")
    for f, n, p, r, s in rows:
        print(f"{f:7d} {n:9d} {p:8d} {r:8.1f} {s:8.1f}")
    half = [r for r in rows if r[0] >= len(seq) // 2]
    slope, err = rss_slope([r[0] for r in half], [r[3] for r in half])
    print(
        f"second half (frames {half[0][0]}-{half[-1][0]}, {len(half)} samples): RSS slope "
        f"{1000 * slope:+.2f} +- {1000 * err:.2f} MB per 1,000 frames (least squares; RSS "
        f"{min(r[3] for r in half):.1f}-{max(r[3] for r in half):.1f} MB); map "
        f"{half[-1][1] - half[0][1]:+d} instances, {half[-1][2] - half[0][2]:+d} stored points; "
        f"{1e3 * rows[-1][4] / len(seq):.1f} ms per frame"
    )
    return 0 if np.isfinite(slope) else 1


def rss_slope(frames: list[int], rss: list[float]) -> tuple[float, float]:
    """Least-squares slope of ``rss`` (MB) against ``frames`` in MB per frame, and its standard
    error (nan with fewer than 3 samples)."""
    x, y = np.asarray(frames, np.float64), np.asarray(rss, np.float64)  # (n,), (n,)
    if len(x) < 2:
        return float("nan"), float("nan")
    slope, intercept = np.polyfit(x, y, 1)
    if len(x) < 3:
        return float(slope), float("nan")
    resid = y - (slope * x + intercept)  # (n,)
    err = np.sqrt(resid @ resid / (len(x) - 2) / np.sum((x - x.mean()) ** 2))
    return float(slope), float(err)
