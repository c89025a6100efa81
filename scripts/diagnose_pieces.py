"""Why a global map holds more instances than the road: each extra piece, attributed to a cause.

Reads the maps ``scripts/map_experiment.py --maps DIR`` wrote (``DIR/<method>/<drive>.icmap``)
and the ground truth of the same drives, and sorts every map instance beyond the first one on a
ground-truth instance into causes (each piece counted once, the first cause that fits):

- ``stray across``: at most half of it within ``GATE`` of the ground truth of its class, running
  across the nearest true line (more than 45 degrees): a stub across lanes;
- ``stray other``: at most half of it on the ground truth, not across (a phantom, a wrong class);
- ``duplicate, same frames``: it lies on another piece of the same true instance over more than
  half of its length (a copy) and the two were observed in overlapping frames: two detections
  of one frame (two skeleton branches of one mask, a doubled kerb);
- ``duplicate, later track``: the same, observed in frames after the other's: a lost track found
  again and not re-identified;
- ``end to end``: it continues another piece of the same true instance (overlapping it over less
  than half of either): a line cut where a skeleton branch ends or where a track was lost;
- ``crossing split``: a crossing beside another piece of the same crossing.

A piece is "on" a true instance when more than half of its samples lie within ``GATE`` of it (the
true instance nearest to the most of them). Prints one table, one row per method, counts per
cause and class (crossings / dividers / boundaries).

    .venv/bin/python scripts/diagnose_pieces.py --source sim:val:12 --maps /tmp/maps
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

GATE = 1.0
CAUSES = (
    "stray across",
    "stray other",
    "duplicate, same frames",
    "duplicate, later track",
    "end to end",
    "crossing split",
)


def _direction(pts: np.ndarray) -> np.ndarray:
    d = pts[-1] - pts[0]
    n = np.linalg.norm(d)
    return d / n if n > 0 else np.array([1.0, 0.0])


def diagnose(map_path: Path, gt: list) -> Counter:
    from icmapper import GlobalMap
    from icmapper.eval.fragmentation import _Shape

    gm = GlobalMap.load(str(map_path))
    out: Counter = Counter()
    for c in range(3):
        truth = [_Shape(g.points, g.closed) for g in gt if int(g.cls) == c]
        pieces = []  # (id, shape, info, owner)
        for i in gm.ids():
            cls, pts = gm.get(int(i))
            if cls != c:
                continue
            s = _Shape(pts, c == 0)
            on = np.array([t.near(s.samples, GATE).mean() for t in truth]) if truth else np.zeros(0)
            owner = int(on.argmax()) if len(on) and on.max() > 0.5 else -1
            pieces.append((int(i), s, gm.info(int(i)), owner))
        by_owner: dict[int, list] = {}
        for p in pieces:
            if p[3] < 0:
                across = False
                if truth and c != 0:
                    d = [float(np.min(np.linalg.norm(t.samples - p[1].samples.mean(0), axis=1)))
                         for t in truth]  # fmt: skip
                    t = truth[int(np.argmin(d))]
                    k = np.linalg.norm(t.samples - p[1].samples.mean(0), axis=1).argmin()
                    lo, hi = max(k - 4, 0), min(k + 5, len(t.samples))
                    cos = abs(_direction(p[1].samples) @ _direction(t.samples[lo:hi]))
                    across = cos < np.cos(np.radians(45))
                out["stray across" if across else "stray other", c] += 1
            else:
                by_owner.setdefault(p[3], []).append(p)
        for group in by_owner.values():
            group.sort(key=lambda p: -len(p[1].samples))  # the longest is the instance itself
            for p in group[1:]:
                if c == 0:
                    out["crossing split", c] += 1
                    continue
                cause = "end to end"
                for q in group:
                    if q is p or q[1].near(p[1].samples, GATE).mean() <= 0.5:
                        continue
                    later = p[2]["first_frame"] > q[2]["last_frame"]
                    cause = "duplicate, later track" if later else "duplicate, same frames"
                    break
                out[cause, c] += 1
    return out


def main(argv: list[str] | None = None) -> int:
    from icmapper.data import gt as gt_mod
    from icmapper.data.sources import open_source
    from icmapper.data.types import RANGE_60x30

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", required=True)
    ap.add_argument("--maps", required=True, help="the --maps folder of map_experiment.py")
    a = ap.parse_args(argv)
    seqs = open_source(a.source, render=False)
    gts = {s.name: gt_mod.global_gt(s, RANGE_60x30) for s in seqs}
    print("| method | " + " | ".join(CAUSES) + " | extra pieces |")
    print("|---" * (len(CAUSES) + 2) + "|")
    for d in sorted(Path(a.maps).iterdir()):
        total: Counter = Counter()
        for name, gt in gts.items():
            path = d / f"{name}.icmap"
            if not path.exists():
                raise SystemExit(f"{path} is missing: map the same source with --maps first")
            total += diagnose(path, gt)
        cells = ["/".join(str(total[cause, c]) for c in range(3)) for cause in CAUSES]
        n = sum(total.values())
        print(f"| {d.name} | " + " | ".join(cells) + f" | {n} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
