"""The ego driver: follows lanes, speeds, keyframe rate, duration; works on any lane graph."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data import LaneSegment, WorldMap, pose_to_xy_yaw
from icmapper.data.sim import drive, generate_city
from shapely.geometry import Point, Polygon
from shapely.ops import unary_union


@pytest.fixture(scope="module")
def city() -> WorldMap:
    return generate_city(10_007)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drive_follows_lanes(city: WorldMap, seed: int) -> None:
    times, poses = drive(city, seed)
    assert poses.shape == (len(times), 4, 4) and poses.dtype == np.float64
    np.testing.assert_allclose(np.diff(times), 0.5)
    assert 20.0 <= times[-1] <= 40.0
    xy = poses[:, :2, 3]
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1) / 0.5  # (T-1,) chord speed
    assert step.min() >= 3.0 * 0.95 and step.max() <= 15.0 + 1e-6
    lanes = np.concatenate(
        [lane.centerline for lane in city.lanes.values()]
    )  # dense enough (<= 2 m)
    area = unary_union([Polygon(p).buffer(0) for p in city.drivable])
    for p in xy:
        assert np.min(np.linalg.norm(lanes - p, axis=1)) < 1.5
        assert area.buffer(0.05).contains(Point(p))
    # yaw follows the direction of travel
    yaws = np.array([pose_to_xy_yaw(p)[2] for p in poses[:-1]])
    heading = np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0]))
    assert np.max(np.abs(np.angle(np.exp(1j * (yaws - heading))))) < 0.35


def test_drive_deterministic_and_seeded(city: WorldMap) -> None:
    a, b, c = drive(city, 5), drive(city, 5), drive(city, 6)
    np.testing.assert_array_equal(a[1], b[1])
    assert a[1].shape != c[1].shape or not np.allclose(a[1], c[1])


def test_drive_generic_lane_graph_and_hz() -> None:
    # A 400 m loop of four lanes, no sim-specific fields.
    corners = [np.array(p, float) for p in [(0, 0), (100, 0), (100, 100), (0, 100)]]
    lanes = {}
    for i in range(4):
        a, b = corners[i], corners[(i + 1) % 4]
        cl = a + np.linspace(0, 1, 51)[:, None] * (b - a)
        lanes[10 + i] = LaneSegment(10 + i, cl, (10 + (i + 1) % 4,))
    world = WorldMap("loop", [], [], lanes)
    times, poses = drive(world, 0, duration_s=30.0, hz=10.0)
    assert len(times) == 301
    np.testing.assert_allclose(np.diff(times), 0.1)
    on_square = np.minimum.reduce(
        [
            np.abs(poses[:, 0, 3]),
            np.abs(poses[:, 0, 3] - 100),
            np.abs(poses[:, 1, 3]),
            np.abs(poses[:, 1, 3] - 100),
        ]
    )
    assert on_square.max() < 1.0


def test_drive_bad_input() -> None:
    with pytest.raises(ValueError, match="no lane graph"):
        drive(WorldMap("empty", []), 0)
    tiny = WorldMap("tiny", [], [], {0: LaneSegment(0, np.array([[0.0, 0.0], [5.0, 0.0]]), ())})
    with pytest.raises(ValueError, match="too small"):
        drive(tiny, 0)
    with pytest.raises(ValueError, match="hz"):
        drive(tiny, 0, hz=0.0)
