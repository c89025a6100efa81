"""Tracking metrics (CLEAR MOT): MOTA, MOTP, ID switches per class (numpy + scipy, no I/O).

The accumulator reproduces py-motmetrics' ``MOTAccumulator.update`` (default
``max_switch_time=inf``, scipy solver) event for event:

1. an object whose last correspondence is a hypothesis present in this frame within the gate keeps
   it (MATCH), objects in input order;
2. the remaining objects and hypotheses are assigned by ``scipy.optimize.linear_sum_assignment``
   on the distances, forbidden pairs replaced by motmetrics' large constant; an assigned allowed
   pair is a SWITCH if the object's last correspondence was another hypothesis, else a MATCH;
3. unassigned objects are misses, unassigned hypotheses false positives.

MOTA = 1 - (misses + false positives + switches) / objects, MOTP = mean distance of MATCH and
SWITCH pairs (here the Chamfer distance in metres: lower is better). Matching is per frame and per
class on the Chamfer distance, a pair allowed iff its distance <= the gate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from icmapper.eval.detection import CLASS_NAMES, Matching, match, mean_ignore_nan
from icmapper.eval.instances import Instances

#: Default matching gate (metres of Chamfer distance) per perception range: the largest AP
#: threshold of that range.
GATES: dict[str, float] = {"60x30": 1.5, "100x50": 2.0}
#: Predictions below this score are not part of the tracking output.
DEFAULT_SCORE_THRESHOLD = 0.4


def _expensive(costs: NDArray[np.float64]) -> NDArray[np.float64]:
    """motmetrics' ``add_expensive_edges``: non-finite -> 2 * min(shape) * (max|c| + 1) + 1."""
    valid = np.isfinite(costs)
    if valid.all():
        return costs.copy()
    if not valid.any():
        return np.zeros_like(costs)
    c = np.abs(costs[valid]).max() + 1
    return np.where(valid, costs, 2 * min(costs.shape) * c + 1)


@dataclass
class MotAccumulator:
    """CLEAR MOT counts of one sequence (one class). ``update`` once per frame."""

    num_objects: int = 0
    num_matches: int = 0
    num_switches: int = 0
    num_misses: int = 0
    num_false_positives: int = 0
    dist_sum: float = 0.0
    last: dict[int, int] = field(default_factory=dict)  # object id -> last hypothesis id

    def update(
        self, oids: NDArray[np.int64], hids: NDArray[np.int64], dists: NDArray[np.float64]
    ) -> None:
        """oids (n,) object ids, hids (m,) hypothesis ids (each unique in the frame), dists
        (n, m) with NaN for forbidden pairs."""
        n, m = oids.shape[0], hids.shape[0]
        self.num_objects += n
        o_done = np.zeros(n, dtype=bool)
        h_done = np.zeros(m, dtype=bool)
        if n and m:
            dists = dists.astype(np.float64, copy=True)
            h_pos = {int(h): j for j, h in enumerate(hids)}
            for i in range(n):  # 1. keep previous correspondences
                prev = self.last.get(int(oids[i]))
                j = h_pos.get(prev) if prev is not None else None
                if j is None or h_done[j] or not np.isfinite(dists[i, j]):
                    continue
                o_done[i] = h_done[j] = True
                self.num_matches += 1
                self.dist_sum += float(dists[i, j])
            dists[o_done, :] = np.nan
            dists[:, h_done] = np.nan
            if np.isfinite(dists).any():  # 2. assignment of the rest
                rows, cols = linear_sum_assignment(_expensive(dists))
                for i, j in zip(rows, cols, strict=True):
                    if not np.isfinite(dists[i, j]):
                        continue
                    o, h = int(oids[i]), int(hids[j])
                    if o in self.last and self.last[o] != h:
                        self.num_switches += 1
                    else:
                        self.num_matches += 1
                    self.dist_sum += float(dists[i, j])
                    o_done[i] = h_done[j] = True
                    self.last[o] = h
        self.num_misses += int(n - o_done.sum())
        self.num_false_positives += int(m - h_done.sum())


def summarize(accs: list[MotAccumulator]) -> dict[str, float]:
    """Pools accumulators (sequences): MOTA and MOTP over all, IDS = switches per sequence."""
    tot = {
        k: sum(getattr(a, k) for a in accs)
        for k in ("num_objects", "num_matches", "num_switches", "num_misses", "num_false_positives")
    }
    dist = sum(a.dist_sum for a in accs)
    det = tot["num_matches"] + tot["num_switches"]
    errors = tot["num_misses"] + tot["num_switches"] + tot["num_false_positives"]
    return {
        "MOTA": 1.0 - errors / tot["num_objects"] if tot["num_objects"] else float("nan"),
        "MOTP": dist / det if det else float("nan"),
        "IDS": tot["num_switches"] / len(accs) if accs else float("nan"),
        **{k: float(v) for k, v in tot.items()},
    }


