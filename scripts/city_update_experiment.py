"""City-update experiment (issue 32): the numbers of docs/mapping.md, "Updating a city map".

For each city and detections: a city map is built from the drives of ``sim-city:val:CITY:N``,
then, for each change seed, a copy of it is updated with ``sim-city-changed:val:CITY:N:SEED``
(the same routes after changes) and the update is evaluated against the true changes
(``city.update_eval``). Prints the pooled precision / recall / F1 per change type and class,
the unchanged instances wrongly changed, the TbV frame accuracy and the maps' mCD / mGAP
(updated, never updated, from scratch) averaged over the updates; ``--json`` writes them.

    OMP_NUM_THREADS=1 .venv/bin/python scripts/city_update_experiment.py \
        --detections oracle:low oracle:medium --cities 0 1 --seeds 0 1 2 3 4
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def run(
    detections: str,
    cities: list[int],
    seeds: list[int],
    drives: int,
    work: Path,
    checkpoint: str | None = None,
    update: dict[str, Any] | None = None,
) -> dict:
    from icmapper.city.drives import CitySettings
    from icmapper.city.run import build_city
    from icmapper.city.update import UpdateConfig
    from icmapper.city.update_eval import CHANGE_TYPES, evaluate_update
    from icmapper.city.update_run import update_city
    from icmapper.data.types import CLASS_NAMES
    from icmapper.mapping.config import MapperConfig

    if detections != "learned":
        checkpoint = None
    elif checkpoint is None:
        from icmapper.checkpoints import DEFAULT_CHECKPOINT

        checkpoint = str(DEFAULT_CHECKPOINT)
    size = (64, 176)
    results = []
    for city in cities:
        base = work / f"base-{detections.replace(':', '-')}-{city}"
        # what `icmapper map --city` maps with: the checkpoint's [mapper] table when learned
        config = MapperConfig.for_checkpoint(checkpoint) if checkpoint else MapperConfig()
        settings = CitySettings("icmapper", detections, checkpoint, config.to_dict(), size)
        if not base.exists():
            build_city(base, [f"sim-city:val:{city}:{drives}"], settings, "60x30",
                       pictures=False, log=lambda *_: None, progress=False)  # fmt: skip
        for seed in seeds:
            upd = work / f"{base.name}-u{seed}"
            shutil.rmtree(upd, ignore_errors=True)
            shutil.copytree(base, upd)
            spec = f"sim-city-changed:val:{city}:{drives}:{seed}"
            update_city(upd, [spec], detections, checkpoint, image_size=size,
                        config=UpdateConfig(**(update or {})), log=lambda *_: None,
                        progress=False)  # fmt: skip
            r = evaluate_update(upd, image_size=size)
            r["city"], r["seed"] = city, seed
            results.append(r)
            by = r["changes"]["by_type"]
            print(
                f"{detections} city {city} seed {seed}: "
                + ", ".join(f"{t} {by[t]['tp']}/{by[t]['fp']}/{by[t]['fn']}" for t in CHANGE_TYPES)
                + f", wrong {100 * r['wrongly_changed']:.1f} %, mCD "
                + "/".join(f"{r['maps'][k]['mCD']:.3f}" for k in r["maps"]),
                flush=True,
            )
    pooled: dict[str, Any] = {}
    for t in CHANGE_TYPES:
        for name in ("all", *CLASS_NAMES):
            tp = fp = fn = 0
            for r in results:
                s = (
                    r["changes"]["by_type"][t]
                    if name == "all"
                    else r["changes"]["by_class"][t][name]
                )
                tp, fp, fn = tp + s["tp"], fp + s["fp"], fn + s["fn"]
            if tp + fp + fn:
                p = tp / (tp + fp) if tp + fp else float("nan")
                rc = tp / (tp + fn) if tp + fn else float("nan")
                f1 = 2 * p * rc / (p + rc) if tp else 0.0
                pooled[f"{t}/{name}"] = {"tp": tp, "fp": fp, "fn": fn, "p": p, "r": rc, "f1": f1}
    maps = {
        k: {m: float(np.mean([r["maps"][k][m] for r in results])) for m in ("mCD", "mGAP")}
        for k in results[0]["maps"]
    }
    return {
        "detections": detections,
        "updates": len(results),
        "pooled": pooled,
        "wrongly_changed": float(np.mean([r["wrongly_changed"] for r in results])),
        "wrongly_removed": float(np.mean([r["wrongly_removed"] for r in results])),
        "mAcc": float(np.nanmean([r["frames"]["mAcc"] for r in results])),
        "accuracy": float(np.nanmean([r["frames"]["accuracy"] for r in results])),
        "maps": maps,
        "runs": results,
    }


def _update_setting(text: str) -> tuple[str, Any]:
    """NAME=VALUE of an ``UpdateConfig`` field: a number, or per-class numbers "a,b,c"."""
    name, _, value = text.partition("=")
    nums = tuple(float(v) for v in value.split(","))
    return name, nums if len(nums) > 1 else nums[0]


def table(out: dict) -> str:
    lines = [
        f"### {out['detections']} ({out['updates']} updates)",
        "",
        "| Change / class | TP | FP | FN | Precision | Recall | F1 |",
        "|---|---|---|---|---|---|---|",
    ]
    for k, s in out["pooled"].items():
        lines.append(
            f"| {k} | {s['tp']} | {s['fp']} | {s['fn']} | {s['p']:.2f} | {s['r']:.2f} | "
            f"{s['f1']:.2f} |"
        )
    m = out["maps"]
    lines += [
        "",
        f"Unchanged instances wrongly changed {100 * out['wrongly_changed']:.2f} % (wrongly "
        f"removed {100 * out['wrongly_removed']:.2f} %); frames: accuracy "
        f"{out['accuracy']:.3f}, mAcc {out['mAcc']:.3f}.",
        "",
        "| Map | mCD | mGAP |",
        "|---|---|---|",
    ]
    for k, v in m.items():
        lines.append(f"| {k} | {v['mCD']:.3f} | {100 * v['mGAP']:.1f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--detections", nargs="+", default=["oracle:low", "oracle:medium"])
    ap.add_argument("--cities", nargs="+", type=int, default=[0, 1])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    ap.add_argument("--drives", type=int, default=3)
    ap.add_argument(
        "--checkpoint", default=None, help="for learned detections (default: the shipped one)"
    )
    ap.add_argument(
        "--update",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="an UpdateConfig setting (per class: a,b,c; e.g. remove_drop=inf,inf,inf)",
    )
    ap.add_argument(
        "--work", default=None, help="folder for the city runs, kept (default: a temporary one)"
    )
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    outs = []
    with tempfile.TemporaryDirectory(prefix="city-update-") as temporary:
        work = Path(args.work or temporary)
        for det in args.detections:
            update = dict(_update_setting(t) for t in args.update)
            out = run(det, args.cities, args.seeds, args.drives, work, args.checkpoint, update)
            print(table(out))
            outs.append(out)
    if args.json:
        Path(args.json).write_text(json.dumps(outs, indent=1, default=float))


if __name__ == "__main__":
    main()
