"""The interactive viewer: one self-contained HTML file (data and code inline, works offline).

``viewer_data`` gathers what the page shows into one JSON-able dict (format "icmapper-viewer",
version 1): the global map (instances with bookkeeping and, with ground truth, each one's Chamfer
distance to the nearest same-class ground-truth instance), the ground-truth global map, per frame
the ego pose and the predictions in world coordinates, per-class CD and GAP, and JPEG camera
thumbnails with the tracked predictions drawn on them. ``write_viewer`` puts it and the page's
code (``viewer.js``, ``viewer.html``: package data next to this module) into one file.

The page draws on a canvas. It exposes its state to tests and scripts as
``window.icmapperViewer`` (documented in ``viewer.js`` and docs/vis.md): the number of instances
drawn per class, the current frame, the selected instance, the last draw times, and methods to
move the slider, select, toggle layers and convert world to page coordinates. The time slider is
an ``<input type="range" id="frame">``.

The map at frame t is the final map's instances with ``first_frame <= t`` (``vis.replay``).
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import write_text_atomic
from icmapper.data.types import CLASS_NAMES, PerceptionRange, ego_to_world, pose_to_xy_yaw
from icmapper.eval.runfmt import RunSequence
from icmapper.vis.replay import MapItem, RunReplay, load_map_items
from icmapper.vis.style import CLASS_HEX

FORMAT_NAME = "icmapper-viewer"
FORMAT_VERSION = 1
#: Ground-truth instances farther than this (m, bounding boxes) are not candidates for an
#: instance's nearest ground truth; an instance with none within it reports no distance.
NEAREST_GT_REACH = 10.0
#: Coordinates are written with this many decimals (1 cm).
DECIMALS = 2


def _flat(polylines: list[NDArray[np.floating]]) -> tuple[list[int], list[float]]:
    """Offsets (k + 1,) into a flat coordinate list, and the flat list x0, y0, x1, ... (rounded)."""
    start = [0]
    for p in polylines:
        start.append(start[-1] + int(np.asarray(p).shape[0]))
    if not polylines:
        return start, []
    xy = np.round(np.concatenate([np.asarray(p, np.float64) for p in polylines]), DECIMALS)
    return start, xy.ravel().tolist()


def _finite_or_none(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def nearest_gt_chamfer(
    items: list[MapItem], gt: list[tuple[int, NDArray[np.float64], bool]]
) -> tuple[list[float | None], list[int | None]]:
    """For each map instance: the Chamfer distance (evaluation protocol: 200 points by arc
    length) to the nearest same-class GT instance within ``NEAREST_GT_REACH`` of its bounding
    box, and that GT's index (None, None where there is none)."""
    from icmapper.eval.chamfer import NUM_SAMPLES
    from icmapper.geom import chamfer_pairs, resample_many

    cd: list[float | None] = [None] * len(items)
    which: list[int | None] = [None] * len(items)
    if not items or not gt:
        return cd, which
    g_cls = np.array([c for c, _, _ in gt])  # (G,)
    g_lo = np.array([p.min(0) for _, p, _ in gt])  # (G, 2)
    g_hi = np.array([p.max(0) for _, p, _ in gt])  # (G, 2)
    g_fine = [resample_many(p[None], NUM_SAMPLES, closed)[0] for _, p, closed in gt]  # G x (200, 2)
    for i, m in enumerate(items):
        lo, hi = m.points.min(0), m.points.max(0)
        gap = np.maximum(np.maximum(g_lo - hi, lo - g_hi), 0.0)  # (G, 2)
        cand = np.flatnonzero((g_cls == m.cls) & (np.hypot(*gap.T) <= NEAREST_GT_REACH))
        if cand.size == 0:
            continue
        a = resample_many(m.points[None], NUM_SAMPLES, m.closed)  # (1, 200, 2)
        d = chamfer_pairs(np.repeat(a, cand.size, 0), np.stack([g_fine[j] for j in cand]))
        k = int(np.argmin(d))
        cd[i], which[i] = round(float(d[k]), 3), int(cand[k])
    return cd, which