def accumulate(
    pred: Instances, gt: Instances, m: Matching, gate: float, num_seqs: int
) -> list[list[MotAccumulator]]:
    """Runs the accumulators: -> accs[class][seq].

    pred: the tracking output (already score-filtered); m: its matching with max_dist >= gate.
    Track ids (pred.ids) must be unique per frame and class.
    """
    if gate > m.max_dist:
        raise ValueError(f"gate {gate} exceeds the matching's max_dist {m.max_dist}")
    num_frames = int(max(pred.frame.max(initial=0), gt.frame.max(initial=0))) + 1
    num_c = len(CLASS_NAMES)
    kp, kg = pred.key(num_frames, num_c), gt.key(num_frames, num_c)
    allowed = m.pairs_dist <= gate
    pp, pg, pd = m.pairs_pred[allowed], m.pairs_gt[allowed], m.pairs_dist[allowed]
    # group rows by key
    order_p, order_g = np.argsort(kp, kind="stable"), np.argsort(kg, kind="stable")
    keys = np.union1d(kp, kg)
    sp = np.searchsorted(kp[order_p], keys, "left"), np.searchsorted(kp[order_p], keys, "right")
    sg = np.searchsorted(kg[order_g], keys, "left"), np.searchsorted(kg[order_g], keys, "right")
    # pairs by key of their prediction
    order_pairs = np.argsort(kp[pp], kind="stable")
    kpair = kp[pp][order_pairs]
    spair = np.searchsorted(kpair, keys, "left"), np.searchsorted(kpair, keys, "right")
    pos_p = np.empty(len(pred), dtype=np.int64)
    pos_g = np.empty(len(gt), dtype=np.int64)
    accs = [[MotAccumulator() for _ in range(num_seqs)] for _ in range(num_c)]
    for k_i, key in enumerate(keys):  # keys are ordered by seq, frame, class
        c = int(key % num_c)
        s = int(key // num_c // num_frames)
        rows_p = order_p[sp[0][k_i] : sp[1][k_i]]
        rows_g = order_g[sg[0][k_i] : sg[1][k_i]]
        dists = np.full((rows_g.size, rows_p.size), np.nan)
        sel = order_pairs[spair[0][k_i] : spair[1][k_i]]
        if sel.size:
            pos_p[rows_p] = np.arange(rows_p.size)
            pos_g[rows_g] = np.arange(rows_g.size)
            dists[pos_g[pg[sel]], pos_p[pp[sel]]] = pd[sel]
        accs[c][s].update(gt.ids[rows_g], pred.ids[rows_p], dists)
    return accs


def tracking_metrics(
    pred: Instances,
    gt: Instances,
    gate: float,
    num_seqs: int,
    score_threshold: float = DEFAULT_SCORE_THRESHOLD,
    m: Matching | None = None,
) -> dict:
    """MOTA / MOTP / IDS per class and their mean over classes.

    pred: all predictions (those with score >= score_threshold are the tracking output);
    m: optional matching of *all* predictions (max_dist >= gate), reused when given.
    Returns {"gate", "score_threshold", "per_class": {class: {MOTA, MOTP, IDS, num_*}},
    "mean": {MOTA, MOTP, IDS}} (means over classes with ground truth).
    """
    keep = pred.scores >= score_threshold
    if m is None:
        sub = pred.select(keep)
        m_sub = match(sub, gt, gate)
    else:  # restrict the matching to the kept rows
        new_row = np.cumsum(keep) - 1
        sel = keep[m.pairs_pred]
        sub = pred.select(keep)
        m_sub = Matching(
            m.max_dist,
            new_row[m.pairs_pred[sel]],
            m.pairs_gt[sel],
            m.pairs_dist[sel],
            m.nearest_gt[keep],
            m.nearest_dist[keep],
        )
    accs = accumulate(sub, gt, m_sub, gate, num_seqs)
    per = {name: summarize(accs[c]) for c, name in enumerate(CLASS_NAMES)}
    valid = [per[n] for n in CLASS_NAMES if per[n]["num_objects"] > 0]
    mean = {k: mean_ignore_nan([v[k] for v in valid]) for k in ("MOTA", "MOTP", "IDS")}
    return {"gate": gate, "score_threshold": score_threshold, "per_class": per, "mean": mean}
