"""C-mAP, MapTracker's consistency-aware mAP (numpy, no I/O).

Like detection AP (same nearest-GT greedy matching, same thresholds), but a true positive is kept
only if its predicted track ID is the one first matched to that ground-truth track: per sequence
and ground-truth instance, the TPs are taken in frame order; the first fixes the predicted ID; a
later TP on the same ground truth with another predicted ID counts as a false positive. (The
reverse — one predicted ID moving to another ground truth — is not penalised; DESIGN.md.)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.detection import Matching, ap_summary
from icmapper.eval.instances import Instances


def consistent(
    pred: Instances, gt: Instances, m: Matching, tp: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """TP flags (N,) -> TP flags (N,) with inconsistent-ID TPs turned into false positives."""
    rows = np.flatnonzero(tp)
    g = m.nearest_gt[rows]
    # sort TPs by (sequence, gt class, gt id, frame)
    order = np.lexsort((pred.frame[rows], gt.ids[g], gt.classes[g], gt.seq[g]))
    rows, g = rows[order], g[order]
    key_seq, key_cls, key_id = gt.seq[g], gt.classes[g], gt.ids[g]
    new_key = np.ones(rows.size, dtype=bool)
    new_key[1:] = (
        (key_seq[1:] != key_seq[:-1]) | (key_cls[1:] != key_cls[:-1]) | (key_id[1:] != key_id[:-1])
    )
    first_of_key = np.maximum.accumulate(np.where(new_key, np.arange(rows.size), 0))
    first_track = pred.ids[rows[first_of_key]]
    out = tp.copy()
    out[rows[pred.ids[rows] != first_track]] = False
    return out


def consistency_map(
    pred: Instances, gt: Instances, thresholds: tuple[float, ...], m: Matching | None = None
) -> dict:
    """C-AP per class and threshold, per class, and C-mAP (same keys as detection_ap, "C-")."""
    return ap_summary(pred, gt, thresholds, m, keep=consistent, prefix="C-")
