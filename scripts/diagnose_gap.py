"""Why a ground-truth instance is not matched in GAP: its nearest map instance, per true instance.

Reads the maps ``scripts/map_experiment.py --maps DIR`` wrote (``DIR/<method>/<drive>.icmap``)
and the global ground truth of the same drives. For each true instance of one class it finds
the map instance of that class with the smallest Chamfer distance as GAP measures it (both
sampled to 200 points along, ``eval.globalmap.gap_samples``; the mean of the two directed mean
distances) and prints, worst first, those above ``--show`` metres: the true length, the
distance and its two halves (true to map: the truth the instance leaves uncovered; map to true:
what it draws elsewhere), the instance's length and observations. A short true piece far from
everything is a sliver of the visited area; "true to map" large with "map to true" small is a
line the map holds in several pieces; both large, a line joined to another or missed. Prints
how many true instances have a match within 0.5, 1.0 and 1.5 m first (an upper bound of GAP's
recall at each threshold: matches are one-to-one there), and the same for the true lines that
lie on themselves (column U: a kerb around a median island, one instance up one side, round the
nose and down the other; within ``U_GAP`` metres of itself over more than ``U_LENGTH`` metres,
counting samples more than ``U_APART`` metres apart along it). Then how far the true lines lie
from the map, U and the others apart: the mean distance of their samples to the nearest map line
of the class (the coverage half of the class's CD, pooled over the drives:
``coverage``, which is ``eval.globalmap.sample_distances``).

    .venv/bin/python scripts/diagnose_gap.py --source sim:val:12 --maps /tmp/maps/icmapper --cls 2
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from icmapper.eval.globalmap import sample_distances as coverage

#: A true line lies on itself where a sample has another within this many metres ...
U_GAP = 4.0
#: ... at least this far along the line from it ...
U_APART = 8.0
#: ... over more than this many metres of its length.
U_LENGTH = 10.0


def lies_on_itself(points: np.ndarray) -> bool:
    """Whether a polyline (n, 2) comes back within ``U_GAP`` of itself over more than
    ``U_LENGTH`` metres (samples every 0.5 m, pairs more than ``U_APART`` apart along it)."""
    from scipy.spatial import cKDTree

    p = np.asarray(points, dtype=np.float64)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t = np.arange(0.0, cum[-1] + 1e-9, 0.5)  # (m,)
    d = np.stack([np.interp(t, cum, p[:, 0]), np.interp(t, cum, p[:, 1])], axis=1)  # (m, 2)
    near = cKDTree(d).query_ball_point(d, U_GAP)
    on_itself = sum(any(abs(t[j] - t[i]) > U_APART for j in js) for i, js in enumerate(near))
    return 0.5 * on_itself > U_LENGTH


def main(argv: list[str] | None = None) -> int:
    from icmapper.data import gt as gt_mod
    from icmapper.data.sources import open_source
    from icmapper.data.types import CLASS_NAMES, RANGE_60x30
    from icmapper.eval.globalmap import gap_samples, load_global_map
    from scipy.spatial import cKDTree

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", required=True)
    ap.add_argument("--maps", required=True, help="one method's folder of <drive>.icmap files")
    ap.add_argument("--cls", type=int, default=2, help="class index (0 crossing, 1, 2)")
    ap.add_argument("--show", type=float, default=1.0, help="list true instances above (m)")
    a = ap.parse_args(argv)
    if a.cls not in (0, 1, 2):
        raise SystemExit(f"--cls must be 0, 1 or 2, got {a.cls}")
    rows = []
    cover: dict[bool, list[np.ndarray]] = {True: [], False: []}  # lies on itself -> distances
    preds_of: dict[str, list] = {}  # drive -> its map's instances of the class
    for seq in open_source(a.source, render=False):
        path = Path(a.maps) / f"{seq.name}.icmap"
        if not path.exists():
            raise SystemExit(f"no map for drive {seq.name}: {path}")
        preds = preds_of[seq.name] = [p for p in load_global_map(path) if p[0] == a.cls]
        samples = [gap_samples(p[1], p[2]) for p in preds]  # each (200, 2)
        for g in gt_mod.global_gt(seq, RANGE_60x30):
            if int(g.cls) != a.cls:
                continue
            gs = gap_samples(g.points, g.closed)  # (200, 2)
            length = float(np.linalg.norm(np.diff(gs, axis=0), axis=1).sum())
            best = (np.inf, np.nan, np.nan, -1)
            for k, ps in enumerate(samples):
                to_map = float(cKDTree(ps).query(gs)[0].mean())
                to_true = float(cKDTree(gs).query(ps)[0].mean())
                if 0.5 * (to_map + to_true) < best[0]:
                    best = (0.5 * (to_map + to_true), to_map, to_true, k)
            u = not g.closed and lies_on_itself(g.points)
            rows.append((seq.name, length, *best, u))
            cover[u].append(coverage(g.points, [p[1] for p in preds], bool(g.closed)))
    rows.sort(key=lambda r: -r[2])
    name = CLASS_NAMES[a.cls]
    for what, sel in (("", rows), (" lying on themselves (U)", [r for r in rows if r[6]])):
        print(
            f"{len(sel)} true {name} instances{what}; nearest map instance within 0.5 / 1.0 / "
            "1.5 m: " + " / ".join(str(sum(r[2] <= t for r in sel)) for t in (0.5, 1.0, 1.5))
        )
    for what, u in (("lying on themselves (U)", True), ("the others", False)):
        d = np.concatenate(cover[u]) if cover[u] else np.zeros(0)
        print(
            f"true {name} instances {what}: their samples lie {d.mean() if len(d) else np.nan:.3f}"
            f" m from the map on average ({len(d)} samples, {np.mean(d > 1.0) if len(d) else 0:.1%}"
            " farther than 1 m)"
        )
    print(
        "| drive | true length m | U | Chamfer m | true to map | map to true | map length m | obs |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for drive, length, cd, to_map, to_true, k, u in rows:
        if cd <= a.show:
            break
        mark = "U" if u else ""
        if k < 0:
            print(f"| {drive} | {length:.1f} | {mark} | no map instance | | | | |")
            continue
        _, pts, _, obs = preds_of[drive][k]
        plen = float(np.linalg.norm(np.diff(np.asarray(pts), axis=0), axis=1).sum())
        print(
            f"| {drive} | {length:.1f} | {mark} | {cd:.2f} | {to_map:.2f} | {to_true:.2f} "
            f"| {plen:.1f} | {obs:.0f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
