"""Cross-drive evaluation of a city run (GlobalMapNet's cross-scene protocol): the ground-truth
city map is the world's instances clipped to the union of every patch visited by every drive;
the city map is scored against it (CD per class, mCD, GAP per class, mGAP, as for one drive's
map); each drive's own run is evaluated as usual, and the mean of the single-drive maps' mCD and
mGAP (each against its own drive's ground truth) is reported beside the city map's."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from icmapper.city.manifest import CITY_MAP, read_manifest
from icmapper.city.run import city_sequences


def evaluate_city(city: str | os.PathLike) -> dict[str, Any]:
    """{"city": mapping metrics of the city map, "drives": per-drive results (evaluate_run),
    "single_drive_mean": mean mCD / mGAP of the drive maps, "method", "mode", "n_drives"}."""
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
        drives.append(r)
    maps = [r["mapping"] for r in drives if "mapping" in r]
    mean = {
        "mCD": float(np.mean([m["mCD"] for m in maps])) if maps else float("nan"),
        "mGAP": float(np.mean([m["mGAP"] for m in maps])) if maps else float("nan"),
    }
    return {
        "method": manifest.method,
        "mode": manifest.mode,
        "n_drives": len(seqs),
        "failed_drives": len(manifest.drives) - len(seqs),
        "city": city_metrics,
        "single_drive_mean": mean,
        "drives": drives,
    }


def city_table(result: dict[str, Any]) -> str:
    """Markdown: the city map's CD per class, mCD and mGAP beside the single-drive mean."""
    from icmapper.data.types import CLASS_NAMES

    c = result["city"]
    head = "| map | " + " | ".join(f"CD_{n.split('_')[-1][:5]}" for n in CLASS_NAMES)
    head += " | mCD | mGAP |\n|---|" + "---|" * (len(CLASS_NAMES) + 2)
    cds = " | ".join(f"{c['CD'][n]:.3f}" for n in CLASS_NAMES)
    rows = [
        f"| city map ({result['n_drives']} drives, {result['mode']}) | {cds} | "
        f"{c['mCD']:.3f} | {100 * c['mGAP']:.1f} |",
        "| single-drive maps (mean) | "
        + " | ".join("" for _ in CLASS_NAMES)
        + f" | {result['single_drive_mean']['mCD']:.3f} | "
        f"{100 * result['single_drive_mean']['mGAP']:.1f} |",
    ]
    return f"## City run: {result['method']}\n\n{head}\n" + "\n".join(rows) + "\n"
