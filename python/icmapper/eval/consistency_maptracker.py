"""C-mAP as MapTracker's tool computes it (numpy, no I/O): the option beside ``consistency.py``.

Followed: woodfrog/maptracker at ee8321f, ``tools/tracking/calculate_cmap.py`` (with
``--consist 1``) on the output of ``prepare_pred_tracks.py`` (our own implementation). Differences
from icmapper's C-mAP (``consistency.py``), all MapTracker's:

- track ids are not the method's: they are re-derived from the predictions by
  ``maptracker_tracks.derive_track_ids`` (score > 0.4, warped earlier frames, mask IoU, a
  look-back of 5 frames);
- only predictions with score > 0.4 are scored at all (the tool reads the re-tracked file, which
  holds those only);
- in a frame without ground truth of a class (or without predictions of it) that class's
  predictions are left out (``_evaluate_single`` returns no rows), not counted as false positives;
- instances are sampled at ``linspace(0, L, 200)`` along the line, both ends included, crossings
  along their closed ring back to the first point (``interp_fixed_num``);
- per frame and class, TP/FP by descending score against the nearest ground truth as in AP; then,
  per sequence and class, frames in order and predictions in their order within the frame: the
  first prediction matched to a ground-truth id fixes that id's predicted track; a later TP on it
  with another predicted id becomes an FP.

Ground-truth ids are icmapper's (``gt.sequence_gt``), where MapTracker matches its own
(``prepare_gt_tracks.py``). Score sorts are stable (numpy's default sort in the tool is not, so
its order among equal scores is arbitrary).
"""

from __future__ import annotations

from collections.abc import Sequence as Seq
from typing import Any

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.detection import CLASS_NAMES, average_precision, mean_ignore_nan
from icmapper.eval.maptracker_tracks import (
    LOOK_BACK,
    SCORE_THRESHOLD,
    derive_track_ids,
    interp_fixed_num,
)

#: Points per instance of the Chamfer distance (calculate_cmap.py's INTERP_NUM).
INTERP_NUM = 200


def _samples(points: NDArray[np.floating], classes: NDArray[np.int64]) -> NDArray[np.float64]:
    """(k, n, 2) -> (k, INTERP_NUM, 2) ``interp_fixed_num`` samples (crossings closed)."""
    out = np.empty((len(classes), INTERP_NUM, 2))
    for j in range(len(classes)):
        out[j] = interp_fixed_num(points[j], INTERP_NUM, int(classes[j]) == 0)
    return out


def _frame_rows(
    d: NDArray[np.float64],
    scores: NDArray[np.float64],
    pred_ids: NDArray[np.int64],
    gt_ids: NDArray[np.int64],
    threshold: float,
    owner: dict[int, int] | None,
) -> NDArray[np.float64]:
    """One frame and class: Chamfer matrix d (n, m), scores (n,), predicted ids (n,), gt ids (m,)
    -> rows (n, 3) of (tp, fp, score) in prediction order; ``owner`` (gt id -> predicted id) is
    updated in place and turns inconsistent TPs into FPs (None: plain AP)."""
    n = d.shape[0]
    nearest = d.argmin(axis=1)  # (n,)
    nearest_d = d[np.arange(n), nearest]  # (n,)
    covered = np.zeros(d.shape[1], dtype=bool)
    matched = np.full(n, -1, dtype=np.int64)  # gt column of each TP
    for i in np.argsort(-scores, kind="stable"):
        if nearest_d[i] <= threshold and not covered[nearest[i]]:
            covered[nearest[i]] = True
            matched[i] = nearest[i]
    tp = (matched >= 0).astype(np.float64)
    if owner is not None:
        for i in range(n):  # prediction order within the frame, as the tool's loop
            key = int(gt_ids[matched[i]]) if matched[i] >= 0 else -1
            pid = int(pred_ids[i])
            if key not in owner:
                owner[key] = pid
            elif owner[key] != pid:
                tp[i] = 0.0
    return np.stack([tp, 1.0 - tp, scores], axis=1)  # (n, 3)