def _map_block(items: list[MapItem], cd: list, gt_index: list) -> dict[str, Any]:
    start, xy = _flat([m.points for m in items])
    return {
        "id": [m.id for m in items],
        "cls": [m.cls for m in items],
        "closed": [int(m.closed) for m in items],
        "first": [m.first_frame for m in items],
        "last": [m.last_frame for m in items],
        "obs": [m.observations for m in items],
        "cd": cd,
        "gt": gt_index,
        "start": start,
        "xy": xy,
    }


def _gt_block(gt: list[tuple[int, NDArray[np.float64], bool]]) -> dict[str, Any]:
    start, xy = _flat([p for _, p, _ in gt])
    return {
        "cls": [c for c, _, _ in gt],
        "closed": [int(c) for _, _, c in gt],
        "start": start,
        "xy": xy,
    }


def _metrics(items: list[MapItem], gt: list, range_name: str) -> dict[str, Any]:
    """Per-class CD and GAP of this one map against its ground truth (eval.globalmap)."""
    from icmapper.eval.detection import THRESHOLDS
    from icmapper.eval.globalmap import global_metrics

    pred = [(m.cls, m.points, m.closed, float(m.observations)) for m in items]
    thr = THRESHOLDS.get(range_name, THRESHOLDS["60x30"])
    r = global_metrics([pred], [gt], thr)
    return {
        "CD": {k: _finite_or_none(v) for k, v in r["CD"].items()},
        "GAP": {k: _finite_or_none(v) for k, v in r["GAP"].items()},
        "mCD": _finite_or_none(r["mCD"]),
        "mGAP": _finite_or_none(r["mGAP"]),
        "thresholds": r["thresholds"],
        "note": "CD in metres (inf or none shown as -); GAP: Chamfer AP over global instances",
    }


def _thumbs(replay: RunReplay, quality: int = 70) -> dict[str, Any] | None:
    """JPEG data URLs of every frame's cameras, tracked predictions drawn on them."""
    from icmapper.vis.frame import camera_order, prediction_overlays
    from icmapper.vis.overlay import draw_camera_overlays

    src = replay.source
    if src is None or src.render is None:
        return None
    from icmapper.progress import progress

    order = [i for row in camera_order(src.rig.names) for i in row]
    frames = []
    bar = progress(len(replay), f"viewer thumbnails {replay.name}", unit="frame")
    for t in range(len(replay)):
        view = replay.frame(t)
        if view.images is None or view.rig is None:
            return None
        overlays = prediction_overlays(view)
        for ov in overlays:
            ov.label, ov.width = None, 1
        imgs = draw_camera_overlays(view.images, view.rig, overlays)
        urls = []
        for i in order:
            buf = io.BytesIO()
            imgs[i].save(buf, format="JPEG", quality=quality)
            urls.append("data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode())
        frames.append(urls)
        bar.update(1)
    bar.close()
    return {
        "names": [src.rig.names[i] for i in order],
        "size": list(src.rig.image_size),
        "columns": max(len(r) for r in camera_order(src.rig.names)),
        "frames": frames,
    }


def _frames_block(seq: RunSequence) -> dict[str, Any]:
    """A run sequence's frames: count, source indices, seconds from its start, (x, y, yaw)."""
    t0 = float(seq.timestamps[0]) if len(seq) else 0.0
    return {
        "count": len(seq),
        "index": seq.frame_index.tolist(),
        "time": [round(float(x) - t0, 3) for x in seq.timestamps],
        "pose": [[round(v, 3) for v in pose_to_xy_yaw(p)] for p in seq.poses],
    }


def _dets_block(seq: RunSequence) -> dict[str, Any]:
    """A run sequence's predictions in world coordinates, frame by frame (``frameStart``)."""
    dets_cls, dets_tid, dets_score, dets_pts, frame_start = [], [], [], [], [0]
    for t in range(len(seq)):
        f = seq.frame(t)
        for c, s, tid, pts in zip(
            f.classes.tolist(), f.scores.tolist(), f.track_ids.tolist(), f.points, strict=True
        ):
            dets_cls.append(int(c))
            dets_tid.append(int(tid))
            dets_score.append(round(float(s), 3))
            dets_pts.append(ego_to_world(pts, f.pose))
        frame_start.append(len(dets_cls))
    d_start, d_xy = _flat(dets_pts)
    return {
        "frameStart": frame_start,
        "cls": dets_cls,
        "tid": dets_tid,
        "score": dets_score,
        "untrackedFrom": 1 << 40,
        "start": d_start,
        "xy": d_xy,
    }


def viewer_data(replay: RunReplay, thumbnails: bool = True) -> dict[str, Any]:
    """Everything the page shows for one sequence of a run (module docstring)."""
    seq = replay.seq
    items = replay.map_items
    gt_items = None
    if replay.source is not None:
        gt_items = [(int(g.cls), np.asarray(g.points), bool(g.closed)) for g in replay.global_gt]
    cd, gt_index = nearest_gt_chamfer(items, gt_items or [])
    data: dict[str, Any] = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "kind": "run",
        "title": f"{replay.run.method} on {replay.name}",
        "method": replay.run.method,
        "source": replay.run.source,
        "sequence": replay.name,
        "classes": list(CLASS_NAMES),
        "colours": list(CLASS_HEX),
        "range": [replay.rng.half_x, replay.rng.half_y],
        "frames": _frames_block(seq),
        "map": _map_block(items, cd, gt_index),
        "gt": _gt_block(gt_items) if gt_items is not None else None,
        "dets": _dets_block(seq),
        "metrics": _metrics(items, gt_items, replay.run.range_name) if gt_items else None,
        "cameras": _thumbs(replay) if thumbnails else None,
    }
    return data


