"""The change report of a city update: ``changes.geojson`` and its picture.

``changes.geojson`` is a FeatureCollection with one feature per confirmed change, in the map frame
of ``city.geojson`` (the same ``icmapper`` member naming the frame: ``georef.frame_member``;
its ``schema`` is the map schema's, ``report`` says "changes"). A feature's geometry is the
geometry after the change (a removal: the removed instance; a move: the moved part; a crossing:
a Polygon), and its properties are ``change`` (added | removed | moved), ``class``, ``class_id``,
``instance`` (the map id; an addition's new id), ``drive`` (the drives that saw it), ``update``
(the update's number), ``evidence`` (frames in which it should have been seen, was seen, was
missed: counts and the (drive, frame) lists), and for a move ``offset`` (metres, + left of the
stored line) and ``before`` (the stored part's coordinates).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from icmapper.city.update import Change

#: Colours of the picture.
CHANGE_COLOURS = {
    "unchanged": "0.72",
    "removed": "tab:red",
    "added": "tab:green",
    "moved": "orange",
}


def changes_geojson(
    changes: Sequence[Change], update: int, local_frame: str = ""
) -> dict[str, Any]:
    """The report of one update's confirmed changes (module docstring)."""
    from icmapper.georef import feature_geometry, frame_member

    features = []
    for k, ch in enumerate(changes):
        props: dict[str, Any] = {
            "change": ch.change,
            "class": ch.class_name,
            "class_id": ch.cls,
            "instance": ch.instance,
            "drive": sorted({d for d, _ in ch.evidence.seen}) or ch.evidence.drives(),
            "update": update,
            "cause": ch.cause,
            "evidence": ch.evidence.to_json(),
        }
        if ch.change == "moved" and ch.before is not None:
            props["offset"] = round(ch.offset, 4)
            props["before"] = np.asarray(ch.before, np.float64).tolist()
        features.append(
            {
                "type": "Feature",
                "id": k,
                "geometry": feature_geometry(np.asarray(ch.points).tolist(), ch.closed),
                "properties": props,
            }
        )
    member = frame_member(local_frame)
    member["report"] = "changes"
    return {"type": "FeatureCollection", "features": features, "icmapper": member}


def read_changes(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The features of a ``changes.geojson`` as plain records: change, class_id, instance,
    points (n, 2) and closed (ValueError naming the file when it is not a change report)."""
    import json

    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
        if raw["icmapper"].get("report") != "changes":
            raise KeyError("report")
        out = []
        for f in raw["features"]:
            geom, props = f["geometry"], f["properties"]
            closed = geom["type"] == "Polygon"
            pts = np.asarray(geom["coordinates"][0][:-1] if closed else geom["coordinates"])
            out.append(
                {
                    "change": props["change"],
                    "cls": int(props["class_id"]),
                    "instance": int(props["instance"]),
                    "points": pts.astype(np.float64).reshape(-1, 2),
                    "closed": closed,
                    "cause": str(props.get("cause", "road")),
                }
            )
        return out
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"{path}: not an icmapper change report ({exc!r})") from None


def plot_changes(
    before: str | os.PathLike,
    changes: Sequence[Change],
    seqs: Sequence[Any],
    out_path: str | os.PathLike,
    title: str = "",
) -> None:
    """Writes a PNG of an update (atomically): the city map before it, unchanged instances grey,
    removed red, added green, moved orange (the stored line dashed), map errors (changes the
    city's own drives saw before: reported, not applied) in short dashes, each change ringed
    and numbered as in the report; the drives' paths dotted."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from icmapper._icmap import GlobalMap
    from icmapper.atomic import atomic_path

    gmap = GlobalMap.load(str(before))
    touched = {ch.instance for ch in changes if ch.change != "added"}
    xy = np.concatenate(
        [np.asarray(gmap.get(int(i))[1]) for i in gmap.ids().tolist()]
        + [np.asarray(ch.points) for ch in changes]
        + [np.zeros((0, 2))]
    )  # (N, 2) everything drawn
    span = np.ptp(xy, axis=0) + 20.0 if len(xy) else np.array([100.0, 100.0])  # (2,)
    aspect = float(np.clip(span[1] / span[0], 0.4, 2.5))
    fig, ax = plt.subplots(figsize=(11.0, 1.0 + 8.0 * aspect))

    def draw(pts: np.ndarray, closed: bool, **kw: Any) -> None:
        p = np.vstack([pts, pts[:1]]) if closed else pts
        ax.plot(p[:, 0], p[:, 1], **kw)

    for i in gmap.ids().tolist():
        cls, pts = gmap.get(int(i))
        moved_whole = int(i) in touched
        colour = CHANGE_COLOURS["unchanged"]
        draw(np.asarray(pts), int(cls) == 0, color=colour, lw=0.9, ls=":" if moved_whole else "-")
    for s in seqs:
        xy = np.asarray(s.poses)[:, :2, 3]  # (T, 2)
        ax.plot(xy[:, 0], xy[:, 1], color="tab:blue", lw=0.7, ls=(0, (1, 3)), alpha=0.6)
    for k, ch in enumerate(changes):
        colour = CHANGE_COLOURS[ch.change]
        if ch.before is not None:
            draw(np.asarray(ch.before), ch.closed, color="0.3", lw=1.2, ls="--")
        road = ch.cause == "road"
        draw(np.asarray(ch.points), ch.closed, color=colour, lw=2.4 if road else 1.6,
             ls="-" if road else (0, (2, 1)))  # fmt: skip
        c = np.asarray(ch.points).mean(axis=0)
        r = min(12.0, max(5.0, 0.5 * float(np.ptp(np.asarray(ch.points), axis=0).max()) + 2.0))
        ax.add_patch(plt.Circle(tuple(c), r, fill=False, color=colour, lw=1.0))
        ax.annotate(str(k), tuple(c + r * 0.75), color=colour, fontsize=9, weight="bold")
    handles = [
        plt.Line2D([], [], color=CHANGE_COLOURS[n], lw=2.4 if n != "unchanged" else 1.0, label=n)
        for n in ("unchanged", "removed", "added", "moved")
    ]
    handles.append(plt.Line2D([], [], color="0.3", lw=1.2, ls="--", label="moved: before"))
    handles.append(
        plt.Line2D([], [], color="0.3", lw=1.6, ls=(0, (2, 1)), label="map error (not applied)")
    )
    handles.append(plt.Line2D([], [], color="tab:blue", lw=0.7, ls=(0, (1, 3)), label="drives"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m)")
    ax.set_title(title)
    fig.tight_layout()
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
