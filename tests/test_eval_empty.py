"""Frames without predictions or without ground truth, and empty global maps, in every metric
(detection AP, C-mAP, tracking, global map): no crash, and the numbers of the references
(numpy + shapely AP, py-motmetrics) or of the protocol's definition (issue 14, point 6)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from icmapper import geom
from icmapper.eval.detection import CLASS_NAMES, THRESHOLDS
from icmapper.eval.evaluate import _gt_table, _pred_table, evaluate
from icmapper.eval.runfmt import FramePredictions

from benchmarks.evaluation import make_workload, reference_ap

TH = THRESHOLDS["60x30"]


class GT:
    """FrameGT-like container (ids (k,), classes (k,), points (k, 20, 2))."""

    def __init__(self, ids: np.ndarray, classes: np.ndarray, points: np.ndarray) -> None:
        self.ids, self.classes, self.points = ids, classes, points


def no_predictions(f: int) -> FramePredictions:
    """A frame where the detector found nothing (arrays of length 0, as a run file stores it)."""
    return FramePredictions(
        f, np.eye(4), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 20, 2), np.float32),
        np.zeros(0, np.int64),
    )  # fmt: skip


def no_gt() -> GT:
    """A stretch of road without markings."""
    return GT(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 20, 2), np.float32))


def line(y: float) -> np.ndarray:
    return np.stack([np.linspace(-10.0, 10.0, 20), np.full(20, y)], axis=1)  # (20, 2)


def one_divider(f: int, score: float = 0.9, tid: int = 1) -> FramePredictions:
    return FramePredictions(
        f, np.eye(4), np.array([1]), np.array([score]), line(0.2)[None].astype(np.float32),
        np.array([tid]),
    )  # fmt: skip


def workload_with_holes(seed: int) -> tuple[list, list, list, list]:
    """The benchmark workload (3 sequences x 8 frames) with predictions removed from some frames,
    ground truth removed from others, and frames empty on both sides."""
    P, G, GP, GG = make_workload(3, 8, 12, (30.0, 15.0), seed)
    for s in range(3):
        P[s][1] = no_predictions(1)
        G[s][3] = no_gt()
        P[s][5], G[s][5] = no_predictions(5), no_gt()
    P[1] = [no_predictions(f) for f in range(8)]  # a sequence where nothing is detected
    G[2] = [no_gt() for _ in range(8)]  # a sequence without markings
    return P, G, GP, GG


def test_frames_without_predictions_or_gt_do_not_crash_and_keep_shapes() -> None:
    P, G, GP, GG = workload_with_holes(0)
    res = evaluate(P, G, GP, GG, "60x30")
    assert res["num_predictions"] == sum(len(p) for ps in P for p in ps)
    assert res["num_gt"] == sum(len(g.ids) for gs in G for g in gs)
    assert res["num_frames"] == 24
    for name in CLASS_NAMES:
        assert 0.0 <= res["detection"]["AP_class"][name] <= 1.0
        assert 0.0 <= res["consistency"]["C-AP_class"][name] <= res["detection"]["AP_class"][name]
    assert res["mapping"] is not None


def test_detection_ap_with_empty_frames_matches_reference() -> None:
    """AP against the straightforward numpy + shapely reference on the same frames."""
    P, G, _, _ = workload_with_holes(1)
    res = evaluate(P, G, None, None, "60x30")
    ref = reference_ap(_pred_table(P), _gt_table(G), TH)
    for name in CLASS_NAMES:
        for thr, v in res["detection"]["AP"][name].items():
            assert v == pytest.approx(ref[name][thr], abs=1e-9, nan_ok=True)


def test_tracking_with_empty_frames_matches_motmetrics() -> None:
    import motmetrics as mm

    P, G, _, _ = workload_with_holes(2)
    res = evaluate(P, G, None, None, "60x30", score_threshold=0.4, gate=1.5)
    for c, name in enumerate(CLASS_NAMES):
        totals = dict.fromkeys(("num_objects", "num_misses", "num_false_positives"), 0)
        switches = 0
        for ps, gs in zip(P, G, strict=True):
            acc = mm.MOTAccumulator(auto_id=True)
            for p, g in zip(ps, gs, strict=True):
                gi = np.flatnonzero(np.asarray(g.classes) == c)
                pi = np.flatnonzero((np.asarray(p.classes) == c) & (np.asarray(p.scores) >= 0.4))
                d = np.full((gi.size, pi.size), np.nan)
                if gi.size and pi.size:
                    ga = geom.resample_many(np.asarray(g.points)[gi], 200, c == 0)
                    pa = geom.resample_many(np.asarray(p.points)[pi], 200, c == 0)
                    d = geom.chamfer_matrix(ga, pa)  # (gi, pi)
                    d[d > 1.5] = np.nan
                acc.update(np.asarray(g.ids)[gi], np.asarray(p.track_ids)[pi], d)
            s = mm.metrics.create().compute(
                acc, metrics=["num_objects", "num_misses", "num_false_positives", "num_switches"]
            )
            for k in totals:
                totals[k] += int(s[k].iloc[0])
            switches += int(s["num_switches"].iloc[0])
        ours = res["tracking"]["per_class"][name]
        assert ours["num_objects"] == totals["num_objects"]
        assert ours["num_misses"] == totals["num_misses"]
        assert ours["num_false_positives"] == totals["num_false_positives"]
        assert ours["num_switches"] == switches
        if totals["num_objects"]:
            errors = totals["num_misses"] + totals["num_false_positives"] + switches
            assert ours["MOTA"] == pytest.approx(1 - errors / totals["num_objects"])


def test_frames_empty_on_both_sides_change_nothing() -> None:
    """Appending frames with neither predictions nor ground truth leaves every metric as is."""
    P, G, GP, GG = make_workload(2, 6, 12, (30.0, 15.0), 3)
    base = evaluate(P, G, GP, GG, "60x30")
    P2 = [ps + [no_predictions(6), no_predictions(7)] for ps in P]
    G2 = [gs + [no_gt(), no_gt()] for gs in G]
    more = evaluate(P2, G2, GP, GG, "60x30")
    for key in ("detection", "consistency", "tracking", "mapping"):
        assert _same(base[key], more[key]), key


def test_no_predictions_at_all() -> None:
    gts = [[GT(np.array([1]), np.array([1]), line(0.0)[None]) for _ in range(3)]]
    preds = [[no_predictions(f) for f in range(3)]]
    res = evaluate(preds, gts, [[]], [[(1, line(0.0), False)]], "60x30")
    assert res["detection"]["AP"]["divider"] == {"0.5": 0.0, "1": 0.0, "1.5": 0.0}
    assert math.isnan(res["detection"]["AP_class"]["boundary"])  # no GT of that class
    assert res["detection"]["mAP"] == 0.0 and res["consistency"]["C-mAP"] == 0.0
    trk = res["tracking"]["per_class"]["divider"]
    assert trk["MOTA"] == 0.0 and trk["num_misses"] == 3 and math.isnan(trk["MOTP"])
    mapping = res["mapping"]
    assert mapping["CD"]["divider"] == math.inf  # GT but no predicted instance
    assert math.isnan(mapping["CD"]["boundary"])  # neither side: left out
    assert mapping["GAP"]["divider"] == 0.0 and mapping["mGAP"] == 0.0


def test_no_ground_truth_at_all() -> None:
    preds = [[one_divider(f) for f in range(3)]]
    gts = [[no_gt() for _ in range(3)]]
    res = evaluate(preds, gts, [[(1, line(0.0), False, 2.0)]], [[]], "60x30")
    assert all(math.isnan(v) for v in res["detection"]["AP_class"].values())
    assert math.isnan(res["detection"]["mAP"]) and math.isnan(res["consistency"]["C-mAP"])
    trk = res["tracking"]["per_class"]["divider"]
    assert trk["num_false_positives"] == 3 and math.isnan(trk["MOTA"])
    assert math.isnan(res["tracking"]["mean"]["MOTA"])  # no class with GT
    assert res["mapping"]["CD"]["divider"] == math.inf
    assert math.isnan(res["mapping"]["GAP"]["divider"]) and math.isnan(res["mapping"]["mGAP"])


def test_nothing_at_all() -> None:
    res = evaluate([[no_predictions(0)]], [[no_gt()]], [[]], [[]], "60x30")
    assert res["num_predictions"] == res["num_gt"] == 0
    assert math.isnan(res["detection"]["mAP"]) and math.isnan(res["tracking"]["mean"]["MOTA"])
    assert all(math.isnan(v) for v in res["mapping"]["CD"].values())
    assert math.isnan(res["mapping"]["mCD"]) and math.isnan(res["mapping"]["mGAP"])
    res = evaluate([], [], None, None, "60x30")  # no sequences
    assert res["num_frames"] == 0 and math.isnan(res["detection"]["mAP"])


def test_an_empty_global_map_in_one_sequence() -> None:
    """One sequence's predicted global map is empty: its GT instances are misses in GAP, its CD
    is inf and the mean over sequences is inf."""
    world = [(1, line(0.0) * [5, 1], False), (0, line(1.0)[::4] * [1, 3], True)]
    scored = [(*w, 3.0) for w in world]
    gts = [[GT(np.array([1]), np.array([1]), line(0.0)[None])] for _ in range(2)]
    preds = [[one_divider(0)], [one_divider(0)]]
    res = evaluate(preds, gts, [scored, []], [world, world], "60x30")["mapping"]
    assert res["CD"]["divider"] == math.inf
    # GAP pools both sequences: 1 TP of 2 GT per class -> AP 0.5 at every threshold
    assert res["GAP"]["divider"] == pytest.approx(0.5)
    assert res["GAP"]["ped_crossing"] == pytest.approx(0.5)


def test_points_that_do_not_match_the_count_are_refused() -> None:
    bad = FramePredictions(
        0, np.eye(4), np.array([1, 1]), np.array([0.5, 0.5]), np.zeros((3, 20, 2), np.float32),
        np.array([1, 2]),
    )  # fmt: skip
    with pytest.raises(ValueError, match="sequence 0, frame 0: 2 instances"):
        evaluate([[bad]], [[no_gt()]], None, None, "60x30")
    stray = FramePredictions(
        0, np.eye(4), np.zeros(0, np.int64), np.zeros(0), np.zeros((1, 20, 2), np.float32),
        np.zeros(0, np.int64),
    )  # fmt: skip
    with pytest.raises(ValueError, match="no instances but points"):
        evaluate([[stray]], [[no_gt()]], None, None, "60x30")
    mixed = GT(np.array([1]), np.array([1]), np.zeros((1, 10, 2)))
    with pytest.raises(ValueError, match="10 points per instance, earlier frames have 20"):
        evaluate([[no_predictions(0)] * 2], [[GT(*one(1)), mixed]], None, None, "60x30")


def one(i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.array([i]), np.array([1]), line(0.0)[None]


def _same(a: object, b: object) -> bool:
    """Equal nested results, NaN equal to NaN."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return a == b


