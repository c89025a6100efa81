"""Containers of the online mapping loop: per-frame detections and the result of one step.

Shared by the IC-Mapper pipeline (mapper.py) and every baseline (baselines/), so that methods are
interchangeable behind one interface (`MappingMethod`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.data.types import Frame, PerceptionRange
    from icmapper.mapping.config import MapperConfig


@dataclass
class Detections:
    """Map instances detected in one frame, ego frame.

    classes (k,) int64; scores (k,) float32 in [0, 1]; points (k, 20, 2) float32 ego metres;
    queries (k, D) float32 decoder query features (None for detectors without them, e.g. oracle);
    gt_ids (k,) int64 true identity where known (oracle source, for tests/analysis only; never used
    by a method).
    """

    classes: NDArray[np.int64]
    scores: NDArray[np.float32]
    points: NDArray[np.float32]
    queries: NDArray[np.float32] | None = None
    gt_ids: NDArray[np.int64] | None = None

    def __len__(self) -> int:
        return int(self.classes.shape[0])

    @staticmethod
    def empty(num_points: int = 20) -> Detections:
        return Detections(
            np.zeros(0, np.int64), np.zeros(0, np.float32), np.zeros((0, num_points, 2), np.float32)
        )

    def validate(self) -> None:
        """Raises ValueError naming the problem (shapes, dtypes, NaN, classes, scores)."""
        k = len(self)
        if self.classes.ndim != 1:
            raise ValueError(f"detections: classes must be (k,), got {self.classes.shape}")
        if self.scores.shape != (k,):
            raise ValueError(f"detections: scores must be ({k},), got {self.scores.shape}")
        if self.points.ndim != 3 or self.points.shape[0] != k or self.points.shape[2] != 2:
            raise ValueError(f"detections: points must be ({k}, n, 2), got {self.points.shape}")
        if not np.all(np.isfinite(self.points)):
            bad = np.unique(np.nonzero(~np.isfinite(self.points))[0]).tolist()
            raise ValueError(f"detections: points of detection(s) {bad} contain NaN or inf")
        if not np.all(np.isfinite(self.scores)):
            raise ValueError("detections: scores contain NaN or inf")
        if k and (self.classes.min() < 0 or self.classes.max() > 2):
            raise ValueError(f"detections: unknown class in {sorted(set(self.classes.tolist()))}")


@dataclass
class StepResult:
    """What one mapping step produced.

    detections: the frame's detections (after the method's score threshold);
    track_ids (k,) int64: the identity given to each detection, a track id (IC-Mapper: the global
        instance its track maps into, unique in the frame) or -1 where the method gives none;
    points (k, 20, 2) float32 ego: the instance geometry after fusion (== detections.points for
    methods without fusion); inserted / merged: global-map ids touched this frame.
    """

    frame_index: int
    detections: Detections
    track_ids: NDArray[np.int64]
    points: NDArray[np.float32]
    inserted: list[int] = field(default_factory=list)
    merged: list[int] = field(default_factory=list)


class MappingMethod(Protocol):
    """A method that turns a frame stream into a global map (IC-Mapper or a baseline)."""

    name: str
    config: MapperConfig  # the settings it runs with
    rng: PerceptionRange  # the perception range its detections cover

    def reset(self) -> None:
        """Forget everything: a new sequence starts."""

    def step(self, frame: Frame) -> StepResult:
        """Processes one keyframe."""
        ...

    def finish(self) -> GlobalMap:
        """Ends the sequence and returns the global map (offline methods build it here)."""
        ...


class DetectionSource(Protocol):
    """Where per-frame detections come from: the learned detector or the noisy-GT oracle."""

    def reset(self) -> None: ...

    def detect(self, frame: Frame) -> Detections: ...
