"""MapTracker's C-mAP (eval/consistency_maptracker.py, eval/maptracker_tracks.py) on hand-built
sequences whose outcome is worked out by hand: an ID swap, a track re-found after a gap within
and beyond the look-back, the score filter and frames without ground truth; plus the raster
pieces against independent oracles (scipy's dilation, OpenCV's ellipse formula)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from icmapper.data.types import FrameGT, world_to_ego, xy_yaw_to_pose
from icmapper.eval.consistency_maptracker import maptracker_cmap
from icmapper.eval.evaluate import evaluate
from icmapper.eval.maptracker_tracks import ELLIPSE_7, Raster, derive_track_ids, dilate
from icmapper.eval.runfmt import FramePredictions

THR = (0.5, 1.0, 1.5)
HALF = (30.0, 15.0)


def _line(y: float) -> np.ndarray:
    """A world divider along x in [-10, 10] at height y: (20, 2)."""
    return np.stack([np.linspace(-10, 10, 20), np.full(20, y)], axis=1)


def _sequence(
    pred_ys: list[list[float]], gt_ys: list[float], moving: bool = False, score: float = 0.9
) -> tuple[list[FramePredictions], list[FrameGT]]:
    """Frame t predicts dividers at world heights pred_ys[t] (in that order); GT: one divider
    per height in gt_ys (id = its index) in every frame. moving: the ego drives 3 m a frame
    and turns 0.05 rad a frame, so predictions must be warped to match."""
    preds, gts = [], []
    for t, ys in enumerate(pred_ys):
        pose = xy_yaw_to_pose(3.0 * t, 0.5 * t, 0.05 * t) if moving else np.eye(4)
        ego = [world_to_ego(_line(y), pose) for y in ys]
        pts = np.array(ego, np.float32).reshape(len(ys), 20, 2)
        k = len(ys)
        preds.append(
            FramePredictions(
                t, pose, np.ones(k, np.int64), np.full(k, score), pts, np.arange(k, dtype=np.int64)
            )  # fmt: skip
        )
        g = np.array([world_to_ego(_line(y), pose) for y in gt_ys], np.float32)
        gts.append(FrameGT(np.arange(len(gt_ys), dtype=np.int64), np.ones(len(gt_ys), np.int64), g))
    return preds, gts


def _ids(preds: list[FramePredictions], look_back: int = 5) -> list[np.ndarray]:
    frames = [(p.classes, p.scores, p.points) for p in preds]
    return derive_track_ids(frames, np.stack([p.pose for p in preds]), HALF, 0.4, look_back)


def _cmap(preds: list[FramePredictions], gts: list[FrameGT], look_back: int = 5) -> dict:
    return maptracker_cmap([preds], [gts], THR, HALF, look_back=look_back)


def test_id_swap_costs_a_false_positive() -> None:
    """Dividers A (y = 0) and B (y = 1 m; their masks overlap). Frames 0-1 predict A; frame 2
    only B, which inherits A's track through the overlap; frame 3 predicts both: B keeps the
    track, A gets a new id. A's ground truth was first matched by track 0, so A's TP in frame 3
    is an FP: rows TP TP TP FP TP of 8 GT -> C-AP = 3/8 + 1/8 * 0.8 = 0.475; AP = 5/8."""
    preds, gts = _sequence([[0.0], [0.0], [1.0], [0.0, 1.0]], [0.0, 1.0])
    ids = _ids(preds)
    assert ids[2][0] == ids[0][0] == ids[1][0]  # B took A's track
    assert ids[3][1] == ids[0][0] and ids[3][0] not in (ids[0][0],)  # swap
    r = _cmap(preds, gts)
    for thr in ("0.5", "1", "1.5"):
        assert r["C-AP"]["divider"][thr] == pytest.approx(0.475)
        assert r["AP"]["divider"][thr] == pytest.approx(0.625)
    assert r["C-mAP"] == pytest.approx(0.475)  # classes without GT left out
    assert math.isnan(r["C-AP_class"]["boundary"])


@pytest.mark.parametrize("moving", [False, True])
def test_track_refound_within_look_back(moving: bool) -> None:
    """Predicted in frames 0, 1 and 4 (gap of 2 frames): frame 4 looks back to frame 1 and
    keeps the id; every TP is consistent: C-AP = AP = 3/5."""
    preds, gts = _sequence([[0.0], [0.0], [], [], [0.0]], [0.0], moving=moving)
    ids = _ids(preds)
    assert ids[4][0] == ids[0][0]
    r = _cmap(preds, gts)
    assert r["C-mAP"] == pytest.approx(0.6) and r["mAP"] == pytest.approx(0.6)


def test_track_refound_beyond_look_back() -> None:
    """Predicted in frames 0, 1 and 7 (gap of 5): frames 2-6 hold nothing, so frame 7 gets a new
    id and its TP is an FP: rows TP TP FP of 8 GT -> C-AP = 2/8, AP = 3/8. With a look-back of
    6 the track is found again."""
    preds, gts = _sequence([[0.0], [0.0], [], [], [], [], [], [0.0]], [0.0], moving=True)
    assert _ids(preds)[7][0] != _ids(preds)[0][0]
    r = _cmap(preds, gts)
    assert r["C-mAP"] == pytest.approx(0.25) and r["mAP"] == pytest.approx(0.375)
    assert _ids(preds, look_back=6)[7][0] == _ids(preds)[0][0]
    assert _cmap(preds, gts, look_back=6)["C-mAP"] == pytest.approx(0.375)


def test_score_filter_and_frames_without_gt() -> None:
    """Scores <= 0.4 are not scored at all, and a class's predictions in a frame without its GT
    are left out (MapTracker's rules): frame 1 has no GT but the best-scored prediction, frame 0 a
    duplicate at 0.4. MT mAP stays 1; icmapper's AP ranks an FP first (AP 0.5)."""
    preds, gts = _sequence([[0.0, 0.0], [0.0]], [0.0])
    preds[0].scores = np.array([0.9, 0.4])
    preds[1].scores = np.array([0.95])
    gts[1] = FrameGT(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 20, 2), np.float32))
    r = evaluate([preds], [gts], maptracker=True)
    mt = r["consistency_maptracker"]
    assert mt["mAP"] == pytest.approx(1.0) and mt["C-mAP"] == pytest.approx(1.0)
    assert r["detection"]["mAP"] == pytest.approx(0.5)  # icmapper's protocol: FP, TP, FP
    assert _ids(preds)[0][1] == -1  # score 0.4 is not above the threshold


