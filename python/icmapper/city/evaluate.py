"""Cross-drive evaluation of a city run (GlobalMapNet's cross-scene protocol): the ground-truth
city map is the world's instances clipped to the union of every patch visited by every drive;
the city map is scored against it (CD per class, mCD, GAP per class, mGAP, as for one drive's
map); each drive's own run is evaluated as usual (its rows named by the drive).

Beside the city map, what is meaningful for the mode:
- ``merge``: every drive's map is that drive's alone, scored against its own ground truth; their
  mean per class is reported over the drives whose map holds the class (a drive without it has
  CD inf, counted as missing, never averaged), mCD the mean of those class means.
- ``continue``: a drive's map is the city map as it stood after that drive, which holds every
  earlier drive too: scoring it against one drive's ground truth means nothing, so per-drive
  maps are not scored (per-frame metrics are) and only the city map is."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from icmapper.city.manifest import CITY_MAP, read_manifest
from icmapper.city.run import city_sequences


def evaluate_city(city: str | os.PathLike) -> dict[str, Any]:
    """{"city": mapping metrics of the city map, "drives": per-drive results (evaluate_run; their
    "method" names the drive), "single_drive_mean": the drive maps' mean (``single_drive_mean``;
    None in continue mode), "method", "mode", "n_drives", "failed_drives"}."""
    from icmapper.data import gt as gt_mod
    from icmapper.data.types import PerceptionRange
    from icmapper.eval.detection import THRESHOLDS
    from icmapper.eval.evaluate import evaluate_run
    from icmapper.eval.globalmap import global_metrics, load_global_map

    city = Path(city)
    manifest = read_manifest(city)
    seqs = city_sequences(manifest)
    if not seqs:
        raise ValueError(f"{city}: no successful drive to evaluate")
    rng = PerceptionRange.from_name(manifest.range_name)
    gt = [
        (int(m.cls), np.asarray(m.points, np.float64), bool(m.closed))
        for m in gt_mod.city_gt(seqs, rng)
    ]
    pred = load_global_map(city / CITY_MAP)
    city_metrics = global_metrics([pred], [gt], THRESHOLDS[manifest.range_name])
    drives = []
    for d, seq in zip(manifest.ok_drives(), seqs, strict=True):
        r = evaluate_run(city / d.run, sources=[seq])
        r["drive"] = d.index
        r["method"] = f"{manifest.method} drive {d.index} {d.sequence}"
        if manifest.mode == "continue":  # the city so far, not this drive's map
            r["mapping"] = None
        drives.append(r)
    maps = [r["mapping"] for r in drives if r.get("mapping") is not None]
    updates = _updates(city)
    mean = single_drive_mean(maps) if manifest.mode != "continue" else None
    return {
        "method": manifest.method,
        "mode": manifest.mode,
        "range": manifest.range_name,
        "n_drives": len(seqs),
        "failed_drives": len(manifest.drives) - len(seqs),
        "city": city_metrics,
        "single_drive_mean": mean,
        "drives": drives,
        "updates": updates,
    }


def _updates(city: Path) -> list[dict[str, Any]]:
    """``update_eval.evaluate_update`` of every update of the city whose true changes are known
    (docs/eval.md, "City updates")."""
    from icmapper.city.update_eval import evaluate_update
    from icmapper.city.update_run import read_updates

    return [
        evaluate_update(city, k) for k, u in enumerate(read_updates(city).updates) if u.true_changes
    ]


def single_drive_mean(maps: list[dict[str, Any]]) -> dict[str, Any]:
    """The drive maps' mapping metrics (``global_metrics`` results) averaged per class over the
    drives whose CD of the class is finite: {"CD": {class: mean}, "mCD", "mGAP", "missing":
    {class: drives whose map lacks it (CD inf)}}; NaN where no drive has a value."""
    from icmapper.data.types import CLASS_NAMES

    def mean(values: list[float]) -> float:
        return float(np.mean(values)) if values else float("nan")

    cd = {n: mean([m["CD"][n] for m in maps if np.isfinite(m["CD"][n])]) for n in CLASS_NAMES}
    finite = [v for v in cd.values() if np.isfinite(v)]
    return {
        "CD": cd,
        "mCD": mean(finite),
        "mGAP": mean([m["mGAP"] for m in maps if np.isfinite(m["mGAP"])]),
        "missing": {n: sum(bool(np.isinf(m["CD"][n])) for m in maps) for n in CLASS_NAMES},
    }


def city_table(result: dict[str, Any]) -> str:
    """Markdown: the city map's CD per class, mCD and mGAP (the columns of every mapping table)
    beside what the mode makes meaningful (module docstring), with a line on what is left out."""
    from icmapper.eval.report import mapping_table

    rng = result["range"]
    rows = [
        {
            "method": f"city map ({result['n_drives']} drives, {result['mode']})",
            "range": rng,
            "mapping": result["city"],
        }
    ]
    mean = result["single_drive_mean"]
    if mean is not None:
        rows.append({"method": "single-drive maps (mean)", "range": rng, "mapping": mean})
        missing = [f"{k} lack {n}" for n, k in mean["missing"].items() if k]
        note = (
            f"Single-drive maps: each drive's own map against its own ground truth; drives whose "
            f"map lacks a class (CD inf) are left out of that class's mean: {', '.join(missing)}."
            if missing
            else "Single-drive maps: each drive's own map against its own ground truth."
        )
    else:
        note = (
            "Continue mode: each drive's map is the city map as it stood after that drive, so "
            "only the city map is scored (the drives' rows give per-frame metrics)."
        )
    from icmapper.city.update_eval import update_table

    updates = "".join(f"\n{update_table(u)}" for u in result.get("updates", []))
    return f"## City run: {result['method']}\n\n{mapping_table(rows)}\n\n{note}\n{updates}"