#: Colours of the changes layer (the change report's picture: ``changes_report.CHANGE_COLOURS``).
CHANGE_HEX = {"removed": "#d62728", "added": "#2ca02c", "moved": "#ff8c00"}


def changes_block(path: str | os.PathLike) -> dict[str, Any]:
    """The viewer's layer of a city update's change report (``changes.geojson``, see
    ``city.changes_report``): per change its type (added | removed | moved), class, map
    instance, cause (road | map) and geometry (a removal: the removed instance; a move: the
    moved part, ``before`` the stored part it replaced; an addition: the new instance), flat as
    the map's. ValueError naming the file when it is not a change report."""
    from icmapper.city.changes_report import read_changes

    path = Path(path)
    records = read_changes(path)
    raw = json.loads(path.read_text(encoding="utf-8"))
    update = {int(f["properties"].get("update", -1)) for f in raw["features"]}
    before = []
    for f in raw["features"]:
        b = f["properties"].get("before")
        before.append(np.asarray(b, np.float64).reshape(-1, 2) if b else np.zeros((0, 2)))
    start, xy = _flat([r["points"] for r in records])
    b_start, b_xy = _flat(before)
    return {
        "update": max(update) if update else None,
        "change": [r["change"] for r in records],
        "cls": [r["cls"] for r in records],
        "instance": [r["instance"] for r in records],
        "cause": [r["cause"] for r in records],
        "closed": [int(r["closed"]) for r in records],
        "start": start,
        "xy": xy,
        "beforeStart": b_start,
        "beforeXy": b_xy,
        "colours": dict(CHANGE_HEX),
    }


