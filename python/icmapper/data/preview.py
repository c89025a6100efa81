"""A preview picture of one frame: the six camera images laid out like nuScenes (front row
FRONT_LEFT FRONT FRONT_RIGHT, back row BACK_LEFT BACK BACK_RIGHT) with the BEV ground truth beside
them (crossings blue, dividers orange, boundaries green, ids labelled). Writes a PNG atomically."""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import atomic_path
from icmapper.data.types import MapClass, PerceptionRange, RANGE_60x30, Sequence, world_to_ego

CLASS_COLOURS = {
    MapClass.PED_CROSSING: "tab:blue",
    MapClass.DIVIDER: "tab:orange",
    MapClass.BOUNDARY: "tab:green",
}
_FRONT = ("CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT")
_BACK = ("CAM_BACK_LEFT", "CAM_BACK", "CAM_BACK_RIGHT")


def _bev_instances(
    seq: Sequence, pose: NDArray, rng: PerceptionRange
) -> list[tuple[int, int, NDArray, bool]]:
    """(id, class, ego points (n, 2), closed) of the frame's ground truth: gt.frame_gt when the
    gt module is available, else the world instances near the ego (clipped by the plot limits)."""
    try:
        from icmapper.data.gt import frame_gt
    except ImportError:
        frame_gt = None
    if frame_gt is not None:
        try:
            g = frame_gt(seq.world, pose, rng)
            return [
                (int(i), int(c), np.asarray(p, np.float64), MapClass(int(c)).closed)
                for i, c, p in zip(g.ids, g.classes, g.points, strict=True)
            ]
        except BaseException as exc:  # the geometry engine may still be a stub (a pyo3 panic)
            if isinstance(exc, (KeyboardInterrupt, SystemExit)) or not (
                isinstance(exc, (NotImplementedError, RuntimeError))
                or type(exc).__name__ == "PanicException"
            ):
                raise
            warnings.warn(
                f"gt.frame_gt unavailable ({exc}); drawing world instances instead", stacklevel=3
            )
    out = []
    reach = np.hypot(rng.half_x, rng.half_y) + 5.0
    for m in seq.world.instances:
        pts = world_to_ego(m.points, pose)
        if len(pts) and np.min(np.linalg.norm(pts, axis=1)) < reach * 4:
            inside = (np.abs(pts[:, 0]) <= rng.half_x) & (np.abs(pts[:, 1]) <= rng.half_y)
            if np.any(inside):
                out.append((m.id, int(m.cls), pts, m.closed))
    return out


def preview_png(
    sequence: Sequence,
    frame_index: int,
    out_path: str | os.PathLike[str],
    rng: PerceptionRange = RANGE_60x30,
) -> Path:
    """Writes the preview of frame `frame_index` of `sequence` to `out_path` (PNG); returns it.

    Raises ValueError when the sequence has no images or lacks the six nuScenes cameras, and
    IndexError for a frame out of range.
    """
    import matplotlib.pyplot as plt

    fig = preview_figure(sequence, frame_index, rng)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic_path(out) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return out


def preview_figure(sequence: Sequence, frame_index: int, rng: PerceptionRange = RANGE_60x30) -> Any:
    """The matplotlib figure ``preview_png`` writes (errors as there); the caller closes it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if sequence.render is None:
        raise ValueError(f"sequence {sequence.name!r} has no images to preview")
    frame = sequence.frame(frame_index)
    images = frame.images  # (C, 3, H, W) uint8
    names = list(sequence.rig.names)
    missing = [n for n in _FRONT + _BACK if n not in names]
    if missing:
        raise ValueError(f"rig of {sequence.name!r} lacks cameras {missing}")
    h, w = sequence.rig.image_size
    fig_w, fig_h = 16.0, 5.6
    cam_wf = 0.238  # width of one camera panel, fraction of the figure
    cam_hf = cam_wf * fig_w * h / w / fig_h  # its height keeping the image aspect
    fig = plt.figure(figsize=(fig_w, fig_h), dpi=110)
    for row, group in enumerate((_FRONT, _BACK)):
        bottom = 0.5 + 0.03 if row == 0 else 0.5 - cam_hf - 0.03
        for col, name in enumerate(group):
            ax = fig.add_axes((0.005 + col * (cam_wf + 0.002), bottom, cam_wf, cam_hf))
            ax.imshow(images[names.index(name)].transpose(1, 2, 0))  # (H, W, 3)
            ax.set_title(name, fontsize=8, pad=2)
            ax.axis("off")
    ax = fig.add_axes((0.75, 0.08, 0.24, 0.85))  # room below for the tick labels and x label
    for iid, cls, pts, closed in _bev_instances(sequence, frame.pose, rng):
        if closed:
            pts = np.concatenate([pts, pts[:1]])
        colour = CLASS_COLOURS[MapClass(cls)]
        ax.plot(-pts[:, 1], pts[:, 0], color=colour, lw=1.6)  # x: right (-y), y: forward (x)
        inside = (np.abs(pts[:, 0]) <= rng.half_x) & (np.abs(pts[:, 1]) <= rng.half_y)
        if np.any(inside):
            k = np.flatnonzero(inside)[len(np.flatnonzero(inside)) // 2]
            ax.text(
                -pts[k, 1],
                pts[k, 0],
                str(iid),
                fontsize=6,
                color=colour,
                ha="center",
                va="center",
                bbox={"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.7},
            )
    ax.add_patch(plt.Rectangle((-0.95, -2.4), 1.9, 4.8, color="k"))  # the ego (about 4.8 m x 1.9 m)
    ax.set_xlim(-rng.half_y, rng.half_y)
    ax.set_ylim(-rng.half_x, rng.half_x)
    ax.set_aspect("equal")
    ax.set_xlabel("ego y (m), left is left", fontsize=6)
    ax.set_ylabel("ego x (m), forward", fontsize=6)
    ticks = np.linspace(-rng.half_y, rng.half_y, 5)
    ax.set_xticks(ticks, [f"{0.0 - t:g}" for t in ticks])  # plotted at -y: label with y (no "-0")
    ax.set_title(f"{sequence.name} frame {frame.index}  BEV GT {rng.name} m", fontsize=8)
    ax.tick_params(labelsize=6)
    handles = [
        plt.Line2D([], [], color=c, label=MapClass(k).name.lower())
        for k, c in CLASS_COLOURS.items()
    ]
    ax.legend(handles=handles, fontsize=6, loc="lower right")
    return fig
