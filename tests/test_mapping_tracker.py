"""Inference association (icmapper.mapping.tracker): assignment against brute force, id bookkeeping,
ageing out, the ego view of the buffer and the positional affinity."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from icmapper.data.types import xy_yaw_to_pose
from icmapper.mapping.tracker import (
    Tracker,
    match_scores,
    overlap,
    polyline_chamfer_matrix,
    positional_affinity,
)


def _brute_force_best(scores, det_cls, trk_cls, thr) -> float:
    """Maximum summed score over all one-to-one partial matchings of admissible pairs."""
    k, t = scores.shape
    best = 0.0
    # Every partial matching: pad the tracks with k "unmatched" slots, take all injections.
    cols = list(range(t)) + [-1] * k
    for perm in set(itertools.permutations(cols, k)):
        total = 0.0
        ok = True
        for i, j in enumerate(perm):
            if j < 0:
                continue
            if scores[i, j] < thr or det_cls[i] != trk_cls[j]:
                ok = False
                break
            total += scores[i, j]
        if ok:
            best = max(best, total)
    return best


@pytest.mark.parametrize("seed", range(40))
def test_match_scores_is_optimal_against_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k, t = int(rng.integers(0, 5)), int(rng.integers(0, 5))
    scores = rng.random((k, t))
    det_cls = rng.integers(0, 2, k)
    trk_cls = rng.integers(0, 2, t)
    thr = float(rng.choice([0.0, 0.3, 0.5, 0.8]))
    cols = match_scores(scores, det_cls, trk_cls, thr)
    assert cols.shape == (k,)
    matched = cols[cols >= 0]
    assert len(set(matched.tolist())) == len(matched)  # one-to-one
    total = 0.0
    for i, j in enumerate(cols):
        if j >= 0:
            assert scores[i, j] >= thr and det_cls[i] == trk_cls[j]
            total += scores[i, j]
    assert total == pytest.approx(_brute_force_best(scores, det_cls, trk_cls, thr))


def test_match_scores_rejects_bad_scores() -> None:
    with pytest.raises(ValueError, match="NaN"):
        match_scores(np.array([[np.nan]]), np.array([1]), np.array([1]), 0.5)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        match_scores(np.array([[1.5]]), np.array([1]), np.array([1]), 0.5)
    with pytest.raises(ValueError, match="must be"):
        match_scores(np.zeros((2, 1)), np.array([1]), np.array([1]), 0.5)


def _span(x0: float, x1: float, y: float, n: int = 20) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], axis=1)  # (n, 2)


def test_the_piece_covering_more_of_a_track_continues_it() -> None:
    """The range edge cuts a track's line (x -20..20) into a long piece drawn 0.4 m off and a
    short piece at one end lying exactly on it. By the positional score alone (the smaller
    directed distance) the short piece takes the track; weighed by how much each shares with
    the track (``overlap``), the long one keeps it and the short piece opens a new track."""
    pose = np.eye(4)
    track = _span(-20.0, 20.0, 0.0)[None]  # (1, 20, 2)
    dets = np.stack([_span(-20.0, 12.0, 0.4), _span(14.0, 20.0, 0.0)])  # (2, 20, 2)
    cls = np.array([2, 2])
    scores = positional_affinity(dets, cls, track, np.array([2]), 1.5, "min")  # (2, 1)
    assert scores[1, 0] > scores[0, 0] > 0.5
    shared = overlap(dets, cls, track, np.array([2]), 1.0)
    assert shared[0, 0] == pytest.approx(0.8, abs=0.06) and shared[1, 0] <= 0.25
    from icmapper.mapping.associate import association_scores
    from icmapper.mapping.types import Detections

    det = Detections(cls, np.ones(2, np.float32), dets.astype(np.float32))
    kw = {"head": None, "to_unit": None, "device": "cpu", "positional_scale": 1.5}
    both, from_both = association_scores(det, np.array([2]), track, None, **kw, share_gate=1.0)
    np.testing.assert_allclose(both, scores, atol=1e-6)  # one pass over the distances: both
    np.testing.assert_allclose(from_both, shared)
    assert association_scores(det, np.array([2]), track, None, **kw)[1] is None
    for weigh, continued in ((None, 1), (shared, 0)):
        tr = Tracker(threshold=0.5, max_age=3)
        tr.assign(np.zeros((1, 0)), np.array([2]), track, pose)  # track 0
        ids = tr.assign(scores, cls, dets, pose, shared=weigh)
        assert ids[continued] == 0 and ids[1 - continued] == 1
    with pytest.raises(ValueError, match="weights"):
        match_scores(scores, cls, np.array([2]), 0.5, weights=np.ones((1, 1)))


def _line(x0: float, y: float, n: int = 20) -> np.ndarray:
    return np.stack([np.linspace(x0, x0 + 10.0, n), np.full(n, y)], axis=1).astype(np.float32)


def test_ids_new_monotonic_and_matched() -> None:
    tr = Tracker(threshold=0.5, max_age=1)
    pose = np.eye(4)
    pts = np.stack([_line(0, 0), _line(0, 5)])  # (2, 20, 2)
    ids0 = tr.assign(np.zeros((2, 0)), np.array([1, 2]), pts, pose)
    assert ids0.tolist() == [0, 1]
    # Frame 1: detection 0 matches track 1, detection 1 is new, detection 2 is below threshold.
    scores = np.array([[0.1, 0.9], [0.2, 0.3], [0.45, 0.0]])
    pts1 = np.stack([_line(0, 5), _line(0, 9), _line(0, 0)])
    ids1 = tr.assign(scores, np.array([2, 1, 1]), pts1, pose)
    assert ids1.tolist() == [1, 2, 3]
    # Class mismatch blocks a high score.
    ids2 = tr.assign(np.zeros((1, len(tr))) + 0.99, np.array([0]), _line(0, 0)[None], pose)
    assert ids2.tolist() == [4]


def test_tracks_age_out() -> None:
    tr = Tracker(threshold=0.5, max_age=2)
    pose = np.eye(4)
    tr.assign(np.zeros((1, 0)), np.array([1]), _line(0, 0)[None], pose)
    for expected_age in (1, 2):
        tr.assign(np.zeros((0, 1)), np.zeros(0, np.int64), np.zeros((0, 20, 2)), pose)
        assert [t.age for t in tr.tracks] == [expected_age]
    # Still there at age 2: a match revives it.
    ids = tr.assign(np.array([[0.9]]), np.array([1]), _line(0, 0)[None], pose)
    assert ids.tolist() == [0] and tr.tracks[0].age == 0 and tr.tracks[0].hits == 2
    for _ in range(3):
        tr.assign(np.zeros((0, len(tr))), np.zeros(0, np.int64), np.zeros((0, 20, 2)), pose)
    assert len(tr) == 0
    tr.reset()
    assert tr.assign(np.zeros((1, 0)), np.array([1]), _line(0, 0)[None], pose).tolist() == [0]


def test_buffer_is_world_frame_and_viewed_in_ego() -> None:
    tr = Tracker()
    pose0 = xy_yaw_to_pose(100.0, 50.0, 0.7)
    det = _line(-5, 2)[None]  # (1, 20, 2) ego
    q = np.ones((1, 8), np.float32)
    tr.assign(np.zeros((1, 0)), np.array([1]), det, pose0, det_queries=q)
    ids, cls, pts, queries = tr.tracks_in_ego(pose0)
    assert ids.tolist() == [0] and cls.tolist() == [1]
    assert pts.dtype == np.float32 and pts.shape == (1, 20, 2)
    np.testing.assert_allclose(pts, det, atol=1e-4)
    assert queries is not None and queries.shape == (1, 8)
    # Seen from a pose 4 m further along the heading, the line is 4 m closer in x.
    c, s = np.cos(0.7), np.sin(0.7)
    pose1 = xy_yaw_to_pose(100.0 + 4 * c, 50.0 + 4 * s, 0.7)
    _, _, pts1, _ = tr.tracks_in_ego(pose1)
    np.testing.assert_allclose(pts1[0], det[0] - [4.0, 0.0], atol=1e-4)


def test_assign_bad_input_leaves_buffer_unchanged() -> None:
    tr = Tracker()
    tr.assign(np.zeros((1, 0)), np.array([1]), _line(0, 0)[None], np.eye(4))
    bad = _line(0, 0)[None].copy()
    bad[0, 3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        tr.assign(np.array([[0.9]]), np.array([1]), bad, np.eye(4))
    with pytest.raises(ValueError, match="scores"):
        tr.assign(np.zeros((1, 2)), np.array([1]), _line(0, 0)[None], np.eye(4))
    assert len(tr) == 1 and tr.tracks[0].age == 0 and tr.tracks[0].hits == 1


def test_positional_affinity() -> None:
    det = np.stack([_line(0, 0), _line(0, 3)])  # (2, 20, 2)
    trk = np.stack([_line(0, 0.5), _line(0, 3)])
    aff = positional_affinity(det, np.array([1, 1]), trk, np.array([1, 2]), scale=1.0)
    assert aff.shape == (2, 2)
    assert aff[0, 0] == pytest.approx(np.exp(-0.5))
    assert aff[1, 1] == 0.0  # other class
    assert 0.0 <= aff.min() and aff.max() <= 1.0
    assert positional_affinity(det[:0], np.zeros(0), trk, np.array([1, 2])).shape == (0, 2)


def test_polyline_chamfer_matrix_against_shapely() -> None:
    import shapely

    rng = np.random.default_rng(1)
    a = np.cumsum(rng.normal(size=(3, 6, 2)), axis=1)
    b = np.cumsum(rng.normal(size=(4, 5, 2)), axis=1)
    a_closed = np.array([False, True, False])
    b_closed = np.array([True, False, False, True])
    cd = polyline_chamfer_matrix(a, b, a_closed, b_closed)

    def geom(p, closed):
        return shapely.LinearRing(p) if closed else shapely.LineString(p)

    def mean_dist(p, g):
        return np.mean([g.distance(shapely.Point(q)) for q in p])

    for i in range(3):
        for j in range(4):
            ga, gb = geom(a[i], a_closed[i]), geom(b[j], b_closed[j])
            want = 0.5 * (mean_dist(a[i], gb) + mean_dist(b[j], ga))
            assert cd[i, j] == pytest.approx(want, abs=1e-9)


def test_positional_affinity_ignores_sampling_phase() -> None:
    # The same 60 m line sampled at 20 points, shifted 1.5 m along itself: near-perfect affinity.
    line = np.stack([np.linspace(-30, 30, 20), np.zeros(20)], axis=1)
    aff = positional_affinity(line[None] + [1.5, 0.0], np.array([1]), line[None], np.array([1]))
    assert aff[0, 0] > np.exp(-0.1)
