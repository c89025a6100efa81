"""Ground truth: clipping into the range, 20-point pieces, stable/distinct ids, point orders,
ids derived by matching, global GT."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data import gt
from icmapper.data.types import (
    CameraRig,
    MapClass,
    MapInstance,
    RANGE_60x30,
    Sequence,
    WorldMap,
    xy_yaw_to_pose,
)


def _rig() -> CameraRig:
    return CameraRig(("CAM",), np.eye(3)[None], np.eye(4)[None], (8, 8))


def _world() -> WorldMap:
    xs = np.linspace(-300, 300, 61)
    line = lambda y: np.stack([xs, np.full_like(xs, y)], axis=1)  # noqa: E731
    # A U that leaves the range ahead and comes back: two pieces while x in the U's legs.
    u = np.array([[10.0, 10.0], [60.0, 10.0], [60.0, -10.0], [10.0, -10.0]])
    loop = np.array([[-50.0, -7.0], [400.0, -7.0], [400.0, 7.0], [-50.0, 7.0], [-50.0, -7.0]])
    cross = np.array([[40.0, -7.0], [44.0, -7.0], [44.0, 7.0], [40.0, 7.0]])
    return WorldMap(
        "toy",
        [
            MapInstance(1, MapClass.DIVIDER, line(0.0), False, "dashed_white"),
            MapInstance(2, MapClass.DIVIDER, line(3.5), False, "dashed_white"),
            MapInstance(3, MapClass.DIVIDER, u, False, "solid_white"),
            MapInstance(4, MapClass.BOUNDARY, loop, False, "curb"),
            MapInstance(5, MapClass.PED_CROSSING, cross, True, "zebra"),
        ],
    )


def _seq(xs: np.ndarray, world: WorldMap | None = None, source: str = "sim") -> Sequence:
    poses = np.stack([xy_yaw_to_pose(float(x), 0.0, 0.0) for x in xs])
    # nuScenes' world instances carry no identity across frames: ids come from matching
    by_matching = source == "nuscenes"
    ts = np.arange(len(xs)) * 0.5
    return Sequence("toy", source, world or _world(), ts, poses, _rig(), None, by_matching)


def test_frame_gt_clips_inside_range_and_samples_20_points() -> None:
    pose = xy_yaw_to_pose(20.0, 1.0, 0.1)
    g = gt.frame_gt(_world(), pose, RANGE_60x30)
    assert g.points.shape == (len(g), 20, 2) and g.points.dtype == np.float32
    assert g.ids.dtype == np.int64 and g.classes.dtype == np.int64
    assert np.all(np.abs(g.points[..., 0]) <= 30 + 1e-4)
    assert np.all(np.abs(g.points[..., 1]) <= 15 + 1e-4)
    assert set(g.classes.tolist()) == {0, 1, 2}
    # Evenly spaced by arc length: equal consecutive distances for the straight dividers.
    for k in np.nonzero(g.ids // gt.PIECE_FACTOR == 1)[0]:
        d = np.linalg.norm(np.diff(g.points[k], axis=0), axis=1)
        assert np.allclose(d, d.mean(), atol=1e-3)


def test_frame_gt_points_in_ego_frame() -> None:
    g = gt.frame_gt(_world(), xy_yaw_to_pose(0.0, -2.0, 0.0), RANGE_60x30)
    k = int(np.nonzero(g.ids == 1 * gt.PIECE_FACTOR)[0][0])
    assert np.allclose(g.points[k][:, 1], 2.0, atol=1e-4)  # the y = 0 line is 2 m to the left


def test_pieces_get_distinct_ids() -> None:
    # At x = 15 the range x in [-15, 45] cuts both legs of the U, not its far end (x = 60).
    g = gt.frame_gt(_world(), xy_yaw_to_pose(15.0, 0.0, 0.0), RANGE_60x30)
    u = g.ids[g.ids // gt.PIECE_FACTOR == 3]
    assert len(u) == 2 and len(set(u.tolist())) == 2


def test_sequence_ids_stable_over_a_drive() -> None:
    seq = _seq(np.arange(0.0, 60.0, 5.0))
    frames = gt.sequence_gt(seq, RANGE_60x30)
    # Straight dividers: one piece each, same id every frame.
    for f in frames:
        assert 1000 in f.ids and 2000 in f.ids
    # The U: its two legs keep their ids while both are in range, then it becomes one piece
    # that keeps one of the earlier ids.
    u_ids = [set(f.ids[f.ids // 1000 == 3].tolist()) for f in frames]
    assert u_ids[3] == u_ids[4] and len(u_ids[3]) == 2
    merged = [s for s in u_ids[5:] if len(s) == 1]
    assert merged and all(s <= u_ids[3] for s in merged)
    for f in frames:
        assert len(set(f.ids.tolist())) == len(f)


def test_loop_seam_gives_one_piece() -> None:
    # The boundary loop's first/last point (-50, -7) lies inside the range at x = -30.
    g = gt.frame_gt(_world(), xy_yaw_to_pose(-30.0, 0.0, 0.0), RANGE_60x30)
    assert np.sum(g.ids // 1000 == 4) == 1


def test_point_orders() -> None:
    pts = np.random.default_rng(0).normal(size=(20, 2)).astype(np.float32)
    o = gt.point_orders(pts, closed=False)
    assert o.shape == (2, 20, 2) and np.array_equal(o[0], pts) and np.array_equal(o[1], pts[::-1])
    c = gt.point_orders(pts, closed=True)
    assert c.shape == (40, 20, 2) and c.dtype == np.float32
    assert len({c[i].tobytes() for i in range(40)}) == 40  # all distinct
    for i in range(40):  # every order is the same cyclic sequence, either direction
        seq = c[i] if i < 20 else c[i][::-1]
        shift = int(np.nonzero((pts == seq[0]).all(axis=1))[0][0])
        assert np.array_equal(np.roll(pts, -shift, axis=0), seq)
    with pytest.raises(ValueError):
        gt.point_orders(np.zeros((20, 3)), closed=False)


def test_derive_ids_by_matching_recovers_identity() -> None:
    world = _world()
    world.instances = [i for i in world.instances if i.id != 3]  # the U merges its legs
    seq = _seq(np.arange(0.0, 40.0, 5.0), world)
    true = gt.sequence_gt(seq, RANGE_60x30)
    derived = gt.derive_ids_by_matching(true, seq.poses)
    pairs = {
        (int(a), int(b))
        for t, d in zip(true, derived, strict=True)
        for a, b in zip(t.ids, d.ids, strict=True)
    }
    # A bijection between true and derived ids over the whole drive.
    assert len({a for a, _ in pairs}) == len(pairs) == len({b for _, b in pairs})
    with pytest.raises(ValueError):
        gt.derive_ids_by_matching(true, seq.poses[:-1])


def test_nuscenes_source_derives_ids() -> None:
    frames = gt.sequence_gt(_seq(np.arange(0.0, 20.0, 5.0), source="nuscenes"), RANGE_60x30)
    assert frames[0].ids.max() < len(frames[0])  # fresh ids 0..k-1, not world ids


def test_global_gt_is_union_of_visited_patches() -> None:
    seq = _seq(np.array([0.0, 10.0, 20.0, 120.0]))  # a gap: x in [50, 90] is never seen
    glob = gt.global_gt(seq, RANGE_60x30)
    parts = sorted(
        (float(i.points[:, 0].min()), float(i.points[:, 0].max()))
        for i in glob
        if i.id // 1000 == 1
    )
    assert np.allclose(parts, [(-30.0, 50.0), (90.0, 150.0)], atol=1e-6)
    ids = [i.id for i in glob]
    assert len(ids) == len(set(ids))
    cross = [i for i in glob if i.cls == MapClass.PED_CROSSING]
    assert len(cross) == 1 and cross[0].closed


@pytest.mark.parametrize("join_gap, want", [(0.0, 2), (39.0, 2), (41.0, 1)])
def test_global_gt_join_gap_joins_pieces_of_one_line(join_gap: float, want: int) -> None:
    """The what-if of the diagnosis: visited pieces of one line less than ``join_gap`` apart
    along it count as one (the 40 m gap x in [50, 90] above); 0 is the protocol."""
    seq = _seq(np.array([0.0, 10.0, 20.0, 120.0]))
    glob = gt.global_gt(seq, RANGE_60x30, join_gap)
    line = [i for i in glob if i.id // 1000 == 1]
    assert len(line) == want
    if want == 1:
        assert np.allclose([line[0].points[:, 0].min(), line[0].points[:, 0].max()], [-30, 150])
    with pytest.raises(ValueError, match="join_gap"):
        gt.global_gt(seq, RANGE_60x30, -1.0)
