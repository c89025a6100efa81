"""Global-map metrics: CD per class / mCD (HDMapNet-style dense Chamfer) and GAP (numpy + scipy).

CD: all instances of a class (predicted global map, ground-truth global map: world frame) are
sampled densely, every ``step`` metres along the arc length (closed crossings along their closed
contour), the samples of a class pooled; when a pool exceeds ``cap`` points it is subsampled
deterministically (``cap`` evenly strided indices). CD = (mean nearest distance pred->GT + mean
nearest distance GT->pred) / 2 (metres, lower is better). A class empty on both sides is NaN (left
out of mCD); empty on one side only is inf. mCD = mean over classes.

GAP (GlobalMapNet): Chamfer AP over global instances — the detection protocol (nearest-GT greedy
matching, VOC area AP) with each sequence's global map as one "frame"; an instance's score is its
observation count (ties in map order). Sampling as GlobalMapNet's ``interp_fixed_num``
(``plugin/datasets/evaluation/scene_eval.py``): the raw coordinates of every instance, a closed
crossing as its ring with the first point repeated at the end (GlobalMapNet stores polygons as
closed lines), are resampled ONCE to 200 points at ``linspace(0, length, 200)``
(:func:`gap_samples`), and the Chamfer distance is taken on those samples as they are.
"""

from __future__ import annotations

import os
from collections.abc import Sequence as Seq

import numpy as np
from numpy.typing import NDArray

from icmapper.eval.chamfer import NUM_SAMPLES
from icmapper.eval.detection import CLASS_NAMES, detection_ap, match, mean_ignore_nan
from icmapper.eval.instances import Instances
from icmapper.geom import cloud_chamfer, resample_many

#: Dense sampling step (metres) and per-class point cap of the CD metric.
CD_STEP = 0.5
CD_CAP = 200_000


def dense_sample(points: NDArray[np.floating], closed: bool, step: float = CD_STEP) -> NDArray:
    """(n, 2) polyline / ring -> (m, 2) float64 points every ``step`` metres by arc length
    (m = ceil(length / step) + 1 open, ceil(length / step) closed; at least 1)."""
    pts = np.asarray(points, dtype=np.float64)
    ring = np.vstack([pts, pts[:1]]) if closed else pts
    length = float(np.linalg.norm(np.diff(ring, axis=0), axis=1).sum())
    m = int(np.ceil(length / step)) + (0 if closed else 1)
    return resample_many(pts[None], max(m, 1), closed)[0]


def sample_distances(
    truth: NDArray[np.floating], lines: Seq[NDArray[np.floating]], closed: bool = False
) -> NDArray[np.float64]:
    """Distance (n,) from each sample of ``truth`` (m, 2), a polyline (a ring when ``closed``)
    sampled as the CD samples it, to the nearest sample of ``lines`` (each (k, 2), of the same
    kind): the coverage half of a CD, per sample, for diagnosis. Infinite without lines."""
    from scipy.spatial import cKDTree

    q = dense_sample(np.asarray(truth, np.float64), closed)
    if not lines:
        return np.full(len(q), np.inf)
    pts = np.concatenate([dense_sample(np.asarray(x, np.float64), closed) for x in lines])
    return cKDTree(pts).query(q)[0]


def _class_cloud(
    instances: Seq[tuple[int, NDArray, bool]], c: int, step: float, cap: int
) -> NDArray:
    clouds = [dense_sample(p, closed, step) for cls, p, closed in instances if cls == c]
    if not clouds:
        return np.zeros((0, 2))
    cloud = np.concatenate(clouds)  # (m, 2)
    if cloud.shape[0] > cap:
        cloud = cloud[np.linspace(0, cloud.shape[0] - 1, cap).round().astype(np.int64)]
    return cloud


