"""Evaluation benchmark: ``python -m benchmarks eval [--seqs 150 --frames 40 --preds 50]``.

Builds a synthetic workload (seeded) of S sequences x T frames x P predictions per frame at both
perception ranges (ground-truth tracks of dividers, boundaries and crossings; noisy predictions
with occasional ID changes; low-score false positives; per-sequence global maps), times
``evaluate`` (detection AP, C-mAP, tracking, global-map CD and GAP) at both ranges, and prints the
ratio against a straightforward numpy + shapely implementation of the same AP protocol (shapely
resampling, a Chamfer distance per instance pair, Python greedy matching), which is timed on a
subset of the sequences and extrapolated linearly (said so in the output). Also times the exact
Chamfer stage with the numpy and the engine backends on the same pairs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from icmapper.eval.chamfer import NUM_SAMPLES, Resampled, chamfer_pairs, group_pairs
from icmapper.eval.detection import CLASS_NAMES, THRESHOLDS, average_precision
from icmapper.eval.instances import Instances
from icmapper.eval.runfmt import FramePredictions
from numpy.typing import NDArray


class _GT:
    """FrameGT-like container (ids, classes, points)."""

    def __init__(self, ids: NDArray, classes: NDArray, points: NDArray) -> None:
        self.ids, self.classes, self.points = ids, classes, points


def _smooth_line(rng: np.random.Generator, half: tuple[float, float], y: float) -> NDArray:
    hx, _ = half
    x = np.linspace(-hx * rng.uniform(0.5, 1.0), hx * rng.uniform(0.5, 1.0), 20)
    curv = rng.normal(0, 0.002)
    return np.stack([x, y + curv * x**2], axis=1)  # (20, 2)


def _rect(x: float, y: float, w: float, h: float) -> NDArray:
    ring = np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h], [x, y]])
    seg = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    s = np.linspace(0, seg.sum(), 21)[:20]
    cum = np.r_[0, np.cumsum(seg)]
    return np.stack([np.interp(s, cum, ring[:, 0]), np.interp(s, cum, ring[:, 1])], axis=1)


def make_sequence(
    rng: np.random.Generator, num_frames: int, num_preds: int, half: tuple[float, float], seq: int
) -> tuple[list[FramePredictions], list[_GT]]:
    """One synthetic sequence: GT tracks drifting backwards (the ego drives forward 2 m/frame)."""
    hx, hy = half
    tracks = []  # (id, cls, base points (20, 2))
    lanes = np.arange(-hy + 2.0, hy - 1.0, 3.5)
    for k, y in enumerate(lanes):
        tracks.append((k, 1, _smooth_line(rng, half, y)))
    tracks.append((100, 2, _smooth_line(rng, half, -hy + 0.5)))
    tracks.append((101, 2, _smooth_line(rng, half, hy - 0.5)))
    for k in range(int(rng.integers(1, 4))):
        tracks.append((200 + k, 0, _rect(rng.uniform(-hx, hx - 4), -hy * 0.6, 4.0, hy * 1.2)))
    preds, gts = [], []
    id_map = {t[0]: 1000 + t[0] for t in tracks}
    next_id = 5000
    for f in range(num_frames):
        g_ids, g_cls, g_pts = [], [], []
        for tid, c, base in tracks:
            pts = base - np.array([(2.0 * f) % (2 * hx) - hx * 0.5, 0.0])
            pts[:, 0] = np.clip(pts[:, 0], -hx, hx)
            if np.ptp(pts[:, 0]) < 1.0:
                continue
            g_ids.append(tid), g_cls.append(c), g_pts.append(pts)
        gts.append(_GT(np.array(g_ids), np.array(g_cls), np.array(g_pts, dtype=np.float32)))
        p_cls, p_pts, p_sc, p_id = [], [], [], []
        for tid, c, pts in zip(g_ids, g_cls, g_pts, strict=True):
            if rng.random() < 0.15:
                continue
            if rng.random() < 0.01:
                id_map[tid] = next_id
                next_id += 1
            noise = rng.normal(0, 0.25, (1, 2)) + rng.normal(0, 0.15, (20, 2))
            p_cls.append(c), p_pts.append(pts + noise), p_sc.append(rng.uniform(0.4, 1.0))
            p_id.append(id_map[tid])
        while len(p_cls) < num_preds:
            c = int(rng.integers(0, 3))
            if c == 0:
                pts = _rect(rng.uniform(-hx, hx - 4), rng.uniform(-hy, hy - 8), 4.0, 8.0)
            else:
                pts = _smooth_line(rng, half, rng.uniform(-hy, hy))
            p_cls.append(c), p_pts.append(pts), p_sc.append(rng.uniform(0.0, 0.45))
            p_id.append(next_id)
            next_id += 1
        pose = np.eye(4)
        pose[0, 3] = 2.0 * f
        preds.append(
            FramePredictions(
                f, pose, np.array(p_cls), np.array(p_sc), np.array(p_pts, dtype=np.float32),
                np.array(p_id), float(f) * 0.5,
            )
        )  # fmt: skip
    return preds, gts


def make_global(rng: np.random.Generator, half: tuple[float, float]) -> tuple[list, list]:
    """A synthetic global map pair: (pred [(cls, pts, closed, score)], gt [(cls, pts, closed)])."""
    gt = []
    for y in np.arange(-half[1] + 2.0, half[1] - 1.0, 3.5):
        x = np.linspace(-20, 100, 120)
        gt.append((1, np.stack([x, y + 0.01 * x], 1), False))
    for k in range(3):
        gt.append((0, _rect(10.0 + 25 * k, -6, 4, 12), True))
    pred = [(c, p + rng.normal(0, 0.2, p.shape), cl, float(rng.integers(1, 20))) for c, p, cl in gt]
    return pred, gt


def make_workload(seqs: int, frames: int, preds: int, half: tuple[float, float], seed: int):
    rng = np.random.default_rng(seed)
    P, G, GP, GG = [], [], [], []
    for s in range(seqs):
        p, g = make_sequence(rng, frames, preds, half, s)
        gp, gg = make_global(rng, half)
        P.append(p), G.append(g), GP.append(gp), GG.append(gg)
    return P, G, GP, GG


def make_dataset(
    num_seqs: int, num_frames: int, num_preds: int, half: tuple[float, float], seed: int
) -> tuple[Instances, Instances]:
    """The workload's per-frame predictions and GT as flat tables (pred, gt)."""
    from icmapper.eval.evaluate import _gt_table, _pred_table

    P, G, _, _ = make_workload(num_seqs, num_frames, num_preds, half, seed)
    return _pred_table(P), _gt_table(G)


