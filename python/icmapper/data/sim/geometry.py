"""Small planar-curve helpers shared by the synthetic city generator, the driver and the renderer:
Bezier sampling, sub-curves and offset curves (arc length and points at arc lengths are
``icmapper.geom``'s, under the names the simulator uses). Numpy, no randomness, no I/O."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper import geom


def quadratic_bezier(p0: NDArray, p1: NDArray, p2: NDArray, n: int) -> NDArray[np.float64]:
    """Samples a quadratic Bezier curve with control points p0, p1, p2 ((2,) each) at n parameter
    values evenly spaced in [0, 1]. Returns (n, 2) float64."""
    t = np.linspace(0.0, 1.0, n)[:, None]  # (n, 1)
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t**2 * p2  # (n, 2)


def cubic_bezier(p0: NDArray, p1: NDArray, p2: NDArray, p3: NDArray, n: int) -> NDArray[np.float64]:
    """Samples a cubic Bezier curve (control points (2,) each) at n evenly spaced parameters.
    Returns (n, 2) float64."""
    t = np.linspace(0.0, 1.0, n)[:, None]  # (n, 1)
    u = 1 - t
    return u**3 * p0 + 3 * u**2 * t * p1 + 3 * u * t**2 * p2 + t**3 * p3  # (n, 2)


#: Cumulative arc length (n,) of an (n, 2) polyline (``icmapper.geom.arc_lengths``).
arc_length = geom.arc_lengths
#: Points (m, 2) of an (n, 2) polyline at arc lengths (m,), clamped to the ends
#: (``icmapper.geom.points_at_lengths``).
resample_by_length = geom.points_at_lengths


def sub_curve(points: NDArray, s0: float, s1: float, spacing: float = 1.0) -> NDArray[np.float64]:
    """The piece of an (n, 2) polyline between arc lengths s0 < s1, sampled about every `spacing`
    metres (at least 2 points). Returns (m, 2)."""
    m = max(2, int(np.ceil((s1 - s0) / spacing)) + 1)
    return resample_by_length(points, np.linspace(s0, s1, m))


def tangents(points: NDArray) -> NDArray[np.float64]:
    """Unit tangent of an (n, 2) polyline at every vertex (central differences). Returns (n, 2)."""
    d = np.gradient(points, axis=0)  # (n, 2)
    norm = np.linalg.norm(d, axis=1, keepdims=True)  # (n, 1)
    return d / np.maximum(norm, 1e-12)


def offset_curve(points: NDArray, offset: float) -> NDArray[np.float64]:
    """The (n, 2) polyline shifted sideways by `offset` metres (positive: to the left of travel)."""
    t = tangents(points)  # (n, 2)
    normal = np.stack([-t[:, 1], t[:, 0]], axis=1)  # (n, 2) left normal
    return points + offset * normal
