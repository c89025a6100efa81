"""Flat instance tables: the container every metric module works on (no I/O).

A table holds the instances of many frames (of many sequences) at once, one row per instance:
``seq`` (N,) sequence index, ``frame`` (N,) frame index inside the sequence, ``classes`` (N,),
``ids`` (N,) track id (predictions) or ground-truth instance id, ``scores`` (N,) (1 for ground
truth), ``points`` (N, n, 2) in a common frame (ego frame of the row's frame for per-frame
metrics, world frame for global instances).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray


@dataclass
class Instances:
    """One row per instance; see the module docstring for the columns and shapes."""

    seq: NDArray[np.int64]
    frame: NDArray[np.int64]
    classes: NDArray[np.int64]
    ids: NDArray[np.int64]
    scores: NDArray[np.float64]
    points: NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.seq.shape[0])

    def __post_init__(self) -> None:
        n = self.seq.shape[0]
        for name in ("frame", "classes", "ids", "scores"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Instances.{name} must have shape ({n},)")
        if self.points.ndim != 3 or self.points.shape[0] != n or self.points.shape[2] != 2:
            raise ValueError(f"Instances.points must have shape ({n}, n_points, 2)")

    def key(self, num_frames: int, num_classes: int = 3) -> NDArray[np.int64]:
        """(N,) int64 group key of (seq, frame, class) for per-frame, per-class pairing."""
        return (self.seq * num_frames + self.frame) * num_classes + self.classes

    def select(self, mask: NDArray[np.bool_]) -> Instances:
        """The rows where mask (N,) is true."""
        return Instances(
            self.seq[mask],
            self.frame[mask],
            self.classes[mask],
            self.ids[mask],
            self.scores[mask],
            self.points[mask],
        )

    @staticmethod
    def empty(n_points: int = 20) -> Instances:
        z = np.zeros(0, dtype=np.int64)
        return Instances(z, z, z, z, np.zeros(0), np.zeros((0, n_points, 2)))

    @staticmethod
    def of_frame(
        seq: int,
        frame: int,
        classes: ArrayLike,
        ids: ArrayLike,
        scores: ArrayLike | None,
        points: NDArray[np.float64],
    ) -> Instances:
        """The k rows of one frame: classes, ids (k,), scores (k,) or None (1, ground truth) and
        points (k, n, 2) already shaped; k is the length of ``ids``."""
        k = int(np.asarray(ids).shape[0])
        return Instances(
            np.full(k, seq, dtype=np.int64),
            np.full(k, frame, dtype=np.int64),
            np.asarray(classes, dtype=np.int64).reshape(k),
            np.asarray(ids, dtype=np.int64).reshape(k),
            np.ones(k) if scores is None else np.asarray(scores, dtype=np.float64).reshape(k),
            points,
        )

    @staticmethod
    def concat(parts: Sequence[Instances]) -> Instances:
        """Rows of all parts, in order. Point counts must agree."""
        if not parts:
            return Instances.empty()
        return Instances(
            *(
                np.concatenate([getattr(p, f) for p in parts])
                for f in ("seq", "frame", "classes", "ids", "scores", "points")
            )
        )


def from_frames(
    seq: int,
    frames: Iterable[tuple[NDArray, NDArray, NDArray, NDArray | None]],
    n_points: int = 20,
) -> Instances:
    """Builds a table from per-frame (ids (k,), classes (k,), points (k, n, 2), scores (k,) | None).

    The frame index is the position in ``frames``; scores None means 1 (ground truth).
    """
    parts = []
    for f, (ids, classes, points, scores) in enumerate(frames):
        k = int(np.asarray(ids).shape[0])
        pts = (
            np.asarray(points, dtype=np.float64).reshape(k, -1, 2)
            if k
            else np.zeros((0, n_points, 2))
        )
        parts.append(Instances.of_frame(seq, f, classes, ids, scores, pts))
    return Instances.concat(parts) if parts else Instances.empty(n_points)
