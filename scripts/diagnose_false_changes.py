"""What lies under the city updates' false changes? For every reported change that matches no true
one (issue 32's evaluation, ``city.update_eval.match_changes``), the nearest true change of any
type and class and its distance (``change_distance``, the rule the matching uses), counted by
the false change's type and class and the nearest true change's type and class.

Reads the update folders ``city_update_experiment.py --work DIR`` leaves (``DIR/*-u*``): the
reported ``changes.geojson`` and the ``true_changes.json`` of each update.

    OMP_NUM_THREADS=1 .venv/bin/python scripts/city_update_experiment.py --detections learned \
        --cities 3 4 5 --seeds 0 1 --work /tmp/upd
    .venv/bin/python scripts/diagnose_false_changes.py /tmp/upd

``--moves`` also lists every reported lane-line move, true or false (and the nearest true change of
a false one), with its offset (metres, sideways) and evidence (frames expected, seen, missed).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path


def main() -> None:
    from icmapper.city.changes_report import read_changes
    from icmapper.city.update_eval import change_distance, match_changes
    from icmapper.data.sim.changes import TrueChange
    from icmapper.data.types import CLASS_NAMES

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("work", type=Path, help="the --work folder of city_update_experiment.py")
    ap.add_argument("--near", type=float, default=4.0, help="metres: 'near' a true change")
    ap.add_argument("--moves", action="store_true", help="list every reported lane-line move")
    a = ap.parse_args()
    moves: list[str] = []
    counts: Counter[tuple[str, str]] = Counter()
    total: Counter[str] = Counter()
    for upd in sorted(a.work.glob("*-u*")):
        folder = sorted((upd / "updates").iterdir())[-1]
        text = (folder / "true_changes.json").read_text("utf-8")
        truth = [TrueChange.from_json(c) for c in json.loads(text)["changes"]]
        listed = read_changes(folder / "changes.geojson")
        raw = json.loads((folder / "changes.geojson").read_text("utf-8"))["features"]
        props = [f["properties"] for f, r in zip(raw, listed, strict=True) if r["cause"] == "road"]
        reported = [r for r in listed if r["cause"] == "road"]
        hit = {r for r, _, _ in match_changes(reported, truth)}
        for i, rep in enumerate(reported):
            if rep["change"] == "moved" and rep["cls"] == 1:
                ev = props[i]["evidence"]
                near = min(
                    ((change_distance(rep["points"], False, t.points, t.closed), t) for t in truth),
                    key=lambda x: x[0],
                    default=(float("inf"), None),
                )
                what = "true" if i in hit else f"false, nearest {near[1].change} at {near[0]:.1f} m"
                moves.append(
                    f"| {upd.name} | {what} | {props[i]['offset']:+.2f} | {ev['expected']} "
                    f"| {ev['seen']} | {ev['missed']} |"
                )
            if i in hit:
                continue
            kind = f"{rep['change']} {CLASS_NAMES[rep['cls']]}"
            total[kind] += 1
            near = [
                (change_distance(rep["points"], rep["closed"], t.points, t.closed), t)
                for t in truth
            ]
            d, t = min(near, key=lambda x: x[0]) if near else (float("inf"), None)
            what = f"{t.change} {CLASS_NAMES[t.cls]}" if t is not None and d <= a.near else "none"
            counts[(kind, what)] += 1
    print(f"| false change | n | nearest true change within {a.near:g} m: count |")
    print("|---|---|---|")
    for kind, n in sorted(total.items()):
        mine = sorted(((c, what) for (k, what), c in counts.items() if k == kind), reverse=True)
        near_txt = ", ".join(f"{what} {c}" for c, what in mine)
        print(f"| {kind} | {n} | {near_txt} |")
    if a.moves:
        print("\n| update | lane-line move | offset m | expected | seen | missed |")
        print("|---|---|---|---|---|---|")
        print("\n".join(sorted(moves, key=lambda m: m.split("|")[2])))


if __name__ == "__main__":
    main()
