"""Oracle detection source (icmapper.mapping.oracle): exactness without noise, determinism from
(seed, frame index), and the noise statistics it is configured with."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data.types import FrameGT, Sequence, WorldMap, xy_yaw_to_pose
from icmapper.mapping.oracle import OracleDetector, OracleNoise
from icmapper.mapping.types import Detections

NUM_FRAMES = 50


def _line(y: float, x0: float = -25.0, x1: float = 25.0) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, 20), np.full(20, y)], axis=1)


def _rect(cx: float, cy: float) -> np.ndarray:
    # 20 points along the contour of a 4 x 10 m rectangle.
    t = np.linspace(0.0, 28.0, 20, endpoint=False)
    ring = np.array([[-2, -5], [2, -5], [2, 5], [-2, 5], [-2, -5]], float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    return np.stack([np.interp(t, s, ring[:, 0]) + cx, np.interp(t, s, ring[:, 1]) + cy], axis=1)


def _fixture() -> tuple[Sequence, list[FrameGT]]:
    """A sequence of NUM_FRAMES frames, each with the same six GT instances (ego frame)."""
    inst = [_line(-7.0), _line(-3.5), _line(0.0), _line(3.5), _line(7.0), _rect(10.0, 0.0)]
    classes = np.array([2, 1, 1, 1, 2, 0], np.int64)
    pts = np.stack(inst).astype(np.float32)  # (6, 20, 2)
    gt = [FrameGT(np.arange(6, dtype=np.int64) + 100, classes, pts) for _ in range(NUM_FRAMES)]
    poses = np.stack([xy_yaw_to_pose(5.0 * i, 0.0, 0.0) for i in range(NUM_FRAMES)])
    seq = Sequence(
        name="oracle-test",
        source="test",
        world=WorldMap("empty", []),
        timestamps=np.arange(NUM_FRAMES) * 0.5,
        poses=poses,
        rig=None,  # type: ignore[arg-type]  # no cameras needed
    )
    return seq, gt


def _all(det: OracleDetector, seq: Sequence) -> list[Detections]:
    return [det.detect(seq.frame(i, with_images=False)) for i in range(len(seq))]


def test_none_noise_gives_exact_ground_truth() -> None:
    seq, gt = _fixture()
    det = OracleDetector(seq, noise="none", gt=gt)
    for i, d in enumerate(_all(det, seq)):
        d.validate()
        assert d.queries is None and d.gt_ids is not None
        order = np.argsort(d.gt_ids)
        np.testing.assert_array_equal(d.gt_ids[order], gt[i].ids)
        np.testing.assert_array_equal(d.classes[order], gt[i].classes)
        np.testing.assert_array_equal(d.points[order], gt[i].points)
        np.testing.assert_array_equal(d.scores, 1.0)
        assert d.points.dtype == np.float32 and d.scores.dtype == np.float32


def test_deterministic_from_seed_and_frame_index() -> None:
    seq, gt = _fixture()
    a = OracleDetector(seq, noise="high", seed=3, gt=gt)
    b = OracleDetector(seq, noise="high", seed=3, gt=gt)
    f7 = seq.frame(7, with_images=False)
    first = a.detect(f7)
    for _ in range(3):  # other frames asked in between change nothing
        a.detect(seq.frame(2, with_images=False))
    for d in (a.detect(f7), b.detect(f7)):
        np.testing.assert_array_equal(d.points, first.points)
        np.testing.assert_array_equal(d.scores, first.scores)
        np.testing.assert_array_equal(d.gt_ids, first.gt_ids)
    other = OracleDetector(seq, noise="high", seed=4, gt=gt).detect(f7)
    assert other.points.shape != first.points.shape or not np.array_equal(
        other.points, first.points
    )


def test_noise_statistics_match_configuration() -> None:
    seq, gt = _fixture()
    noise = OracleNoise(
        jitter_std=0.3, drop_rate=0.2, partial_rate=0.0, false_rate=0.5, score_std=0.05
    )
    dets = _all(OracleDetector(seq, noise=noise, seed=1, gt=gt), seq)
    n_true = sum(int((d.gt_ids >= 0).sum()) for d in dets)
    n_false = sum(int((d.gt_ids < 0).sum()) for d in dets)
    total_gt = 6 * NUM_FRAMES  # 300 instances: drop count ~ Binomial(300, 0.2), std 6.9
    assert abs((total_gt - n_true) - 0.2 * total_gt) < 4 * np.sqrt(total_gt * 0.2 * 0.8)
    # False detections ~ Poisson(0.5 * 50 = 25), std 5.
    assert abs(n_false - 25) < 4 * 5
    # Jitter: residuals to the true points (no partial, no offset) have the configured std.
    res = []
    for i, d in enumerate(dets):
        for j in np.nonzero(d.gt_ids >= 0)[0]:
            k = int(np.nonzero(gt[i].ids == d.gt_ids[j])[0][0])
            res.append(d.points[j] - gt[i].points[k])
    r = np.concatenate(res)  # (N * 20, 2)
    assert r.std() == pytest.approx(0.3, rel=0.05)
    assert abs(r.mean()) < 0.02
    # Scores: true ones high, false ones lower, all in [0, 1].
    s_true = np.concatenate([d.scores[d.gt_ids >= 0] for d in dets])
    s_false = np.concatenate([d.scores[d.gt_ids < 0] for d in dets])
    assert s_true.mean() == pytest.approx(0.85, abs=0.02)
    assert s_false.mean() == pytest.approx(0.4, abs=0.05)
    assert s_true.min() >= 0.0 and s_true.max() <= 1.0


def test_partial_visibility_shortens_polylines_only() -> None:
    seq, gt = _fixture()
    noise = OracleNoise(
        jitter_std=0.0, drop_rate=0.0, partial_rate=1.0, partial_min=0.5, false_rate=0
    )
    for i, d in enumerate(_all(OracleDetector(seq, noise=noise, gt=gt), seq)):
        assert len(d) == 6
        for j in range(6):
            length = np.linalg.norm(np.diff(d.points[j], axis=0), axis=1).sum()
            if d.classes[j] == 0:
                k = int(np.nonzero(gt[i].ids == d.gt_ids[j])[0][0])
                np.testing.assert_array_equal(d.points[j], gt[i].points[k])
            else:
                assert 25.0 - 1e-3 <= length < 50.0  # a sub-range of half to all of 50 m
                assert np.all(np.abs(d.points[j, :, 0]) <= 25.0 + 1e-4)


def test_empty_ground_truth_and_bad_config() -> None:
    seq, gt = _fixture()
    empty = [
        FrameGT(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 20, 2), np.float32))
    ]
    det = OracleDetector(seq, noise="low", gt=empty * NUM_FRAMES)
    d = det.detect(seq.frame(0, with_images=False))
    assert d.points.shape[1:] == (20, 2)
    d.validate()
    with pytest.raises(ValueError, match="drop_rate"):
        OracleNoise(drop_rate=1.5)
    with pytest.raises(ValueError, match="preset"):
        OracleNoise.preset("extreme")
    with pytest.raises(ValueError, match="ground-truth frames"):
        OracleDetector(seq, gt=gt[:3])
