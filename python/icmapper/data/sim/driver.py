"""The ego driver: follows the lane graph of any WorldMap (synthetic or real) through junctions.

`drive(world, seed)` picks a start lane, walks random successors (turns included) until the route
is long enough, and moves along it with a smoothly varying speed in [3, 15] m/s (slower in tight
turns), sampling keyframes at `hz`. It only uses `world.lanes` (centrelines and successors), so it
works on lane graphs built from Argoverse 2 maps too. No I/O.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper.data.sim.geometry import arc_length, resample_by_length
from icmapper.data.types import KEYFRAME_HZ, LaneSegment, WorldMap, xy_yaw_to_pose

MIN_SPEED = 3.0  # m/s
MAX_SPEED = 15.0  # m/s
_TRIES = 64  # start lanes tried before giving up on a too-small lane graph


def drive(
    world: WorldMap, seed: int, duration_s: float | None = None, hz: float = KEYFRAME_HZ
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Drives an ego through `world` along its lane graph.

    world: a WorldMap with a non-empty `lanes` graph (centrelines (n, 2), successors).
    seed: all random choices (start lane, turns, speed profile, duration) derive from it.
    duration_s: drive length in seconds; None draws it uniformly from [20, 40] with the seed.
    hz: keyframe rate.
    Returns timestamps (T,) float64 seconds from 0 at 1/hz spacing, and poses (T, 4, 4) float64
    ego->world (flat ground, yaw along the lane). Raises ValueError when the lane graph is empty or
    too small to hold a route of the requested duration at the minimum speed.
    """
    if not world.lanes:
        raise ValueError(f"world {world.name!r} has no lane graph to drive on")
    if not (np.isfinite(hz) and hz > 0):
        raise ValueError(f"hz must be positive and finite, got {hz}")
    rng = np.random.default_rng([int(seed), 0xD21E])
    if duration_s is None:
        duration_s = float(rng.uniform(20.0, 40.0))
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be positive and finite, got {duration_s}")
    n_frames = int(np.floor(duration_s * hz + 1e-9)) + 1
    times = np.arange(n_frames, dtype=np.float64) / hz  # (T,)

    speed = _speed_profile(rng, times[-1])  # callable over fine time grid
    t_fine = np.arange(0.0, times[-1] + 0.05, 0.05)  # (F,)
    v = speed(t_fine)  # (F,) m/s before turn slow-down
    need = float(np.sum(v) * 0.05) + 20.0

    path = _route(world.lanes, rng, need)
    s_path = arc_length(path)
    # Slow down in tight turns: v <= sqrt(a_lat / curvature), kept within [MIN, MAX].
    curv = _curvature(path)  # (n,)
    s = np.zeros_like(t_fine)
    for i in range(1, len(t_fine)):
        k = float(np.interp(s[i - 1], s_path, curv))
        vi = min(v[i - 1], np.sqrt(2.5 / max(k, 1e-6)))
        s[i] = s[i - 1] + max(vi, MIN_SPEED) * 0.05
    s_key = np.interp(times, t_fine, s)  # (T,)
    if s_key[-1] > s_path[-1]:
        raise ValueError(f"lane graph of {world.name!r} too small for a {duration_s:.0f} s drive")
    xy = resample_by_length(path, s_key)  # (T, 2)
    ahead = resample_by_length(path, np.minimum(s_key + 1.0, s_path[-1]))  # (T, 2)
    behind = resample_by_length(path, np.maximum(s_key - 1.0, 0.0))  # (T, 2)
    d = ahead - behind
    yaw = np.arctan2(d[:, 1], d[:, 0])  # (T,)
    poses = np.stack(
        [xy_yaw_to_pose(float(x), float(y), float(a)) for (x, y), a in zip(xy, yaw, strict=True)]
    )
    return times, poses


def _speed_profile(rng: np.random.Generator, t_end: float):  # noqa: ANN202 (small closure)
    """A smooth random speed v(t) in [MIN_SPEED, MAX_SPEED]: a base speed plus a few slow sines."""
    base = rng.uniform(6.0, 12.0)
    amps = rng.uniform(0.5, 2.5, size=3)
    periods = rng.uniform(8.0, 30.0, size=3)
    phases = rng.uniform(0.0, 2 * np.pi, size=3)

    def v(t: NDArray) -> NDArray:
        w = base + np.sum(
            amps[:, None] * np.sin(2 * np.pi * t[None] / periods[:, None] + phases[:, None]), axis=0
        )
        return np.clip(w, MIN_SPEED, MAX_SPEED)

    return v


def _curvature(path: NDArray) -> NDArray[np.float64]:
    """Unsigned curvature (n,) of an (n, 2) polyline, smoothed over a few metres."""
    d1 = np.gradient(path, axis=0)
    d2 = np.gradient(d1, axis=0)
    num = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    den = np.maximum(np.linalg.norm(d1, axis=1) ** 3, 1e-9)
    k = num / den
    return np.convolve(k, np.ones(5) / 5, mode="same")


def _route(
    lanes: dict[int, LaneSegment], rng: np.random.Generator, need: float
) -> NDArray[np.float64]:
    """A random walk along successors from a random point of a random lane, resampled at 0.5 m,
    at least `need` metres long. Raises ValueError if no start gives a long enough route."""
    ids = sorted(lanes)
    best: NDArray[np.float64] | None = None
    for _ in range(_TRIES):
        lane = lanes[ids[int(rng.integers(len(ids)))]]
        cl = np.asarray(lane.centerline, dtype=np.float64)
        if cl.ndim != 2 or cl.shape[0] < 2 or not np.all(np.isfinite(cl)):
            continue
        start = float(rng.uniform(0.0, 0.5)) * float(arc_length(cl)[-1])
        pieces = [resample_by_length(cl, np.arange(start, arc_length(cl)[-1], 0.5))]
        total = float(arc_length(cl)[-1]) - start
        while total < need:
            succ = [x for x in lane.successors if x in lanes]
            if not succ:
                break
            lane = lanes[succ[int(rng.integers(len(succ)))]]
            cl = np.asarray(lane.centerline, dtype=np.float64)
            if cl.shape[0] < 2:
                break
            pieces.append(cl)
            total += float(arc_length(cl)[-1])
        path = _dedup(np.concatenate([p for p in pieces if len(p)]))
        if path.shape[0] < 2:
            continue
        s = arc_length(path)
        path = resample_by_length(path, np.arange(0.0, s[-1], 0.5))
        if total >= need:
            return path
        if best is None or len(path) > len(best):
            best = path
    if best is not None and best.shape[0] > 1:
        return best  # the caller reports that it is too short
    raise ValueError("lane graph has no usable lane (centrelines need >= 2 finite points)")


def _dedup(points: NDArray) -> NDArray[np.float64]:
    """Drops consecutive points closer than 1 cm."""
    if len(points) < 2:
        return points
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 0.01])
    return points[keep]
