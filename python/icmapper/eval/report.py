"""Markdown tables shaped like the paper's Tables 1-3 from evaluation results (no I/O).

Table 1: detection AP per class and mAP (x100) with C-mAP, one row per method and range;
Table 2: tracking MOTA (x100) / MOTP (m) / IDS per class; Table 3: global-map CD per class, mCD
(m) and mGAP (x100). A missing value prints as "-".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from icmapper.eval.detection import CLASS_NAMES

_SHORT = {"ped_crossing": "ped", "divider": "div", "boundary": "bound"}


def _fmt(v: Any, scale: float = 1.0, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return f"{v * scale:.{digits}f}"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _name(r: dict) -> str:
    return str(r.get("method") or r.get("run") or "run")


def detection_table(results: Sequence[dict], cmap: str = "icmapper") -> str:
    """cmap: which C-mAP columns — "icmapper" (C-mAP), "maptracker" (C-mAP (MT): MapTracker's
    definition, with its mAP beside it, mAP (MT)) or "both"."""
    header = ["Method", "Range", *(f"AP_{_SHORT[c]}" for c in CLASS_NAMES), "mAP"]
    if cmap in ("icmapper", "both"):
        header.append("C-mAP")
    if cmap in ("maptracker", "both"):
        header += ["mAP (MT)", "C-mAP (MT)"]
    rows = []
    for r in results:
        det = r["detection"]
        row = [_name(r), r["range"]] + [_fmt(det["AP_class"][c], 100) for c in CLASS_NAMES]
        row.append(_fmt(det["mAP"], 100))
        if cmap in ("icmapper", "both"):
            row.append(_fmt(r["consistency"]["C-mAP"], 100))
        if cmap in ("maptracker", "both"):
            mt = r.get("consistency_maptracker") or {}
            row += [_fmt(mt.get("mAP"), 100), _fmt(mt.get("C-mAP"), 100)]
        rows.append(row)
    return _table(header, rows)


def tracking_table(results: Sequence[dict]) -> str:
    header = ["Method", "Range"]
    for c in [*CLASS_NAMES, "mean"]:
        s = _SHORT.get(c, c)
        header += [f"MOTA_{s}", f"MOTP_{s}", f"IDS_{s}"]
    rows = []
    for r in results:
        trk = r["tracking"]
        row = [_name(r), r["range"]]
        for c in CLASS_NAMES:
            v = trk["per_class"][c]
            row += [_fmt(v["MOTA"], 100), _fmt(v["MOTP"], 1, 3), _fmt(v["IDS"], 1, 2)]
        m = trk["mean"]
        row += [_fmt(m["MOTA"], 100), _fmt(m["MOTP"], 1, 3), _fmt(m["IDS"], 1, 2)]
        rows.append(row)
    return _table(header, rows)


def mapping_table(results: Sequence[dict]) -> str:
    header = ["Method", "Range", *(f"CD_{_SHORT[c]}" for c in CLASS_NAMES), "mCD", "mGAP"]
    rows = []
    for r in results:
        mp = r.get("mapping")
        if mp is None:
            rows.append([_name(r), r["range"]] + ["-"] * 5)
            continue
        rows.append(
            [_name(r), r["range"]]
            + [_fmt(mp["CD"][c], 1, 3) for c in CLASS_NAMES]
            + [_fmt(mp["mCD"], 1, 3), _fmt(mp["mGAP"], 100)]
        )
    return _table(header, rows)


def cleanliness_table(results: Sequence[dict]) -> str:
    """Per class: the map's instances / the ground truth's (their ratio), pieces per covered
    ground-truth instance, and the share of map instances that duplicate another (x100)
    (``eval.fragmentation``)."""
    header = ["Method", "Range"]
    for c in CLASS_NAMES:
        s = _SHORT[c]
        header += [f"n_{s}", f"pieces_{s}", f"dup_{s}"]
    rows = []
    for r in results:
        fr = (r.get("mapping") or {}).get("fragmentation")
        if fr is None:
            rows.append([_name(r), r["range"]] + ["-"] * (3 * len(CLASS_NAMES)))
            continue
        row = [_name(r), r["range"]]
        for c in CLASS_NAMES:
            n = fr["count"][c]
            row += [
                f"{n['map']}/{n['gt']} ({_fmt(n['ratio'], 1, 2)})",
                _fmt(fr["pieces"][c], 1, 2),
                _fmt(fr["duplicates"][c], 100),
            ]
        rows.append(row)
    return _table(header, rows)


def markdown(results: Sequence[dict], cmap: str = "icmapper") -> str:
    """The three tables, titled, one row per result (method and range); ``cmap``: the C-mAP
    columns of Table 1 (``detection_table``)."""
    parts = [
        "### Detection (AP x100, Chamfer thresholds per range)",
        detection_table(results, cmap),
        "### Tracking (MOTA x100, MOTP m, IDS per sequence)",
        tracking_table(results),
        "### Global map (CD m, lower is better; mGAP x100)",
        mapping_table(results),
        "### Map cleanliness (instances map/GT (ratio), pieces per GT instance, duplicates x100)",
        cleanliness_table(results),
    ]
    return "\n\n".join(parts) + "\n"
