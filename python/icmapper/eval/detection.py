"""Detection AP with the Chamfer protocol of StreamMapNet / IC-Mapper (numpy, no I/O).

Per class, predictions of all frames are taken by descending score (ties: table order, stable);
each is compared with its *nearest* ground truth of the same class in the same frame only (ties:
the lower table row): a true positive if that distance is within the threshold and that ground
truth is not yet taken, else a false positive (no fall-back to the next-nearest). A prediction in a
frame (and class) without ground truth is a false positive. AP is the area under the monotone
precision envelope (VOC "area", as mmdet's ``average_precision(mode="area")``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.chamfer import Resampled, sparse_chamfer
from icmapper.eval.instances import Instances

CLASS_NAMES: tuple[str, ...] = ("ped_crossing", "divider", "boundary")
#: Chamfer thresholds (metres) per perception range name.
THRESHOLDS: dict[str, tuple[float, ...]] = {"60x30": (0.5, 1.0, 1.5), "100x50": (1.0, 1.5, 2.0)}


@dataclass
class Matching:
    """Chamfer relations of predictions and ground truth for one evaluation.

    pairs_pred, pairs_gt, pairs_dist (P,): every same-frame, same-class pair with Chamfer
    distance <= max_dist (exact), sorted by prediction then ground truth row.
    nearest_gt (N,) int64: per prediction the nearest ground-truth row (-1 when no ground truth
    lies within max_dist — then it is a false positive at every threshold <= max_dist);
    nearest_dist (N,) float64 (inf when -1).
    """

    max_dist: float
    pairs_pred: NDArray[np.int64]
    pairs_gt: NDArray[np.int64]
    pairs_dist: NDArray[np.float64]
    nearest_gt: NDArray[np.int64]
    nearest_dist: NDArray[np.float64]


def prepare(inst: Instances, sampled: bool = False) -> Resampled:
    """Resamples a table's instances to the protocol's 200 points (crossings closed); with
    ``sampled`` the table's points are those samples already (N, 200, 2) and are used as given."""
    if sampled:
        return Resampled.from_samples(inst.points)
    return Resampled.from_points(inst.points, inst.classes == 0)


def match(
    pred: Instances,
    gt: Instances,
    max_dist: float,
    block_rows: int = 20_000,
    backend: str | None = None,
    sampled: bool = False,
) -> Matching:
    """Chamfer pairs (<= max_dist) and nearest ground truth of every prediction.

    pred, gt: tables in the same frames (same seq/frame numbering), points in the same frame.
    Works through blocks of whole sequences of about ``block_rows`` predictions, so memory stays
    bounded (the 200-point samples of a block only). ``sampled``: both tables hold the protocol's
    200 samples already (:func:`prepare`); ``backend``: of the exact Chamfer stage.
    """
    num_frames = int(max(pred.frame.max(initial=0), gt.frame.max(initial=0))) + 1
    kp, kg = pred.key(num_frames), gt.key(num_frames)
    p_order = np.argsort(pred.seq, kind="stable")
    g_order = np.argsort(gt.seq, kind="stable")
    seqs = np.union1d(pred.seq, gt.seq)
    p_cut = np.searchsorted(pred.seq[p_order], seqs)
    g_cut = np.searchsorted(gt.seq[g_order], seqs)
    parts_p, parts_g, parts_d = [], [], []
    i = 0
    while i < seqs.size:
        j = i + 1  # extend the block by whole sequences
        while j < seqs.size and p_cut[j] - p_cut[i] < block_rows:
            j += 1
        p_end = p_cut[j] if j < seqs.size else len(pred)
        g_end = g_cut[j] if j < seqs.size else len(gt)
        rows_p, rows_g = p_order[p_cut[i] : p_end], g_order[g_cut[i] : g_end]
        sub_p, sub_g = pred.select(rows_p), gt.select(rows_g)
        ip, ig, dist = sparse_chamfer(
            prepare(sub_p, sampled),
            kp[rows_p],
            prepare(sub_g, sampled),
            kg[rows_g],
            max_dist,
            backend,
        )
        parts_p.append(rows_p[ip]), parts_g.append(rows_g[ig]), parts_d.append(dist)
        i = j
    ip = np.concatenate(parts_p + [np.zeros(0, np.int64)])
    ig = np.concatenate(parts_g + [np.zeros(0, np.int64)])
    dist = np.concatenate(parts_d + [np.zeros(0)])
    nearest_gt = np.full(len(pred), -1, dtype=np.int64)
    nearest_dist = np.full(len(pred), np.inf)
    order = np.lexsort((ig, dist, ip))  # by prediction, then distance, then gt row
    ip, ig, dist = ip[order], ig[order], dist[order]
    if ip.size:
        first = np.ones(ip.size, dtype=bool)
        first[1:] = ip[1:] != ip[:-1]
        nearest_gt[ip[first]] = ig[first]
        nearest_dist[ip[first]] = dist[first]
    # pairs sorted by prediction then gt row
    order = np.lexsort((ig, ip))
    return Matching(max_dist, ip[order], ig[order], dist[order], nearest_gt, nearest_dist)