def maptracker_cmap(
    predictions_per_seq: Seq[Seq[Any]],
    gt_per_seq: Seq[Seq[Any]],
    thresholds: tuple[float, ...],
    half_extents: tuple[float, float],
    score_threshold: float = SCORE_THRESHOLD,
    look_back: int = LOOK_BACK,
) -> dict:
    """MapTracker's C-mAP and, with the same rules but without the consistency check, its mAP.

    predictions_per_seq[s][t]: FramePredictions-like (classes (k,), scores (k,), points (k, n, 2)
    ego, pose (4, 4)); gt_per_seq[s][t]: FrameGT-like (ids, classes, points) of the same frame;
    half_extents: the perception range (hx, hy). Returns {"thresholds", "score_threshold",
    "look_back", "C-AP": {class: {thr: ap}}, "C-AP_class", "C-mAP", "AP", "AP_class", "mAP"}.
    """
    from icmapper import geom

    num_gt = np.zeros(len(CLASS_NAMES), dtype=np.int64)
    # per sequence, frame, class: (d (n, m), scores (n,), predicted ids (n,), gt ids (m,))
    cells: list[list[list[tuple[Any, ...] | None]]] = []
    for preds, gts in zip(predictions_per_seq, gt_per_seq, strict=True):
        poses = np.stack([np.asarray(p.pose, dtype=np.float64) for p in preds])  # (T, 4, 4)
        frames = [
            (np.asarray(p.classes), np.asarray(p.scores, np.float64), np.asarray(p.points))
            for p in preds
        ]
        ids = derive_track_ids(frames, poses, half_extents, score_threshold, look_back)
        seq_cells = []
        for (classes, scores, points), tids, g in zip(frames, ids, gts, strict=True):
            g_cls = np.asarray(g.classes, dtype=np.int64)
            g_pts = np.asarray(g.points, dtype=np.float64)
            g_ids = np.asarray(g.ids, dtype=np.int64)
            keep = tids >= 0
            frame_cells: list[tuple[Any, ...] | None] = []
            for c in range(len(CLASS_NAMES)):
                num_gt[c] += int(np.count_nonzero(g_cls == c))
                p_rows = np.flatnonzero(keep & (classes == c))
                g_rows = np.flatnonzero(g_cls == c)
                if p_rows.size == 0 or g_rows.size == 0:
                    frame_cells.append(None)
                    continue
                ps = _samples(points[p_rows], classes[p_rows])  # (n, 200, 2)
                gs = _samples(g_pts[g_rows], g_cls[g_rows])  # (m, 200, 2)
                d = geom.chamfer_matrix(ps, gs)  # (n, m)
                frame_cells.append((d, scores[p_rows], tids[p_rows], g_ids[g_rows]))
            seq_cells.append(frame_cells)
        cells.append(seq_cells)

    out: dict[str, Any] = {
        "thresholds": [float(t) for t in thresholds],
        "score_threshold": float(score_threshold),
        "look_back": int(look_back),
    }
    for key, consist in (("C-AP", True), ("AP", False)):
        per: dict[str, dict[str, float]] = {name: {} for name in CLASS_NAMES}
        for thr in thresholds:
            for c, name in enumerate(CLASS_NAMES):
                rows = [np.zeros((0, 3))]
                for seq_cells in cells:
                    owner: dict[int, int] | None = {} if consist else None
                    for frame_cells in seq_cells:
                        cell = frame_cells[c]
                        if cell is not None:
                            rows.append(_frame_rows(*cell, thr, owner))
                table = np.concatenate(rows)  # (N, 3)
                order = np.argsort(-table[:, 2], kind="stable")
                per[name][f"{thr:g}"] = average_precision(table[order, 0] > 0, int(num_gt[c]))
        cls_mean = {name: mean_ignore_nan(list(per[name].values())) for name in CLASS_NAMES}
        out[key] = per
        out[f"{key}_class"] = cls_mean
        out["C-mAP" if consist else "mAP"] = mean_ignore_nan(list(cls_mean.values()))
    return out