def reference_ap(pred: Instances, gt: Instances, thresholds: tuple[float, ...]) -> dict:
    """Straightforward numpy + shapely AP of the same protocol (the speed baseline, and an
    independent oracle in the tests)."""
    import shapely

    def samples(pts: NDArray, closed: bool) -> NDArray:
        ring = np.vstack([pts, pts[:1]]) if closed else pts
        ls = shapely.LineString(ring)
        fr = np.arange(NUM_SAMPLES) / NUM_SAMPLES if closed else np.linspace(0, 1, NUM_SAMPLES)
        return shapely.get_coordinates(ls.interpolate(fr, normalized=True))

    def chamfer(a: NDArray, b: NDArray) -> float:
        d = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))
        return (d.min(1).sum() + d.min(0).sum()) / (2 * NUM_SAMPLES)

    out: dict[str, dict[str, float]] = {}
    frames = sorted(set(zip(pred.seq.tolist(), pred.frame.tolist(), strict=True)))
    for c, name in enumerate(CLASS_NAMES):
        # per frame: nearest GT (row, distance) of every prediction of the class
        nearest: dict[int, tuple[int, float]] = {}
        for s, f in frames:
            prow = np.flatnonzero((pred.seq == s) & (pred.frame == f) & (pred.classes == c))
            grow = np.flatnonzero((gt.seq == s) & (gt.frame == f) & (gt.classes == c))
            gs = [samples(gt.points[j], c == 0) for j in grow]
            for i in prow:
                ps = samples(pred.points[i], c == 0)
                best = (-1, np.inf)
                for j, g in zip(grow, gs, strict=True):
                    d = chamfer(ps, g)
                    if d < best[1]:
                        best = (int(j), d)
                nearest[int(i)] = best
        rows = [i for i in np.argsort(-pred.scores, kind="stable") if pred.classes[i] == c]
        num_gt = int((gt.classes == c).sum())
        out[name] = {}
        for thr in thresholds:
            taken: set[int] = set()
            tp = []
            for i in rows:
                j, d = nearest[int(i)]
                ok = j >= 0 and d <= thr and j not in taken
                if ok:
                    taken.add(j)
                tp.append(ok)
            out[name][f"{thr:g}"] = average_precision(np.array(tp, dtype=bool), num_gt)
    return out


