"""Does the learned detector see a changed lane line where the paint is, or where the lanes are?

For the drives of ``sim-city-changed:val:CITY:3:SEED`` (issue 32's city updates), every frame's
detections are compared with each true lane-line change in range (at least 4 m of it inside the
range shrunk by 1 m): the share of its in-range points within a gate of a detected divider. Printed
per kind, averaged over the frames and changes: a removed line still detected (0.75 m), an added
line detected (0.6 m: it lies 1.5-1.9 m beside another), a moved line detected at its new place
and at its old one (0.5 m).

    OMP_NUM_THREADS=1 .venv/bin/python scripts/diagnose_changes.py --checkpoint CKPT \
        --cities 0 1 2 --seeds 0 1
"""

from __future__ import annotations

import argparse

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

GATES = {"removed": 0.75, "added": 0.6, "moved": 0.5}
LABELS = {
    "removed": "a removed line still detected",
    "added": "an added line detected",
    "moved": "a moved line detected at its new place",
}


def _dense(points: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    from icmapper.data.sim.geometry import arc_length, sub_curve

    return sub_curve(points, 0.0, float(arc_length(points)[-1]), step)  # (m, 2)


def _covered(line: NDArray[np.float64], tree: cKDTree | None, half: NDArray, gate: float):
    """Share of the in-range points of ``line`` (ego frame) within ``gate`` of a detection
    point; None when under 4 m of it is in range."""
    inside = np.all(np.abs(line) < half - 1.0, axis=1)  # (m,)
    if inside.sum() < 8:  # points every 0.5 m
        return None
    if tree is None:
        return 0.0
    d, _ = tree.query(line[inside])
    return float(np.mean(d < gate))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--checkpoint", default=None, help="default: the shipped one")
    ap.add_argument("--cities", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    a = ap.parse_args()

    from icmapper.checkpoints import DEFAULT_CHECKPOINT
    from icmapper.data.sim.changes import changed_city_drives
    from icmapper.data.types import MapClass, RANGE_60x30, world_to_ego
    from icmapper.mapping.mapper import Mapper
    from icmapper.models.network import checkpoint_settings

    ckpt = str(a.checkpoint or DEFAULT_CHECKPOINT)
    source = Mapper.from_checkpoint(ckpt).source
    size = checkpoint_settings(ckpt)[1]
    half = np.array([RANGE_60x30.half_x, RANGE_60x30.half_y])
    stats: dict[str, list[float]] = {}
    for city in a.cities:
        for seed in a.seeds:
            seqs, changes = changed_city_drives("val", city, 3, seed, image_size=size)
            lines = [c for c in changes if c.cls == MapClass.DIVIDER]
            for seq in seqs:
                source.reset()
                for i in range(len(seq)):
                    frame = seq.frame(i, with_images=True)
                    det = source.detect(frame)
                    div = det.points[det.classes == int(MapClass.DIVIDER)]  # (k, 20, 2) ego
                    pts = [_dense(np.asarray(p, np.float64), 0.25) for p in div]
                    tree = cKDTree(np.concatenate(pts)) if pts else None
                    for c in lines:
                        gate = GATES[c.change]
                        now = world_to_ego(_dense(c.points, 0.5), frame.pose)
                        v = _covered(now, tree, half, gate)
                        if v is not None:
                            stats.setdefault(LABELS[c.change], []).append(v)
                        if c.before is not None:
                            old = world_to_ego(_dense(c.before, 0.5), frame.pose)
                            w = _covered(old, tree, half, gate)
                            if w is not None:
                                key = "a moved line detected at its former place"
                                stats.setdefault(key, []).append(w)
    print(f"checkpoint {ckpt}; val cities {a.cities}, change seeds {a.seeds}")
    for k in sorted(stats):
        print(
            f"{k}: {np.mean(stats[k]):.2f} of the points detected ({len(stats[k])} frame-changes)"
        )


if __name__ == "__main__":
    main()