def test_icmapper_eval_on_a_run_with_empty_frames(tmp_path, capsys) -> None:
    """End to end: a run file whose every other frame has no predictions (and a synthetic source
    whose ground truth has its own empty stretches) is read and evaluated by `icmapper eval`."""
    from icmapper.cli import main
    from icmapper.data import gt
    from icmapper.data.sources import open_source
    from icmapper.data.types import RANGE_60x30
    from icmapper.eval.runfmt import RunWriter

    with RunWriter(tmp_path / "run", "sparse", "sim:val:1", RANGE_60x30) as w:
        for seq in open_source("sim:val:1", render=False):
            frames = []
            for t, g in enumerate(gt.sequence_gt(seq, RANGE_60x30)):
                if t % 2 == 0:
                    fp = no_predictions(t)
                    fp.pose = seq.poses[t]
                else:
                    fp = FramePredictions(
                        t, seq.poses[t], g.classes, np.full(len(g), 0.9), g.points, g.ids
                    )
                frames.append(fp)
            w.add_sequence(seq.name, frames)
    rc = main(["eval", str(tmp_path / "run"), "--json", str(tmp_path / "eval.json")])
    assert rc == 0 and "| sparse | 60x30 |" in capsys.readouterr().out
    det = json.loads((tmp_path / "eval.json").read_text())["runs"][0]["detection"]
    assert 0.3 < det["mAP"] < 0.7  # exact predictions in half of the frames: recall ~ 1/2