def _time_backends(pred: Instances, gt: Instances, max_pairs: int) -> dict[str, float]:
    """Seconds per pair of the exact Chamfer stage, numpy vs engine, on the same pairs."""
    ka = (pred.seq * 10_000 + pred.frame) * 3 + pred.classes
    kb = (gt.seq * 10_000 + gt.frame) * 3 + gt.classes
    ia, ib = group_pairs(ka, kb)
    ia, ib = ia[:max_pairs], ib[:max_pairs]
    a, b = (
        Resampled.from_points(pred.points, pred.classes == 0),
        Resampled.from_points(gt.points, gt.classes == 0),
    )
    fa, fb = a.fine[ia], b.fine[ib]
    out = {}
    for backend in ("numpy", "engine"):
        try:
            t0 = time.perf_counter()
            chamfer_pairs(fa, fb, backend)
            out[backend] = (time.perf_counter() - t0) / max(len(ia), 1)
        except Exception as exc:  # engine missing or unfinished: report, do not fail
            print(f"  backend {backend}: unavailable ({type(exc).__name__}: {exc})")
    return out


def main(argv: list[str] | None = None) -> int:
    from icmapper.eval.evaluate import _gt_table, _pred_table, evaluate

    ap = argparse.ArgumentParser(prog="python -m benchmarks eval", description=__doc__)
    ap.add_argument("--seqs", type=int, default=150)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--preds", type=int, default=50)
    ap.add_argument("--ref-seqs", type=int, default=3, help="sequences timed for the reference")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    total = total_cpu = 0.0
    ratios = []
    for range_name, half in (("60x30", (30.0, 15.0)), ("100x50", (50.0, 25.0))):
        P, G, GP, GG = make_workload(args.seqs, args.frames, args.preds, half, args.seed)
        n_gt = sum(len(g.ids) for gs in G for g in gs)
        print(f"[{range_name}] {args.seqs} seqs x {args.frames} frames x {args.preds} preds, "
              f"{n_gt} GT instances")  # fmt: skip
        t0, c0 = time.perf_counter(), time.process_time()
        res = evaluate(P, G, GP, GG, range_name)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        total += dt
        total_cpu += dc
        print(f"  evaluate (all metrics): {dt:.2f} s wall, {dc:.2f} s CPU")
        print(f"  mAP {res['detection']['mAP']:.4f}  "
              f"C-mAP {res['consistency']['C-mAP']:.4f}  MOTA {res['tracking']['mean']['MOTA']:.4f}"
              f"  mCD {res['mapping']['mCD']:.4f}")  # fmt: skip
        # reference AP on a subset, extrapolated
        k = min(args.ref_seqs, args.seqs)
        pred_sub, gt_sub = _pred_table(P[:k]), _gt_table(G[:k])
        t0 = time.perf_counter()
        ref = reference_ap(pred_sub, gt_sub, THRESHOLDS[range_name])
        t_ref = (time.perf_counter() - t0) * args.seqs / k
        from icmapper.eval.detection import detection_ap

        t0 = time.perf_counter()
        ours_sub = detection_ap(pred_sub, gt_sub, THRESHOLDS[range_name])
        t_ours_sub = time.perf_counter() - t0
        same = all(
            np.isclose(ours_sub["AP"][n][t], ref[n][t], atol=1e-9, equal_nan=True)
            for n in CLASS_NAMES for t in ref[n]
        )  # fmt: skip
        print(f"  reference numpy+shapely AP: {t_ref:.1f} s for all {args.seqs} seqs "
              f"(timed on {k}, extrapolated linearly); same AP on the subset: {same}")  # fmt: skip
        ap_ratio = t_ref * k / args.seqs / t_ours_sub
        print(f"  speed-up of the whole evaluate (all metrics) over the reference AP alone: "
              f"{t_ref / dt:.1f}x; AP alone on the subset: {ap_ratio:.1f}x")  # fmt: skip
        ratios.append(t_ref / dt)
        per = _time_backends(pred_sub, gt_sub, 3000)
        if per:
            print("  exact Chamfer stage per pair: "
                  + ", ".join(f"{b} {v * 1e6:.1f} us" for b, v in per.items()))  # fmt: skip
    print(f"total evaluate time, both ranges: {total:.2f} s wall, {total_cpu:.2f} s CPU "
          "(bound: 60 s)")  # fmt: skip
    return 0