def city_viewer_data(city: str | os.PathLike, with_source: bool = True) -> dict[str, Any]:
    """Everything the page shows for a city run folder (kind "city"): the city map (with each
    instance's distance to the nearest ground truth), the city's cross-drive ground truth and
    its CD / GAP (``with_source``: recomputed from the drives' sources), and per successful
    drive (``drives``: name, drive index, frames, predictions) what a run's page shows of its
    one sequence; the page's drive selector picks one. No camera thumbnails. A city with an
    update (``changes.geojson``: the latest update's report) also gets ``changes``
    (``changes_block``): the page draws them over the map (removed red, added green, moved
    orange; map errors, reported but not applied, in short dashes) with a toggle."""
    from icmapper.city.manifest import CITY_MAP, read_manifest
    from icmapper.eval.runfmt import read_run

    city = Path(city)
    manifest = read_manifest(city)
    ok = manifest.ok_drives()
    if not ok or not (city / CITY_MAP).is_file():
        raise ValueError(f"{city}: a city run without a city map (no drive succeeded)")
    rng = PerceptionRange.from_name(manifest.range_name)
    items = load_map_items(city / CITY_MAP)
    gt_items = None
    if with_source:
        from icmapper.city.run import city_sequences
        from icmapper.data.gt import city_gt

        gt = city_gt(city_sequences(manifest), rng)
        gt_items = [(int(g.cls), np.asarray(g.points), bool(g.closed)) for g in gt]
    cd, gt_index = nearest_gt_chamfer(items, gt_items or [])
    report = city / "changes.geojson"  # the latest update's changes
    drives = []
    for d in ok:
        seq = read_run(city / d.run).sequences[0]
        drives.append(
            {"name": seq.name, "index": d.index, "frames": _frames_block(seq),
             "dets": _dets_block(seq)}
        )  # fmt: skip
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "kind": "city",
        "title": f"city map of {len(ok)} drives ({manifest.method}, {manifest.mode})",
        "method": manifest.method,
        "source": ", ".join(dict.fromkeys(d.spec for d in ok)),
        "sequence": "",
        "classes": list(CLASS_NAMES),
        "colours": list(CLASS_HEX),
        "range": [rng.half_x, rng.half_y],
        "frames": None,  # the selected drive's (``drives``)
        "map": _map_block(items, cd, gt_index),
        "gt": _gt_block(gt_items) if gt_items is not None else None,
        "dets": None,
        "drives": drives,
        "metrics": _metrics(items, gt_items, manifest.range_name) if gt_items else None,
        "cameras": None,
        "changes": changes_block(report) if report.is_file() else None,
    }


def map_viewer_data(items: list[MapItem], title: str) -> dict[str, Any]:
    """The viewer's data for a map file alone: no ego, predictions or ground truth; the slider
    moves through the bookkeeping frames (an instance appears at its first frame)."""
    count = max((m.last_frame for m in items), default=0) + 1
    return {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "kind": "map",
        "title": title,
        "method": "",
        "source": "",
        "sequence": "",
        "classes": list(CLASS_NAMES),
        "colours": list(CLASS_HEX),
        "range": None,
        "frames": {"count": count, "index": list(range(count)), "time": None, "pose": None},
        "map": _map_block(items, [None] * len(items), [None] * len(items)),
        "gt": None,
        "dets": None,
        "metrics": None,
        "cameras": None,
    }


def _asset(name: str) -> str:
    return resources.files("icmapper.vis").joinpath(name).read_text(encoding="utf-8")


def render_html(data: dict[str, Any]) -> str:
    """The page: viewer.html with the data (JSON) and viewer.js inlined."""
    blob = json.dumps(data, separators=(",", ":"), allow_nan=False)
    blob = blob.replace("</", "<\\/")  # never closes the script element
    title = str(data.get("title", "icmapper viewer"))
    for a, b in (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;")):
        title = title.replace(a, b)
    page = _asset("viewer.html")
    parts = {"{{TITLE}}": title, "{{DATA}}": blob, "{{SCRIPT}}": _asset("viewer.js")}
    for key in parts:
        if page.count(key) != 1:
            raise RuntimeError(f"viewer.html must hold {key} exactly once")
    out = []
    rest = page
    while rest:  # substitute in one pass: the data never gets re-scanned
        hits = [(rest.find(k), k) for k in parts if rest.find(k) >= 0]
        if not hits:
            out.append(rest)
            break
        at, key = min(hits)
        out += [rest[:at], parts[key]]
        rest = rest[at + len(key) :]
    return "".join(out)


def write_viewer(data: dict[str, Any], path: str | os.PathLike) -> Path:
    """Writes the page for ``data`` to ``path`` atomically; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = render_html(data)
    write_text_atomic(out, text)
    return out
