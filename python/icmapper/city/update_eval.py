"""Evaluation of a city update against the true changes (docs/eval.md, "City updates").

- Changes: a reported change matches a true one of the same type and class when their
  geometries lie within ``MATCH_DISTANCE`` (1.5 m) of each other: the smaller of the two directed
  mean distances (each point of one to the other's polyline, or ring for a crossing), so that a
  change the map holds only in part (the drives saw part of a long line) still matches; one to
  one, nearest first. Precision, recall and F1 per type and class and per type; *wrongly
  changed*: removals and moves that match no true change, as a share of the instances of the
  map before the update (``wrongly_removed`` the same for removals alone).
- Frames (after Argoverse's "Trust, but Verify"): a frame of the update's drives *holds a change*
  when a change's geometry (after, and before for a move) has >= 3 points inside the frame's
  range shrunk by 1 m (points every 0.5 m); the report's changes are scored against the true
  ones per frame: accuracy over frames, the accuracy on frames with and without a true change,
  and their mean (TbV's mAcc).
- Maps: the updated map, the never-updated map (``before.icmap``) and a map built from scratch
  from the update's drives (the city's method and the update's detections, merge mode) against
  the changed world's ground truth over the patches the update's drives visited: CD per class,
  mCD, mGAP (``eval.globalmap.global_metrics``).
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import CHANGE_TYPES, CLASS_NAMES, PerceptionRange

#: A reported change matches a true one within this distance (m).
MATCH_DISTANCE = 1.5


def _to_lines(pts: NDArray[np.float64], closed: bool) -> NDArray[np.float64]:
    return np.vstack([pts, pts[:1]]) if closed else pts


def change_distance(
    a: NDArray[np.float64], a_closed: bool, b: NDArray[np.float64], b_closed: bool
) -> float:
    """The smaller of the mean distances of a's points (n, 2) to b's line and of b's points to
    a's line (rings closed)."""
    from icmapper import geom

    da, _ = geom.project_onto_polyline(a, _to_lines(b, b_closed))  # (n,)
    db, _ = geom.project_onto_polyline(b, _to_lines(a, a_closed))  # (m,)
    return float(min(da.mean(), db.mean()))


def match_changes(
    reported: list[dict[str, Any]], truth: list[Any], gate: float = MATCH_DISTANCE
) -> list[tuple[int, int, float]]:
    """One-to-one matches (reported index, true index, distance) of the same type and class
    within ``gate``, nearest first. ``reported``: ``changes_report.read_changes`` records;
    ``truth``: ``TrueChange``s."""
    pairs = []
    for r, rep in enumerate(reported):
        for t, tru in enumerate(truth):
            if rep["change"] != tru.change or rep["cls"] != tru.cls:
                continue
            d = change_distance(rep["points"], rep["closed"], tru.points, tru.closed)
            if d <= gate:
                pairs.append((d, r, t))
    out, used_r, used_t = [], set(), set()
    for d, r, t in sorted(pairs):
        if r not in used_r and t not in used_t:
            out.append((r, t, d))
            used_r.add(r)
            used_t.add(t)
    return out


def _prf(tp: int, fp: int, fn: int) -> dict[str, Any]:
    p = tp / (tp + fp) if tp + fp else float("nan")
    r = tp / (tp + fn) if tp + fn else float("nan")
    f1 = 2 * p * r / (p + r) if tp else (0.0 if fp + fn else float("nan"))
    return {"tp": tp, "fp": fp, "fn": fn, "precision": p, "recall": r, "f1": f1}


def change_scores(reported: list[dict[str, Any]], truth: list[Any]) -> dict[str, Any]:
    """{"by_type": {type: prf}, "by_class": {type: {class: prf}}, "matches": [(r, t, d)]}."""
    matches = match_changes(reported, truth)
    hit_r = {r for r, _, _ in matches}
    hit_t = {t for _, t, _ in matches}

    def prf(keep: Any) -> dict[str, Any]:
        tp = sum(1 for r, _, _ in matches if keep(reported[r]["change"], reported[r]["cls"]))
        fp = sum(
            1 for r, x in enumerate(reported) if r not in hit_r and keep(x["change"], x["cls"])
        )
        fn = sum(1 for t, x in enumerate(truth) if t not in hit_t and keep(x.change, x.cls))
        return _prf(tp, fp, fn)

    return {
        "by_type": {t: prf(lambda c, _k, t=t: c == t) for t in CHANGE_TYPES},
        "by_class": {
            t: {
                name: prf(lambda c, k, t=t, j=j: c == t and k == j)
                for j, name in enumerate(CLASS_NAMES)
            }
            for t in CHANGE_TYPES
        },
        "matches": matches,
    }


