"""Predictions without track ids (a StreamMapNet or MapTR file): which numbers they can be scored
on. Every prediction then has an id of its own, so the numbers that measure track ids — icmapper's
C-mAP (a TP on a ground truth matched earlier by another id is an FP), MOTA (which counts ID
switches) and IDS — would score that, not the predictions: they are left out (None, "-" in the
tables). Detection AP, MOTP (matched pairs' distance) and MapTracker's C-mAP (which re-derives
ids from the predictions, ``consistency_maptracker``) stand. No I/O."""

from __future__ import annotations

from typing import Any

#: What needs track ids, as the tables and the note name it.
NEEDS_IDS = ("C-mAP (icmapper's)", "MOTA", "IDS")


def without_track_ids(result: dict[str, Any]) -> dict[str, Any]:
    """``result`` (``evaluate``'s dict) with the id-based numbers set to None and
    ``result["track_ids"] = "none"``; returns it."""
    cons = result["consistency"]
    cons["C-mAP"] = None
    cons["C-AP"] = {c: dict.fromkeys(v) for c, v in cons["C-AP"].items()}
    cons["C-AP_class"] = dict.fromkeys(cons["C-AP_class"])
    trk = result["tracking"]
    for row in [*trk["per_class"].values(), trk["mean"]]:
        for key in ("MOTA", "IDS", "num_switches"):
            if key in row:
                row[key] = None
    result["track_ids"] = "none"
    return result


def note(result: dict[str, Any]) -> str | None:
    """One line for a result without track ids (None for one with them)."""
    if result.get("track_ids") != "none":
        return None
    return (
        f"note: {result.get('run') or result.get('method')} carries no track ids: "
        f"{', '.join(NEEDS_IDS)} measure ids and are left out ('-'); detection AP and MOTP "
        "stand, and --cmap maptracker (or both) re-derives ids from the predictions as "
        "MapTracker's tool does"
    )
