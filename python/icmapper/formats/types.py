"""Containers of per-frame predictions read from (or written to) a prediction file, in icmapper's
conventions once read: classes 0 ped_crossing, 1 divider, 2 boundary; points (k, 20, 2) float32
in the ego frame (x forward, y left, metres), crossings as rings without a repeated first point.

Readers of external formats convert into these; nothing here reads or writes files.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import CLASS_NAMES, NUM_INSTANCE_POINTS

#: How a file's points are expressed: "ego" (x forward, y left) or "lidar" (MapTR on nuScenes:
#: the LIDAR_TOP frame, x right, y forward; converted once the source's calibration is known).
POINT_FRAMES = ("ego", "lidar")


class PredictionFileError(ValueError):
    """A prediction file that is missing, malformed, of an unknown version, or whose frames do not
    fit the source; the message names the file (and the frame at fault)."""


@dataclass
class PredictedFrame:
    """The predictions of one frame as a file names them.

    A frame is named by ``token`` (a dataset's frame token) and/or ``timestamp`` (seconds), with
    ``sequence`` (the source sequence's name) where the format has it; ``pose`` (4, 4) float64
    ego->world or None. classes (k,) int64; scores (k,) float32; points (k, 20, 2) float32;
    track_ids (k,) int64 or None; queries (k, D) float32 or None.
    """

    token: str | None
    timestamp: float | None
    sequence: str | None
    classes: NDArray[np.int64]
    scores: NDArray[np.float32]
    points: NDArray[np.float32]
    pose: NDArray[np.float64] | None = None
    track_ids: NDArray[np.int64] | None = None
    queries: NDArray[np.float32] | None = None

    def __len__(self) -> int:
        return int(self.classes.shape[0])

    def name(self) -> str:
        """How error messages name this frame."""
        return frame_name(self.sequence, self.token, self.timestamp)


def frame_name(sequence: str | None, token: str | None, timestamp: float | None) -> str:
    """ "sequence 'a', token 'b', timestamp 1.5" (the parts that are given)."""
    parts = []
    if sequence is not None:
        parts.append(f"sequence {sequence!r}")
    if token is not None:
        parts.append(f"token {token!r}")
    if timestamp is not None:
        parts.append(f"timestamp {timestamp!r}")
    return ", ".join(parts) or "an unnamed frame"


@dataclass
class PredictionSet:
    """Every frame of one prediction file.

    format: the registered format name it was read as; path: the file; range_name: the
    perception range the predictions were made at ("60x30" when the file does not say);
    point_frame: one of ``POINT_FRAMES``; meta: the file's own metadata, kept as read.
    """

    format: str
    path: str
    frames: list[PredictedFrame]
    range_name: str = "60x30"
    point_frame: str = "ego"
    meta: dict = field(default_factory=dict)

    @property
    def has_queries(self) -> bool:
        """Every non-empty frame carries query features."""
        return bool(self.frames) and all(f.queries is not None for f in self.frames if len(f) > 0)


def class_index(name: object, where: str) -> int:
    """A class name ("ped_crossing", "divider", "boundary") -> its index; PredictionFileError
    naming ``where`` otherwise."""
    if isinstance(name, str) and name in CLASS_NAMES:
        return CLASS_NAMES.index(name)
    raise PredictionFileError(
        f"{where}: unknown class name {name!r}; expected one of {', '.join(CLASS_NAMES)}"
    )


def instance_points(raw: object, cls: int, where: str) -> NDArray[np.float32]:
    """One instance's points as a file gives them -> (20, 2) float32 in icmapper's convention.

    Exactly 20 points are kept as given (a network's output is not evenly spaced; resampling it
    would change what a method sees). A crossing whose last point repeats its first (StreamMapNet,
    MapTracker, MapTR store rings closed) loses the repeat; a crossing left with fewer than 20
    points keeps them all and gains the middles of its longest edges (the ring's shape unchanged:
    StreamMapNet's 20 points with the first repeated read back as the 19 given and one more);
    any other count is resampled to 20 points evenly spaced by arc length. NaN, inf, fewer than
    2 points or a bad shape raise PredictionFileError naming ``where``.
    """
    from icmapper import geom

    try:
        pts = np.asarray(raw, dtype=np.float64)
    except (TypeError, ValueError):
        raise PredictionFileError(f"{where}: points are not a list of [x, y] numbers") from None
    if pts.ndim == 1 and pts.size % 2 == 0:
        pts = pts.reshape(-1, 2)  # a flat [x1, y1, x2, y2, ...] list
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise PredictionFileError(
            f"{where}: points must be at least 2 [x, y] pairs, got shape {pts.shape}"
        )
    if not np.all(np.isfinite(pts)):
        raise PredictionFileError(f"{where}: points contain NaN or inf")
    closed = cls == 0
    if closed and pts.shape[0] > 2 and np.allclose(pts[0], pts[-1], atol=1e-6):
        pts = pts[:-1]
    if pts.shape[0] == NUM_INSTANCE_POINTS:
        return pts.astype(np.float32)
    if closed and pts.shape[0] > 2 and pts.shape[0] < NUM_INSTANCE_POINTS:
        return ring_with_points(pts, NUM_INSTANCE_POINTS).astype(np.float32)
    moves = np.any(pts[1:] != pts[:-1])
    if not moves:
        return np.repeat(pts[:1], NUM_INSTANCE_POINTS, axis=0).astype(np.float32)
    try:
        out = geom.resample(np.ascontiguousarray(pts), NUM_INSTANCE_POINTS, closed)  # (20, 2)
    except ValueError as exc:
        raise PredictionFileError(f"{where}: cannot resample the points ({exc})") from None
    return out.astype(np.float32)


def ring_with_points(ring: NDArray[np.floating], n: int) -> NDArray[np.float64]:
    """A closed ring (m, 2), m <= n, with the middle of its longest edge inserted until it has
    ``n`` points: every given point kept, the shape unchanged."""
    pts = [np.asarray(p, np.float64) for p in ring]
    while len(pts) < n:
        edges = [np.hypot(*(pts[(i + 1) % len(pts)] - pts[i])) for i in range(len(pts))]
        i = int(np.argmax(edges))
        pts.insert(i + 1, (pts[i] + pts[(i + 1) % len(pts)]) / 2)
    return np.stack(pts)  # (n, 2)


def ring_without_points(ring: NDArray[np.floating], n: int) -> NDArray[np.float64]:
    """A closed ring (m, 2), m >= n >= 3, with the points that shape it least removed until ``n``
    remain (each time the vertex spanning the smallest triangle with its neighbours,
    Visvalingam-Whyatt): corners are kept, points along a straight edge go first."""
    pts = np.asarray(ring, np.float64)
    while len(pts) > n:
        prev, nxt = np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0)  # (m, 2) each
        u, v = pts - prev, nxt - prev  # (m, 2) each
        area = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])  # (m,) twice the triangle areas
        pts = np.delete(pts, int(np.argmin(area)), axis=0)
    return pts


def frame_arrays(
    classes: list[int], scores: list[float], points: list[NDArray[np.float32]], where: str
) -> tuple[NDArray[np.int64], NDArray[np.float32], NDArray[np.float32]]:
    """Per-instance lists -> classes (k,) int64, scores (k,) float32, points (k, 20, 2) float32;
    scores must be finite (PredictionFileError naming ``where``)."""
    cls = np.asarray(classes, dtype=np.int64).reshape(-1)  # (k,)
    sc = np.asarray(scores, dtype=np.float64).reshape(-1)  # (k,)
    if not np.all(np.isfinite(sc)):
        raise PredictionFileError(f"{where}: scores contain NaN or inf")
    pts = (
        np.stack(points).astype(np.float32)
        if points
        else np.zeros((0, NUM_INSTANCE_POINTS, 2), np.float32)
    )  # (k, 20, 2)
    return cls, sc.astype(np.float32), pts
