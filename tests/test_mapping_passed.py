"""``mapping.passed``: a polyline observation leaves the stretch the car has passed as the map holds
it. The rule on its own (``fresh_runs``), and in every method that merges polylines: a drive whose
detections of one divider drift 0.5 m sideways behind the car keeps the divider where the near
views put it with ``merge_behind``, and takes the far views' drift without it."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data.types import MapClass, RANGE_60x30, Sequence, WorldMap, xy_yaw_to_pose
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.methods import methods
from icmapper.mapping.passed import COVER, fresh_runs
from icmapper.mapping.types import Detections


def _line(x0: float, x1: float, y: float = 0.0, n: int = 20) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], -1)  # (n, 2)


def test_nothing_left_out_when_off_or_ahead() -> None:
    obs = _line(-30.0, 30.0)
    stored = _line(-60.0, 60.0)
    # off: the whole observation, as it is
    (run,) = fresh_runs(obs, obs, stored, 0.0)
    np.testing.assert_array_equal(run, obs)
    # nothing behind the car beyond 40 m
    (run,) = fresh_runs(obs, obs, stored, 40.0)
    np.testing.assert_array_equal(run, obs)


def test_passed_points_on_the_instance_are_left_out() -> None:
    obs = _line(-30.0, 30.0, 0.3)  # 0.3 m off the stored line: on it (within COVER)
    stored = _line(-60.0, 60.0)
    (run,) = fresh_runs(obs, obs, stored, 5.0)
    assert run[:, 0].min() >= -5.0 and run[:, 0].max() == 30.0
    np.testing.assert_array_equal(run, obs[obs[:, 0] >= -5.0])


def test_passed_points_the_instance_lacks_still_merge() -> None:
    # The stored instance starts 10 m behind the car: the observation's points before its start
    # extend it (a run of their own); those on it between -10 and -5 m are left out.
    obs = _line(-30.0, 30.0, n=61)  # 1 m apart
    stored = _line(-10.0, 60.0)
    front, rear = fresh_runs(obs, obs, stored, 5.0)
    np.testing.assert_array_equal(front, obs[obs[:, 0] >= -5.0])
    np.testing.assert_array_equal(rear, obs[obs[:, 0] <= -10.0])
    # Beside the instance, farther than COVER: never seen before, kept whole; within it, on it.
    far, near = obs + [0.0, COVER + 1.0], obs + [0.0, COVER - 0.5]
    (run,) = fresh_runs(far, far, _line(-60.0, 60.0), 5.0)
    assert len(run) == len(obs)
    (run,) = fresh_runs(near, near, _line(-60.0, 60.0), 5.0)
    np.testing.assert_array_equal(run, near[obs[:, 0] >= -5.0])


def test_world_frame_is_used_for_the_instance() -> None:
    # The ego frame decides what is behind, the world frame what lies on the instance: the
    # car at x = 100 heading +x, the stored instance in world coordinates.
    ego = _line(-30.0, 30.0)
    world = ego + [100.0, 0.0]
    (run,) = fresh_runs(ego, world, _line(40.0, 160.0), 5.0)
    np.testing.assert_array_equal(run, world[ego[:, 0] >= -5.0])
    # a lone point left between two left-out ones is no run
    assert fresh_runs(ego[:3], world[:3], _line(40.0, 160.0), 5.0) == []


def test_bad_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="fresh_runs"):
        fresh_runs(_line(0, 1, n=5), _line(0, 1, n=6), _line(0, 1), 5.0)


def test_merge_behind_is_validated() -> None:
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="merge_behind must be >= 0"):
            MapperConfig(merge_behind=bad)


# --- a drive: one divider at y = 2 along the world x axis, the car at y = 0 -------------------
STEPS = np.arange(0.0, 81.0, 2.0)  # (41,) the car's x


class _DriftingSource:
    """Sees the divider 20 points over x_ego in [-30, 30]; behind the car the detections drift
    sideways: 0 m down to 5 m behind, 0.5 m from 10 m behind (a ramp between)."""

    def reset(self) -> None:
        pass

    def detect(self, frame) -> Detections:
        px = float(frame.pose[0, 3])
        x = np.linspace(max(-30.0, -40.0 - px), 30.0, 20)  # (20,) the divider starts at x = -40
        drift = 0.5 * np.clip((-x - 5.0) / 5.0, 0.0, 1.0)
        pts = np.stack([x, 2.0 + drift], -1)[None].astype(np.float32)  # (1, 20, 2)
        return Detections(
            np.array([MapClass.DIVIDER]), np.ones(1, np.float32), pts, gt_ids=np.array([1])
        )


def _drive() -> Sequence:
    return Sequence(
        name="drift",
        source="test",
        world=WorldMap("drift", []),
        timestamps=np.arange(len(STEPS)) * 0.5,
        poses=np.stack([xy_yaw_to_pose(px, 0.0, 0.0) for px in STEPS]),
        rig=None,  # type: ignore[arg-type]  # the scripted source needs no cameras
    )


def _drift_of_passed_stretch(name: str, merge_behind: float) -> float:
    """Mean sideways error (m) of the map's divider over x in [0, 40], well behind the car's
    last position (80) and well ahead of its first (0)."""
    cfg = MapperConfig(merge_behind=merge_behind, baseline_threshold=0.5)
    seq = _drive()
    if name.startswith("icmapper"):
        method = Mapper(_DriftingSource(), config=cfg)  # positional association, no fusion
        if name == "icmapper-spliced":  # as if fused: spliced into the instance (splice_into)
            method._fuse = lambda det, *a: (det.points.copy(), np.ones(len(det), bool))  # type: ignore[method-assign]
    else:
        method = methods()[name].build(_DriftingSource(), cfg, RANGE_60x30)  # type: ignore[misc]
    method.reset()
    for i in range(len(seq)):
        method.step(seq.frame(i, with_images=False))
    gmap = method.finish()
    (gid,) = [int(i) for i in gmap.ids()]
    pts = np.asarray(gmap.get(gid)[1])
    mid = pts[(pts[:, 0] >= 0.0) & (pts[:, 0] <= 40.0)]
    return float(np.abs(mid[:, 1] - 2.0).mean())


@pytest.mark.parametrize("name", ["icmapper", "icmapper-spliced", "post-track", "vma", "polymerge"])
def test_passed_stretch_keeps_the_near_view(name: str) -> None:
    kept = _drift_of_passed_stretch(name, 5.0)
    latest = _drift_of_passed_stretch(name, 0.0)
    assert kept < 0.05, f"{name}: {kept:.3f} m off with merge_behind = 5"
    assert latest > 0.4, f"{name}: {latest:.3f} m off with merge_behind = 0 (the far views win)"


@pytest.mark.parametrize("splice_overlap", [None, 0.5])
def test_merge_view_fits_or_splices_the_fresh_runs(splice_overlap: float | None) -> None:
    """``merge_view`` (Post-Track, stage 2's online map): the passed stretch of the instance is
    kept, the rest follows the view, by curve fit or by splice."""
    from icmapper import GlobalMap
    from icmapper.mapping.passed import merge_view

    m = GlobalMap(smoothing=0.5, spacing=1.0)
    m.insert_with_id(3, int(MapClass.DIVIDER), _line(-60.0, 60.0, n=121), frame=0)
    ego = _line(-30.0, 30.0, 0.5, n=61)  # the car at x = 0, the view 0.5 m to the side
    merge_view(m, 3, ego, ego, 5.0, 1, splice_overlap)
    pts = np.asarray(m.get(3)[1])
    passed, ahead = pts[pts[:, 0] < -12.0], pts[(pts[:, 0] > 5.0) & (pts[:, 0] < 25.0)]
    np.testing.assert_allclose(passed[:, 1], 0.0, atol=1e-12)  # kept exactly
    np.testing.assert_allclose(
        ahead[:, 1], 0.5, atol=0.05
    )  # the view (steps at -5 and 30 m smoothed)
    assert pts[-1, 0] == pytest.approx(60.0)  # the far end beyond the view is kept too