def _holds(
    geoms: list[tuple[NDArray[np.float64], bool]], poses: NDArray[np.float64], rng: PerceptionRange
) -> NDArray[np.bool_]:
    """Per pose (T, 4, 4): whether any geometry has >= 3 of its points (every 0.5 m) inside the
    range shrunk by 1 m."""
    from icmapper.city.update import _dense
    from icmapper.data.gt import in_range_counts

    out = np.zeros(len(poses), bool)  # (T,)
    for pts, closed in geoms:
        dense = _dense(pts, closed)  # (m, 2)
        for f, pose in enumerate(poses):
            if not out[f] and (in_range_counts(dense, pose[None], rng, 1.0) > 0).sum() >= 3:
                out[f] = True
    return out


def frame_accuracy(
    reported: list[dict[str, Any]],
    truth: list[Any],
    poses: NDArray[np.float64],
    rng: PerceptionRange,
) -> dict[str, Any]:
    """TbV-style per-frame scores of the frames ``poses`` (T, 4, 4) (module docstring)."""
    true_geoms = [(c.points, c.closed) for c in truth] + [
        (c.before, False) for c in truth if c.before is not None
    ]
    pred_geoms = [(r["points"], r["closed"]) for r in reported]
    truth_f = _holds(true_geoms, poses, rng)  # (T,)
    pred_f = _holds(pred_geoms, poses, rng)  # (T,)
    ok = pred_f == truth_f
    changed = float(ok[truth_f].mean()) if truth_f.any() else float("nan")
    same = float(ok[~truth_f].mean()) if (~truth_f).any() else float("nan")
    return {
        "frames": int(len(poses)),
        "changed_frames": int(truth_f.sum()),
        "accuracy": float(ok.mean()) if len(ok) else float("nan"),
        "accuracy_changed": changed,
        "accuracy_unchanged": same,
        "mAcc": float(np.nanmean([changed, same])),
    }


def _scratch_map(
    city: Path, manifest: Any, specs: list[str], detections: str, image_size: tuple[int, int]
) -> Path:
    """Builds the from-scratch city map of the update's drives into a temporary folder and
    returns its map file."""
    from icmapper.city.drives import CitySettings
    from icmapper.city.run import build_city

    out = Path(tempfile.mkdtemp(prefix="scratch-", dir=city / "updates"))
    settings = CitySettings(
        manifest.method, detections, manifest.checkpoint, manifest.mapper_config, image_size
    )
    build_city(
        out, specs, settings, manifest.range_name, pictures=False, log=lambda *_: None,
        progress=False,
    )  # fmt: skip
    return out / "city.icmap"