def test_raster_pieces_against_oracles() -> None:
    from scipy.ndimage import binary_dilation

    r = 3  # cv2.getStructuringElement(MORPH_ELLIPSE, (7, 7)): rows of half-width
    want = np.zeros((7, 7), bool)  # round(c * sqrt(r^2 - dy^2) / r) around the centre
    for i in range(7):
        dx = int(round(3 * math.sqrt(max(r * r - (i - r) ** 2, 0)) / r))
        want[i, 3 - dx : 3 + dx + 1] = True
    np.testing.assert_array_equal(ELLIPSE_7, want)
    rng = np.random.default_rng(0)
    for _ in range(20):
        m = rng.random((100, 200)) > 0.995
        np.testing.assert_array_equal(dilate(m), binary_dilation(m, structure=ELLIPSE_7))
    raster = Raster(*HALF)
    line = raster.mask(_line(0.0), closed=False)
    assert line.shape == (100, 200)
    rows = np.flatnonzero(line.any(axis=1))
    np.testing.assert_array_equal(rows, [48, 49, 50, 51, 52])  # y = 0 -> row 50, half-width 2
    square = np.array([[0, 0], [3, 0], [3, 3], [0, 3], [0, 0]], float)
    assert raster.mask(square, closed=True).sum() == pytest.approx(11 * 11, abs=25)
