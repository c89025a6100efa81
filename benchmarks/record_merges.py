"""Records the merges of the geometry benchmark's workload for the Rust replay tool.

Runs the per-frame workload of ``python -m benchmarks geometry`` (1000-instance synthetic city,
200 frames, ~30 noisy detections per frame) through ``GlobalMap`` and writes, for every merge,
the stored geometry before it and the detection: little-endian
``int64 cls, int64 n_global, int64 n_det``, then ``float64 global (n_global, 2)`` and
``float64 det (n_det, 2)``.

Run (repository root): ``.venv/bin/python -m benchmarks.record_merges /tmp/merges.bin`` then
``cargo run --release -p icmap-geom --example replay_merges -- /tmp/merges.bin 5``.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np

from benchmarks import geometry as bench


def record(path: Path, n: int = 1000, frames: int = 200, seed: int = 0) -> int:
    instances = bench.city_instances(n, seed)
    gm = bench._engine_map(instances)
    poses = bench.random_poses(instances, frames, seed + 1)
    rng = np.random.default_rng(seed + 2)
    count = 0
    tmp = path.with_suffix(path.suffix + ".tmp")
    with tmp.open("wb") as out:
        for pose in poses:
            for i, det in bench.detections_for(gm, pose, rng):
                cls, glob = gm.get(i)
                out.write(struct.pack("<qqq", cls, len(glob), len(det)))
                out.write(np.ascontiguousarray(glob, dtype="<f8").tobytes())
                out.write(np.ascontiguousarray(det, dtype="<f8").tobytes())
                gm.merge(i, det, frame=1)
                count += 1
    tmp.replace(path)
    return count


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    print(record(Path(sys.argv[1])), "merges written to", sys.argv[1])