def score_order(scores: NDArray[np.float64]) -> NDArray[np.int64]:
    """Row order by descending score, ties in table order."""
    return np.argsort(-scores, kind="stable").astype(np.int64)


def true_positives(m: Matching, order: NDArray[np.int64], threshold: float) -> NDArray[np.bool_]:
    """(N,) bool: the greedy TP decision of every prediction at one threshold.

    order (N,): the score order (:func:`score_order`). A prediction is TP iff its nearest ground
    truth is within the threshold and no earlier prediction (in score order) took that ground
    truth — equivalently, the first in score order among those whose nearest ground truth is it.
    """
    if threshold > m.max_dist:
        raise ValueError(f"threshold {threshold} exceeds the matching's max_dist {m.max_dist}")
    cand = order[m.nearest_dist[order] <= threshold]  # candidate rows, in score order
    _, first = np.unique(m.nearest_gt[cand], return_index=True)
    tp = np.zeros(m.nearest_gt.shape[0], dtype=bool)
    tp[cand[first]] = True
    return tp


def average_precision(tp_sorted: NDArray[np.bool_], num_gt: int) -> float:
    """VOC "area" AP of a ranked list of TP flags (score order); NaN when num_gt == 0."""
    if num_gt == 0:
        return float("nan")
    tp = np.cumsum(tp_sorted, dtype=np.float64)  # (n,)
    fp = np.cumsum(~tp_sorted, dtype=np.float64)  # (n,)
    eps = np.finfo(np.float32).eps
    recall = tp / max(num_gt, eps)
    precision = tp / np.maximum(tp + fp, eps)
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[0.0], precision, [0.0]])
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]  # monotone envelope
    idx = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[idx + 1] - mrec[idx]) * mpre[idx + 1]))


def ap_table(
    pred: Instances, gt: Instances, tp: NDArray[np.bool_], order: NDArray[np.int64]
) -> dict[str, float]:
    """Per-class AP from TP flags (N,) and the score order -> {class name: AP}."""
    out = {}
    cls_sorted = pred.classes[order]
    for c, name in enumerate(CLASS_NAMES):
        ranked = tp[order][cls_sorted == c]
        out[name] = average_precision(ranked, int(np.count_nonzero(gt.classes == c)))
    return out


def mean_ignore_nan(values: list[float]) -> float:
    """Mean of the finite-or-inf values, NaN entries (classes without ground truth) left out."""
    vals = [v for v in values if not np.isnan(v)]
    return float(np.mean(vals)) if vals else float("nan")


def detection_ap(
    pred: Instances,
    gt: Instances,
    thresholds: tuple[float, ...],
    m: Matching | None = None,
) -> dict:
    """Detection AP per class and threshold, per-class mean and mAP.

    Returns {"thresholds": [...], "AP": {class: {str(thr): AP}}, "AP_class": {class: mean over
    thresholds}, "mAP": mean over classes and thresholds}. Classes without ground truth give NaN
    and are left out of the means.
    """
    return ap_summary(pred, gt, thresholds, m)


def ap_summary(
    pred: Instances,
    gt: Instances,
    thresholds: tuple[float, ...],
    m: Matching | None = None,
    keep: Callable[[Instances, Instances, Matching, NDArray[np.bool_]], NDArray[np.bool_]]
    | None = None,
    prefix: str = "",
) -> dict:
    """AP per class and threshold, per-class mean and mean, under the keys ``detection_ap``
    names, each with ``prefix``; ``keep`` turns the TP flags (N,) of a threshold into those that
    count (C-mAP's consistency rule), None keeps them all."""
    m = match(pred, gt, max(thresholds)) if m is None else m
    order = score_order(pred.scores)
    per: dict[str, dict[str, float]] = {name: {} for name in CLASS_NAMES}
    for thr in thresholds:
        tp = true_positives(m, order, thr)
        if keep is not None:
            tp = keep(pred, gt, m, tp)
        aps = ap_table(pred, gt, tp, order)
        for name in CLASS_NAMES:
            per[name][f"{thr:g}"] = aps[name]
    ap_class = {name: mean_ignore_nan(list(per[name].values())) for name in CLASS_NAMES}
    return {
        "thresholds": [float(t) for t in thresholds],
        f"{prefix}AP": per,
        f"{prefix}AP_class": ap_class,
        f"{prefix}mAP": mean_ignore_nan(list(ap_class.values())),
    }
