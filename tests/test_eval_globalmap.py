"""GAP follows GlobalMapNet's scene evaluation (``plugin/datasets/evaluation/scene_eval.py``):
every global instance's raw coordinates resampled ONCE to 200 points with shapely's
``LineString.interpolate`` at ``linspace(0, length, 200)`` (crossings as closed lines), Chamfer
distance on those samples (issue 14, point 7). Shapely is the oracle."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from icmapper.eval.globalmap import gap_samples, global_metrics
from scipy.spatial.distance import cdist

TH = (0.5, 1.0, 1.5)


def interp_fixed_num(coords: np.ndarray, num: int = 200) -> np.ndarray:
    """GlobalMapNet's ``SceneEvaluate.interp_fixed_num``, written with shapely."""
    line = shapely.LineString(coords)
    distances = np.linspace(0, line.length, num)
    return np.array([line.interpolate(d).coords[0] for d in distances])  # (num, 2)


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    d = cdist(a, b)  # (200, 200)
    return (d.min(axis=1).sum() + d.min(axis=0).sum()) / (2 * len(a))


def zigzag() -> np.ndarray:
    """(121, 2) a divider zigzagging 0.6 m every 0.5 m over 60 m: 200 samples cut its corners, so
    a second resampling of the samples moves them (the bug this pins)."""
    x = np.linspace(0.0, 60.0, 121)
    return np.stack([x, np.where(np.arange(121) % 2 == 0, 0.0, 0.6)], axis=1)


def test_gap_samples_are_globalmapnets() -> None:
    rng = np.random.default_rng(0)
    line = np.cumsum(rng.normal(size=(37, 2)), axis=0)  # (37, 2)
    np.testing.assert_allclose(gap_samples(line, False), interp_fixed_num(line), atol=1e-9)
    ring = np.array([[0.0, 0.0], [4.0, 0.0], [4.5, 9.0], [0.0, 8.0]])  # crossing, not repeated
    closed_line = np.vstack([ring, ring[:1]])  # how GlobalMapNet stores a polygon's exterior
    samples = gap_samples(ring, True)  # (200, 2)
    np.testing.assert_allclose(samples, interp_fixed_num(closed_line), atol=1e-9)
    np.testing.assert_array_equal(samples[0], samples[-1])  # both ends: the start point


def test_near_threshold_match_uses_the_single_resampling() -> None:
    """A predicted divider 0.855 m beside the zigzag: Chamfer 0.494 m on GlobalMapNet's samples
    (TP at 0.5 m), 0.505 m after resampling the samples a second time (FP)."""
    gt = zigzag()
    pred = np.stack([np.linspace(0.0, 60.0, 7), np.full(7, 0.855)], axis=1)  # (7, 2)
    once = chamfer(interp_fixed_num(pred), interp_fixed_num(gt))
    twice = chamfer(
        interp_fixed_num(interp_fixed_num(pred)), interp_fixed_num(interp_fixed_num(gt))
    )
    assert once < 0.5 - 5e-3 and twice > 0.5 + 3e-3  # the case is near the threshold
    out = global_metrics([[(1, pred, False, 5.0)]], [[(1, gt, False)]], TH)
    assert out["GAP"]["divider"] == 1.0  # TP at 0.5, 1.0 and 1.5 m (twice: 2/3)
    # just beyond the threshold on GlobalMapNet's samples: FP at 0.5 m, TP at 1.0 and 1.5 m
    far = pred + [0.0, 0.02]
    assert chamfer(interp_fixed_num(far), interp_fixed_num(gt)) > 0.5
    out = global_metrics([[(1, far, False, 5.0)]], [[(1, gt, False)]], TH)
    assert out["GAP"]["divider"] == pytest.approx(2 / 3)


def test_gap_pairs_distances_equal_globalmapnets() -> None:
    """Every matched pair's distance is the Chamfer distance of GlobalMapNet's samples."""
    from icmapper.eval.detection import match
    from icmapper.eval.globalmap import _table

    rng = np.random.default_rng(1)
    gt = [(1, np.cumsum(rng.normal(size=(30, 2)), axis=0) * 2, False) for _ in range(6)]
    ring = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 9.0], [0.0, 9.0]])
    gt += [(0, ring + [10.0 * k, 0.0], True) for k in range(3)]
    pred = [(c, p + rng.normal(0, 0.3, size=p.shape), cl, 1.0) for c, p, cl in gt]
    pt, gtab = _table([pred]), _table([[(*g, 1.0) for g in gt]])
    m = match(pt, gtab, 2.0, sampled=True)
    assert m.pairs_pred.size >= len(gt)
    for i, j, d in zip(m.pairs_pred, m.pairs_gt, m.pairs_dist, strict=True):
        _, p, cl, _ = pred[i]
        _, g, _ = gt[j]
        close = (lambda x: np.vstack([x, x[:1]])) if cl else (lambda x: x)
        ref = chamfer(interp_fixed_num(close(p)), interp_fixed_num(close(g)))
        assert d == pytest.approx(ref, abs=1e-9)


def test_cd_halves_split_precision_coverage_and_strays() -> None:
    """A true 20 m divider; the map draws it 0.3 m off along its first 10 m only, plus a 2 m stray
    stub 5 m away: precision counts the stub, coverage the missing half, and the halves average
    to the CD the metric reports."""
    from icmapper.eval.globalmap import CLASS_NAMES, cd_halves, map_cd

    x = np.linspace(0.0, 20.0, 41)
    gt = [(1, np.stack([x, np.zeros_like(x)], 1), False)]
    half = np.stack([np.linspace(0.0, 10.0, 21), np.full(21, 0.3)], 1)
    stub = np.array([[5.0, 5.0], [5.0, 7.0]])
    pred = [(1, half, False), (1, stub, False)]
    h = cd_halves(pred, gt)["divider"]
    # the 21 samples of the half line lie 0.3 m off; the stub's 5 lie 5-7 m off
    assert h["kept"] == pytest.approx(0.3)
    assert h["stray"] == pytest.approx(5 / 26)
    stub_d = np.hypot(0.0, np.linspace(5.0, 7.0, 5)).mean()
    assert h["to"] == pytest.approx((21 * 0.3 + 5 * stub_d) / 26)
    gx = np.linspace(0.0, 20.0, 41)  # coverage: the ground truth's samples to the map
    far = np.hypot(np.clip(gx - 10.0, 0.0, None), 0.3)
    assert h["from"] == pytest.approx(far.mean(), abs=1e-9)
    assert (h["to"] + h["from"]) / 2 == pytest.approx(map_cd(pred, gt)["divider"])
    assert all(np.isnan(v) for v in cd_halves(pred, gt)[CLASS_NAMES[0]].values())
