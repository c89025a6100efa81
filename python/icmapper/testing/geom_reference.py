"""Plain numpy / shapely forms of the engine's patch geometry, written from the definitions: the
oriented patch of a pose (x, y, yaw) as a shapely polygon, and the world <-> ego transforms of
points. The oracle of the geometry tests and the reference side of ``benchmarks/geometry.py``;
nothing in the runtime package uses them (the engine has its own)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray

Pose2 = Sequence[float] | NDArray[np.float64]  # (x, y, yaw)


def patch_polygon(pose: Pose2, hx: float, hy: float) -> shapely.Polygon:
    """The patch of half extents ``hx`` x ``hy`` around ``pose``, oriented by its yaw, as a
    shapely polygon in the world frame."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    corners = [(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)]
    return shapely.Polygon([(x + c * u - s * v, y + s * u + c * v) for u, v in corners])


def to_ego(points: NDArray[np.floating], pose: Pose2) -> NDArray[np.float64]:
    """World (..., 2) -> the ego frame of ``pose`` (..., 2)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = points[..., 0] - x, points[..., 1] - y
    return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def to_world(points: NDArray[np.floating], pose: Pose2) -> NDArray[np.float64]:
    """Ego (..., 2) of ``pose`` -> world (..., 2)."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack(
        [x + c * points[..., 0] - s * points[..., 1], y + s * points[..., 0] + c * points[..., 1]],
        axis=-1,
    )
