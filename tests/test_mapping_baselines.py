"""Mapping baselines (icmapper.mapping.baselines) on a small hand-made drive with the oracle source:
each builds a global map near the ground truth, copes with empty frames, and rejects NaN detections
without touching its map. Also the rule-based pieces they share (DBSCAN, splicing)."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data.types import FrameGT, RANGE_60x30, Sequence, WorldMap, xy_yaw_to_pose
from icmapper.mapping.baselines import ClusterFit, PostTrack
from icmapper.mapping.baselines.cluster_fit import dbscan
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.methods import methods
from icmapper.mapping.oracle import OracleDetector
from icmapper.mapping.splice import overlap_fraction, splice_polyline
from icmapper.mapping.types import Detections

#: The registered methods that run on any detection source (the baselines).
BASELINES = {n: i.build for n, i in methods().items() if i.build is not None}

# --- the hand-made drive ----------------------------------------------------------------------
# A straight road along the local x axis, rotated by YAW into the world. The ego drives from x = 0
# to x = 100 in 5 m steps (2 Hz at 10 m/s). Range 60x30: the ego sees x in [px - 30, px + 30].
YAW = 0.3
ORIGIN = np.array([1000.0, -200.0])
ROT = np.array([[np.cos(YAW), -np.sin(YAW)], [np.sin(YAW), np.cos(YAW)]])
STEPS = np.arange(0.0, 101.0, 5.0)  # (21,) ego x along the road
LINES = {  # id: (class, y, x0, x1) in road coordinates
    1: (2, -7.0, -40.0, 140.0),  # boundaries
    2: (2, 7.0, -40.0, 140.0),
    3: (1, 0.0, -40.0, 140.0),  # dividers; the second ends inside the visited stretch
    4: (1, 3.75, 20.0, 80.0),
}
CROSSING = (5, 48.0, 52.0, -6.0, 6.0)  # id, x0, x1, y0, y1 (road coordinates)


def _to_world(local: np.ndarray) -> np.ndarray:
    return local @ ROT.T + ORIGIN


def _rect_ring(x0: float, x1: float, y0: float, y1: float, n: int) -> np.ndarray:
    ring = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ring, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, ring[:, 0]), np.interp(t, s, ring[:, 1])], axis=1)


def _frame_gt(px: float) -> FrameGT:
    """Exact GT of the frame at road x = px (ego frame = road frame shifted by px)."""
    ids, classes, pts = [], [], []
    for wid, (cls, y, x0, x1) in LINES.items():
        a, b = max(x0, px - 30.0), min(x1, px + 30.0)
        if b - a > 1e-6:
            ids.append(wid)
            classes.append(cls)
            pts.append(np.stack([np.linspace(a, b, 20) - px, np.full(20, y)], axis=1))
    wid, x0, x1, y0, y1 = CROSSING
    a, b = max(x0, px - 30.0), min(x1, px + 30.0)
    if b - a > 1e-6:
        ids.append(wid)
        classes.append(0)
        pts.append(_rect_ring(a - px, b - px, y0, y1, 20))
    return FrameGT(
        np.array(ids, np.int64), np.array(classes, np.int64), np.stack(pts).astype(np.float32)
    )


def _global_gt() -> list[tuple[int, np.ndarray]]:
    """GT global map (class, dense world points): instances clipped to the visited x range
    [-30, 130]."""
    out = []
    for cls, y, x0, x1 in LINES.values():
        a, b = max(x0, -30.0), min(x1, 130.0)
        xs = np.arange(a, b + 1e-9, 0.5)
        out.append((cls, _to_world(np.stack([xs, np.full_like(xs, y)], axis=1))))
    _, x0, x1, y0, y1 = CROSSING
    out.append((0, _to_world(_rect_ring(x0, x1, y0, y1, 64))))
    return out


def _sequence() -> tuple[Sequence, list[FrameGT]]:
    poses = np.stack([xy_yaw_to_pose(*_to_world(np.array([[px, 0.0]]))[0], YAW) for px in STEPS])
    seq = Sequence(
        name="hand-made",
        source="test",
        world=WorldMap("hand-made", []),
        timestamps=np.arange(len(STEPS)) * 0.5,
        poses=poses,
        rig=None,  # type: ignore[arg-type]  # the oracle needs no cameras
    )
    return seq, [_frame_gt(px) for px in STEPS]


def _dense(points: np.ndarray, closed: bool, step: float = 0.5) -> np.ndarray:
    p = np.concatenate([points, points[:1]]) if closed else points
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t = np.arange(0.0, s[-1] + 1e-9, step)
    return np.stack([np.interp(t, s, p[:, 0]), np.interp(t, s, p[:, 1])], axis=1)


def _class_chamfer(gmap, cls: int) -> tuple[float, float]:
    """(GT -> map, map -> GT) mean nearest distance of densely sampled points of one class."""
    from scipy.spatial import cKDTree

    gt = np.concatenate([p for c, p in _global_gt() if c == cls])
    pred = [
        _dense(np.asarray(gmap.get(int(i))[1]), cls == 0)
        for i in gmap.ids()
        if int(gmap.get(int(i))[0]) == cls
    ]
    if not pred:
        return np.inf, np.inf
    pr = np.concatenate(pred)
    return float(cKDTree(pr).query(gt)[0].mean()), float(cKDTree(gt).query(pr)[0].mean())


def _run(method, seq: Sequence):
    method.reset()
    for i in range(len(seq)):
        res = method.step(seq.frame(i, with_images=False))
        assert res.frame_index == i
        assert res.track_ids.shape == (len(res.detections),)
        assert res.points.shape == res.detections.points.shape
    return method.finish()


def _make(name: str, source) -> object:
    return BASELINES[name](source, MapperConfig(baseline_threshold=0.6), RANGE_60x30)


# --- rule-based pieces (no engine needed) -----------------------------------------------------


def test_dbscan_finds_blobs_and_noise() -> None:
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0], 0.5, (30, 2))
    b = rng.normal([20, 0], 0.5, (30, 2))
    noise = np.array([[10.0, 10.0], [-10.0, 5.0]])
    labels = dbscan(np.concatenate([a, b, noise]), eps=3.0, min_samples=5)
    assert set(labels[:30].tolist()) == {0} and set(labels[30:60].tolist()) == {1}
    assert labels[60:].tolist() == [-1, -1]
    # A chain of points 2 m apart is one cluster (density-reachable), min_samples counts itself.
    chain = np.stack([np.arange(0, 40, 2.0), np.zeros(20)], axis=1)
    assert set(dbscan(chain, 3.0, 3).tolist()) == {0}
    assert set(dbscan(chain, 3.0, 4).tolist()) == {-1}
    assert dbscan(np.zeros((0, 2)), 3.0, 5).shape == (0,)


def test_splice_substitutes_and_concatenates() -> None:
    stored = np.stack([np.arange(0.0, 21.0), np.zeros(21)], axis=1)  # x 0..20 along y = 0
    new = np.stack([np.linspace(30.0, 10.0, 11), np.full(11, 0.2)], axis=1)  # reversed, x 10..30
    out = splice_polyline(stored, new, overlap=1.0)
    assert np.all(np.diff(out[:, 0]) > 0)  # oriented like stored, one pass
    assert out[0, 0] == 0.0 and out[-1, 0] == 30.0  # kept the start, extended past the end
    assert np.all(out[out[:, 0] > 10.5, 1] == 0.2)  # overlapped part substituted
    # Pure continuation beyond the end, given in reverse.
    cont = np.stack([np.linspace(35.0, 22.0, 5), np.zeros(5)], axis=1)
    out2 = splice_polyline(stored, cont, overlap=1.0)
    assert np.all(np.diff(out2[:, 0]) > 0) and out2[-1, 0] == 35.0 and len(out2) == 21 + 5
    # 11 / 21 stored points are within 1 m of new; 6 / 11 new points (x 10..20) of stored.
    assert overlap_fraction(stored, new, 1.0) == pytest.approx(6 / 11)
    ring = _rect_ring(0, 4, 0, 10, 20)
    assert overlap_fraction(ring + [1.0, 0.0], ring, 0.5, closed=True) > 0.5
    assert overlap_fraction(ring + [30.0, 0.0], ring, 0.5, closed=True) == 0.0


# --- the baselines on the drive ---------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baseline_map_matches_ground_truth(name: str) -> None:
    """With "low" oracle noise (0.1 m jitter, 5 % drops, 5 % partial views), every class of the
    map lies within 0.6 m (mean Chamfer, both directions) of the GT global map: a few times the
    jitter, well under half the 3.75 m lane spacing, so missing, misplaced or spurious instances
    fail. With exact detections the bound is 0.25 m (resampling, curve fit, ends)."""
    seq, gt = _sequence()
    for noise, bound in (("none", 0.25), ("low", 0.6)):
        gmap = _run(_make(name, OracleDetector(seq, noise=noise, seed=0, gt=gt)), seq)
        assert len(gmap) >= 5
        for cls in (0, 1, 2):
            to_map, to_gt = _class_chamfer(gmap, cls)
            assert to_map < bound and to_gt < bound, (name, noise, cls, to_map, to_gt)


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baseline_track_ids(name: str) -> None:
    """Online methods give every detection an id; with exact detections Post-Track's ids follow
    the GT ids one-to-one (no switches), and so the map has one instance per GT instance."""
    seq, gt = _sequence()
    method = _make(name, OracleDetector(seq, noise="none", gt=gt))
    method.reset()
    pairs: set[tuple[int, int]] = set()
    for i in range(len(seq)):
        res = method.step(seq.frame(i, with_images=False))
        if name == "cluster-fit":
            assert np.all(res.track_ids == -1)
            continue
        assert np.all(res.track_ids >= 0)
        pairs |= set(zip(res.detections.gt_ids.tolist(), res.track_ids.tolist(), strict=True))
    gmap = method.finish()
    if name in ("post-track", "vma"):
        gt_of = dict(pairs)
        assert len(pairs) == len(gt_of) == len({v for _, v in pairs}) == 5
        assert len(gmap) == 5


class _ScriptedSource:
    """A DetectionSource replaying given detections per frame index."""

    def __init__(self, per_frame: dict[int, Detections]) -> None:
        self.per_frame = per_frame

    def reset(self) -> None:
        pass

    def detect(self, frame) -> Detections:
        return self.per_frame.get(frame.index, Detections.empty())


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baseline_empty_frames(name: str) -> None:
    seq, _ = _sequence()
    gmap = _run(_make(name, _ScriptedSource({})), seq)
    assert len(gmap) == 0


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baseline_rejects_nan_and_keeps_map(name: str) -> None:
    seq, gt = _sequence()
    oracle = OracleDetector(seq, noise="low", gt=gt)
    good = oracle.detect(seq.frame(1, with_images=False))
    bad_pts = good.points.copy()
    bad_pts[-1, 5] = np.nan
    bad = Detections(good.classes, good.scores, bad_pts)
    first = oracle.detect(seq.frame(0, with_images=False))
    method = _make(name, _ScriptedSource({0: first, 1: bad}))
    method.reset()
    method.step(seq.frame(0, with_images=False))
    before = _snapshot(method)
    with pytest.raises(ValueError, match="NaN"):
        method.step(seq.frame(1, with_images=False))
    after = _snapshot(method)
    assert before.keys() == after.keys()
    for k in before:
        np.testing.assert_array_equal(before[k], after[k])


def _snapshot(method) -> dict:
    if isinstance(method, ClusterFit):
        return {
            f"c{c}": np.concatenate(p) if p else np.zeros((0, 2))
            for c, p in enumerate(method._points)
        }
    out = {int(i): np.asarray(method.map.get(int(i))[1]) for i in method.map.ids()}
    if isinstance(method, PostTrack):
        out["tracks"] = np.array([t.id for t in method.tracker.tracks])
    return out


def test_registry_lists_every_baseline_once() -> None:
    assert list(BASELINES) == ["post-track", "vma", "cluster-fit", "polymerge"]
    for name, build in BASELINES.items():
        assert getattr(build, "name", None) == name  # one spelling per method


def test_settings_validate() -> None:
    for bad in (
        {"gate": 0.0},
        {"vma_overlap": -1.0},
        {"polymerge_buffer": 0.0},
        {"baseline_threshold": 2.0},
        {"cluster_min_samples": 0},
    ):
        with pytest.raises(ValueError, match=next(iter(bad))):
            MapperConfig(**bad)


def test_settings_reach_every_baseline() -> None:
    # a setting chosen once reaches each baseline's map and threshold
    cfg = MapperConfig(smoothing=0.9, spacing=2.0, baseline_threshold=0.7)
    for name, build in BASELINES.items():
        method = build(_ScriptedSource({}), cfg, RANGE_60x30)
        assert method.score_threshold == 0.7, name
        if name != "cluster-fit":  # cluster-fit builds its map at the end
            assert method.map.smoothing == 0.9 and method.map.spacing == 2.0, name
