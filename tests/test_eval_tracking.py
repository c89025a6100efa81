"""The MOT accumulator agrees with py-motmetrics (the reference) on random and adversarial input."""

from __future__ import annotations

import motmetrics as mm
import numpy as np
import pytest
from icmapper.eval.instances import from_frames
from icmapper.eval.tracking import MotAccumulator, summarize, tracking_metrics


def _reference(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> dict[str, float]:
    acc = mm.MOTAccumulator(auto_id=True)
    for oids, hids, d in frames:
        acc.update(oids, hids, d)
    s = mm.metrics.create().compute(
        acc, metrics=["mota", "motp", "num_switches", "num_misses", "num_false_positives"]
    )
    return {k: float(s[k].iloc[0]) for k in s.columns}


def _ours(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> dict[str, float]:
    acc = MotAccumulator()
    for oids, hids, d in frames:
        acc.update(oids, hids, d)
    return summarize([acc])


def _random_frames(rng: np.random.Generator, num_frames: int, adversarial: bool):
    frames = []
    for _ in range(num_frames):
        oids = rng.choice(8, size=rng.integers(0, 6), replace=False)
        hids = rng.choice(10, size=rng.integers(0, 7), replace=False)
        if adversarial:  # ties, few allowed values, many forbidden pairs
            d = rng.choice([0.2, 0.5, 0.5, 1.0, np.nan, np.nan], size=(oids.size, hids.size))
        else:
            d = rng.uniform(0, 2.0, size=(oids.size, hids.size))
            d[d > 1.5] = np.nan
        frames.append((oids, hids, d))
    return frames


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("adversarial", [False, True])
def test_accumulator_matches_motmetrics(seed: int, adversarial: bool) -> None:
    frames = _random_frames(np.random.default_rng(seed), 25, adversarial)
    ref, ours = _reference(frames), _ours(frames)
    assert ours["num_switches"] == ref["num_switches"]
    assert ours["num_misses"] == ref["num_misses"]
    assert ours["num_false_positives"] == ref["num_false_positives"]
    assert ours["MOTA"] == pytest.approx(ref["mota"], abs=1e-12, nan_ok=True)
    assert ours["MOTP"] == pytest.approx(ref["motp"], abs=1e-12, nan_ok=True)


def test_id_swap_counts_like_motmetrics() -> None:
    # two GT tracks (1, 2) followed by hypotheses (10, 11) which swap at frame 2
    d_keep = np.array([[0.1, np.nan], [np.nan, 0.1]])
    d_swap = np.array([[np.nan, 0.1], [0.1, np.nan]])
    ids = (np.array([1, 2]), np.array([10, 11]))
    frames = [(*ids, d_keep), (*ids, d_keep), (*ids, d_swap), (*ids, d_swap)]
    ours, ref = _ours(frames), _reference(frames)
    assert ours["num_switches"] == ref["num_switches"] == 2
    assert ours["MOTA"] == pytest.approx(ref["mota"])


def _line(y: float, x0: float = -10.0) -> np.ndarray:
    return np.stack([np.linspace(x0, x0 + 20, 20), np.full(20, y)], axis=1)


def test_pipeline_matches_motmetrics_on_chamfer() -> None:
    """End to end through Chamfer matching with a gate: same numbers as motmetrics fed the same
    gated Chamfer distances."""
    from icmapper.geom import chamfer_matrix, resample_many

    rng = np.random.default_rng(3)
    gt_frames, pred_frames, ref_frames = [], [], []
    for _ in range(12):
        gys = np.array([-6.0, -2.0, 2.0, 6.0])
        g_ids = np.arange(4)
        g_pts = np.stack([_line(y) for y in gys])
        keep = rng.random(4) > 0.2
        h_ids = rng.permutation(6)[:5]
        h_pts = np.stack([_line(gys[i % 4] + rng.normal(0, 0.8)) for i in range(5)])
        scores = rng.uniform(0.5, 1.0, 5)
        gt_frames.append((g_ids[keep], np.ones(keep.sum(), int), g_pts[keep], None))
        pred_frames.append((h_ids, np.ones(5, int), h_pts, scores))
        d = chamfer_matrix(resample_many(g_pts[keep], 200), resample_many(h_pts, 200))
        d[d > 1.5] = np.nan
        ref_frames.append((g_ids[keep], h_ids, d))
    gt, pred = from_frames(0, gt_frames), from_frames(0, pred_frames)
    out = tracking_metrics(pred, gt, gate=1.5, num_seqs=1, score_threshold=0.0)
    ref = _reference(ref_frames)
    div = out["per_class"]["divider"]
    assert div["num_switches"] == ref["num_switches"]
    assert div["MOTA"] == pytest.approx(ref["mota"], abs=1e-9)
    assert div["MOTP"] == pytest.approx(ref["motp"], abs=1e-9)
