"""Long-run mapping: resident memory over a 10,000-frame drive (oracle detections, IC-Mapper with
positional association) through one synthetic city, sampled along the way. Once the map stops
growing (the drive keeps looping over mapped streets), memory must stay flat: no per-frame leak in
the engine, the tracker or the mapper.

``python -m benchmarks longrun [--frames 10000] [--every 500] [--city 10000]``

Prints frames, map instances, stored map points and resident memory (MB, /proc/self/statm) at
every sample, then the growth of memory over the second half of the run (when the map has stopped
growing) in MB and per 1,000 frames.
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
    grow = half[-1][3] - half[0][3]
    frames = half[-1][0] - half[0][0]
    inst = half[-1][1] - half[0][1]
    print(
        f"second half: RSS {half[0][3]:.1f} -> {half[-1][3]:.1f} MB ({grow:+.1f} MB, "
        f"{1000 * grow / max(frames, 1):+.2f} MB per 1,000 frames); map {inst:+d} instances; "
        f"{1e3 * rows[-1][4] / len(seq):.1f} ms per frame"
    )
    return 0 if np.isfinite(grow) else 1
