"""Pictures of global maps: the predicted map beside the ground truth, with the ego trajectory."""

from __future__ import annotations

import os
from collections.abc import Sequence as Seq
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.atomic import atomic_path

CLASS_COLOURS = ("tab:blue", "tab:orange", "tab:green")  # ped_crossing, divider, boundary


def plot_global_maps(
    pred: Any,
    gt: Seq[Any],
    poses: NDArray[np.float64],
    out_path: str | os.PathLike,
    title: str = "",
) -> None:
    """Writes a PNG: ground-truth global map (left) and predicted global map (right).

    pred: a GlobalMap; gt: MapInstance list (world frame); poses (T, 4, 4) ego->world (a pose of
    NaNs breaks the drawn path, e.g. between the drives of a city).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    traj = np.asarray(poses)[:, :2, 3]  # (T, 2)
    pred_items = []
    for i in pred.ids().tolist():
        cls, pts = pred.get(int(i))
        pred_items.append((int(cls), np.asarray(pts), int(cls) == 0))
    gt_items = [(int(g.cls), np.asarray(g.points), bool(g.closed)) for g in gt]
    allpts = [traj] + [p for _, p, _ in pred_items + gt_items]
    xy = np.concatenate(allpts)
    lo, hi = np.nanmin(xy, 0) - 10, np.nanmax(xy, 0) + 10  # NaN poses break the path
    w, h = hi - lo  # metres
    if w > 1.3 * h:  # a wide map: the two panels one above the other, each as wide as the figure
        fig, axes = plt.subplots(2, 1, figsize=(12, min(2 * 11 * h / w + 1.8, 16)),
                                 sharex=True, sharey=True)  # fmt: skip
    else:
        fig, axes = plt.subplots(1, 2, figsize=(12, min(5.6 * h / w + 1.8, 16)),
                                 sharex=True, sharey=True)  # fmt: skip
    for ax, items, name in (
        (axes[0], gt_items, "ground truth"),
        (axes[1], pred_items, "predicted"),
    ):
        for cls, pts, closed in items:
            p = np.vstack([pts, pts[:1]]) if closed else pts
            ax.plot(p[:, 0], p[:, 1], color=CLASS_COLOURS[cls], lw=1.3)
        ax.plot(traj[:, 0], traj[:, 1], color="0.6", lw=0.8, ls="--")
        per_class = "/".join(str(sum(c == k for c, _, _ in items)) for k in range(3))
        ax.set_title(f"{name}: {len(items)} instances ({per_class} crossings/dividers/boundaries)")
        ax.set_aspect("equal")
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_ylabel("world y (m)")
    axes[-1].set_xlabel("world x (m)")
    handles = [
        plt.Line2D([], [], color=c, label=n)
        for c, n in zip(CLASS_COLOURS, ("ped_crossing", "divider", "boundary"), strict=True)
    ]
    handles.append(plt.Line2D([], [], color="0.6", ls="--", label="ego path"))
    axes[1].legend(handles=handles, loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    save_figure(fig, out_path)


def save_figure(fig: Any, out_path: str | os.PathLike, dpi: int = 110) -> None:
    """Writes matplotlib figure ``fig`` to ``out_path`` (a PNG) atomically and closes it, also
    when the write fails."""
    import matplotlib.pyplot as plt

    try:
        with atomic_path(out_path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        plt.close(fig)