def evaluate_update(
    city: str | os.PathLike, index: int = -1, image_size: tuple[int, int] = (64, 176)
) -> dict[str, Any]:
    """Scores update ``index`` of a city folder (module docstring). ValueError when the update's
    true changes are unknown (its drives' source does not know them)."""
    import shutil

    from icmapper.city.changes_report import read_changes
    from icmapper.city.manifest import read_manifest
    from icmapper.city.update_run import read_updates
    from icmapper.data.gt import visited_gt
    from icmapper.data.sim.changes import TrueChange
    from icmapper.data.sources import open_source
    from icmapper.eval.detection import THRESHOLDS
    from icmapper.eval.globalmap import global_metrics, load_global_map

    city = Path(city)
    manifest = read_manifest(city)
    log = read_updates(city)
    if not log.updates:
        raise ValueError(f"{city}: no update to evaluate")
    entry = log.updates[index]
    folder = city / "updates" / f"{entry.index:04d}"
    truth_file = folder / "true_changes.json"
    if not truth_file.is_file():
        raise ValueError(f"{truth_file}: the true changes of update {entry.index} are unknown")
    truth = [TrueChange.from_json(c) for c in json.loads(truth_file.read_text("utf-8"))["changes"]]
    listed = read_changes(folder / "changes.geojson")
    reported = [r for r in listed if r["cause"] == "road"]  # map errors are not road changes
    rng = PerceptionRange.from_name(manifest.range_name)
    names = {n for _, n in entry.drives}
    seqs = [s for spec in entry.specs for s in open_source(spec, render=False) if s.name in names]
    poses = np.concatenate([np.asarray(s.poses) for s in seqs])  # (sum T, 4, 4)
    scores = change_scores(reported, truth)
    before = load_global_map(folder / "before.icmap")
    wrong = [
        r
        for k, r in enumerate(reported)
        if r["change"] != "added" and k not in {m[0] for m in scores["matches"]}
    ]
    gt = [
        (int(m.cls), np.asarray(m.points, np.float64), bool(m.closed))
        for m in visited_gt(seqs[0].world, poses, rng)
    ]
    thr = THRESHOLDS[manifest.range_name]
    scratch = _scratch_map(city, manifest, entry.specs, entry.detections, image_size)
    try:
        maps = {
            "updated": global_metrics([load_global_map(folder / "after.icmap")], [gt], thr),
            "never_updated": global_metrics([before], [gt], thr),
            "from_scratch": global_metrics([load_global_map(scratch)], [gt], thr),
        }
    finally:
        shutil.rmtree(scratch.parent, ignore_errors=True)
    return {
        "update": entry.index,
        "detections": entry.detections,
        "range": manifest.range_name,
        "n_true": len(truth),
        "n_reported": len(reported),
        "map_errors": len(listed) - len(reported),
        "changes": {k: v for k, v in scores.items() if k != "matches"},
        "wrongly_changed": len(wrong) / max(1, len(before)),
        "wrongly_removed": sum(r["change"] == "removed" for r in wrong) / max(1, len(before)),
        "stored_instances": len(before),
        "frames": frame_accuracy(reported, truth, poses, rng),
        "maps": maps,
    }


def update_table(result: dict[str, Any]) -> str:
    """Markdown tables of ``evaluate_update``: changes per type (and class), frames, maps."""
    from icmapper.eval.report import mapping_table

    def f(x: float) -> str:
        return "-" if not np.isfinite(x) else f"{x:.2f}"

    lines = [
        f"## City update {result['update']} ({result['detections']}): "
        f"{result['n_reported']} reported, {result['n_true']} true changes "
        f"({result['map_errors']} map error(s) reported apart)",
        "",
        "| Change | Class | TP | FP | FN | Precision | Recall | F1 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for t in CHANGE_TYPES:
        rows = [("all", result["changes"]["by_type"][t])]
        rows += [
            (n, s)
            for n, s in result["changes"]["by_class"][t].items()
            if s["tp"] + s["fp"] + s["fn"]
        ]
        for name, s in rows:
            lines.append(
                f"| {t} | {name} | {s['tp']} | {s['fp']} | {s['fn']} | {f(s['precision'])} | "
                f"{f(s['recall'])} | {f(s['f1'])} |"
            )
    fr = result["frames"]
    lines += [
        "",
        f"Unchanged instances wrongly changed: {100 * result['wrongly_changed']:.1f} % "
        f"(wrongly removed {100 * result['wrongly_removed']:.1f} %) of "
        f"{result['stored_instances']} stored.",
        f"Frames (TbV): accuracy {f(fr['accuracy'])}, on the {fr['changed_frames']} frames with a "
        f"change {f(fr['accuracy_changed'])}, on the others {f(fr['accuracy_unchanged'])}, "
        f"mAcc {f(fr['mAcc'])} ({fr['frames']} frames).",
        "",
    ]
    names = {"updated": "updated map", "never_updated": "never-updated map",
             "from_scratch": "from-scratch map"}  # fmt: skip
    rng = result["range"]
    rows = [{"method": names[k], "range": rng, "mapping": m} for k, m in result["maps"].items()]
    lines.append(mapping_table(rows))
    return "\n".join(lines) + "\n"