def class_cd(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """CD of one class: ``geom.cloud_chamfer`` of the pooled samples (n, 2), (m, 2); NaN when
    both are empty, inf when one is."""
    if a.shape[0] == 0 and b.shape[0] == 0:
        return float("nan")
    if a.shape[0] == 0 or b.shape[0] == 0:
        return float("inf")
    return cloud_chamfer(a, b)


def map_cd(
    pred: Seq[tuple[int, NDArray, bool]],
    gt: Seq[tuple[int, NDArray, bool]],
    step: float = CD_STEP,
    cap: int = CD_CAP,
) -> dict[str, float]:
    """CD per class between one predicted and one GT global map: (cls, points (n, 2), closed)."""
    return {
        name: class_cd(_class_cloud(pred, c, step, cap), _class_cloud(gt, c, step, cap))
        for c, name in enumerate(CLASS_NAMES)
    }


def cd_halves(
    pred: Seq[tuple[int, NDArray, bool]],
    gt: Seq[tuple[int, NDArray, bool]],
    far: float = 1.0,
    step: float = CD_STEP,
) -> dict[str, dict[str, float]]:
    """The two halves of each class's CD between one predicted and one GT global map (cls,
    points (n, 2), closed), for diagnosis: ``to`` (mean distance of the map's samples to the
    ground truth's: precision), ``from`` (the ground truth's to the map's: coverage; CD is
    their mean), ``kept`` (``to`` over the map's instances lying within ``far`` metres of the
    ground truth on average) and ``stray`` (the share of the map's samples in the others).
    Sampled as the CD is, without its cap; NaN for a class empty on either side."""
    from scipy.spatial import cKDTree

    out = {}
    for c, name in enumerate(CLASS_NAMES):
        nan = float("nan")
        g = _class_cloud(gt, c, step, np.iinfo(np.int64).max)  # (m, 2)
        p = [dense_sample(pts, closed, step) for cls, pts, closed in pred if cls == c]
        if g.shape[0] == 0 or not p:
            out[name] = {"to": nan, "from": nan, "kept": nan, "stray": nan}
            continue
        tree = cKDTree(g)
        d = [tree.query(q)[0] for q in p]  # per instance (m_i,)
        near = [x for x in d if float(x.mean()) <= far]
        pooled = np.concatenate(d)
        out[name] = {
            "to": float(pooled.mean()),
            "from": float(cKDTree(np.concatenate(p)).query(g)[0].mean()),
            "kept": float(np.concatenate(near).mean()) if near else nan,
            "stray": 1.0 - sum(len(x) for x in near) / len(pooled),
        }
    return out


def gap_samples(points: NDArray[np.floating], closed: bool) -> NDArray[np.float64]:
    """GlobalMapNet's sampling of a global instance for GAP: (n, 2) -> (200, 2) float64, the
    coordinates as one line (closed: the first point appended) at 200 arc positions
    ``linspace(0, length, 200)``, both ends included."""
    pts = np.asarray(points, dtype=np.float64)  # (n, 2)
    line = np.vstack([pts, pts[:1]]) if closed else pts  # (n or n + 1, 2)
    return resample_many(line[None], NUM_SAMPLES, False)[0]  # (200, 2)


def _table(seq_instances: Seq[Seq[tuple[int, NDArray, bool, float]]]) -> Instances:
    """Global instances of every sequence (one frame each) with their GAP samples (N, 200, 2)."""
    rows = [(s, *inst) for s, insts in enumerate(seq_instances) for inst in insts]
    if not rows:
        return Instances.empty(NUM_SAMPLES)
    n = len(rows)
    return Instances(
        np.array([r[0] for r in rows], dtype=np.int64),
        np.zeros(n, dtype=np.int64),
        np.array([r[1] for r in rows], dtype=np.int64),
        np.arange(n, dtype=np.int64),
        np.array([r[4] for r in rows], dtype=np.float64),
        np.stack([gap_samples(r[2], r[3]) for r in rows]),  # (n, 200, 2)
    )


def global_metrics(
    pred: Seq[Seq[tuple[int, NDArray, bool, float]]],
    gt: Seq[Seq[tuple[int, NDArray, bool]]],
    thresholds: tuple[float, ...],
    step: float = CD_STEP,
    cap: int = CD_CAP,
) -> dict:
    """Mapping metrics over sequences.

    pred[s]: the predicted global map of sequence s as (cls, points (n, 2) world, closed, score);
    gt[s]: its ground-truth global map as (cls, points, closed). CD per class is averaged over the
    sequences where it is finite-or-inf (NaN left out); GAP pools all sequences.
    Returns {"CD": {class: m}, "mCD", "GAP": {class: AP}, "mGAP", "thresholds", "step", "cap"}.
    """
    if len(pred) != len(gt):
        raise ValueError(f"{len(pred)} predicted global maps for {len(gt)} sequences")
    per_seq = [map_cd([p[:3] for p in ps], gs, step, cap) for ps, gs in zip(pred, gt, strict=True)]
    cd = {name: mean_ignore_nan([r[name] for r in per_seq]) for name in CLASS_NAMES}
    gt_scored = [[(*g, 1.0) for g in gs] for gs in gt]
    pred_t, gt_t = _table(pred), _table(gt_scored)
    m = match(pred_t, gt_t, max(thresholds), sampled=True)  # the samples as they are
    ap = detection_ap(pred_t, gt_t, thresholds, m)
    return {
        "CD": cd,
        "mCD": mean_ignore_nan(list(cd.values())),
        "GAP": ap["AP_class"],
        "mGAP": ap["mAP"],
        "thresholds": list(ap["thresholds"]),
        "step": step,
        "cap": cap,
    }


def load_global_map(path: str | os.PathLike) -> list[tuple[int, NDArray, bool, float]]:
    """A native map file -> [(cls, points (n, 2) world, closed, score = observations)].

    Needs the engine (``icmapper.GlobalMap``)."""
    from icmapper import GlobalMap

    try:
        gm = GlobalMap.load(str(path))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot load the global map ({exc})") from None
    out = []
    for i in gm.ids():
        cls, pts = gm.get(int(i))
        info = gm.info(int(i))
        obs = info.get("observations", 1)
        out.append((int(cls), np.asarray(pts, dtype=np.float64), int(cls) == 0, float(obs or 1)))
    return out
