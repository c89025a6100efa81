"""What every baseline shares: its construction from a detection source, the shared
``MapperConfig`` and the perception range (``Baseline``; with the global map built frame by frame
and the crossing rule, ``OnlineMapBaseline``); reading one frame's detections from the source,
checking them, applying the score threshold and taking them to the world frame; creating the
global map.

Checks happen before anything is changed, so a bad frame (NaN points, bad pose) raises ValueError
and leaves the method's map and state as they were.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, PerceptionRange, RANGE_60x30, ego_to_world, pose_to_xy_yaw
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger
from icmapper.mapping.types import Detections, DetectionSource

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap


def new_global_map(config: MapperConfig) -> GlobalMap:
    """An empty engine map (icmapper.GlobalMap) with the config's smoothing and spacing; imported
    here so that importing a baseline does not need the native extension."""
    from icmapper._icmap import GlobalMap

    return GlobalMap(smoothing=config.smoothing, spacing=config.spacing)


@dataclass
class FrameInput:
    """One frame's checked detections: dets (after the score threshold), world (k, n, 2) float64
    world-frame points, pose_xyyaw (x, y, yaw) of the ego."""

    dets: Detections
    world: NDArray[np.float64]
    pose_xyyaw: tuple[float, float, float]


def read_frame(source: DetectionSource, frame: Frame, score_threshold: float) -> FrameInput:
    """Detects, validates (ValueError naming the problem), thresholds, moves to the world frame."""
    pose = np.asarray(frame.pose, dtype=np.float64)
    xyyaw = pose_to_xy_yaw(pose)  # validates shape and finiteness
    dets = source.detect(frame)
    dets.validate()
    keep = dets.scores >= score_threshold  # (k,)
    dets = Detections(
        classes=dets.classes[keep],
        scores=dets.scores[keep],
        points=dets.points[keep],
        queries=None if dets.queries is None else dets.queries[keep],
        gt_ids=None if dets.gt_ids is None else dets.gt_ids[keep],
    )
    k, n = dets.points.shape[:2]
    world = ego_to_world(dets.points.reshape(-1, 2), pose).reshape(k, n, 2)  # (k, n, 2)
    return FrameInput(dets, world, xyyaw)


class Baseline:
    """What every baseline is built from: ``source`` (where detections come from), ``config``
    (the shared ``MapperConfig``, its defaults when None; each baseline reads its own settings
    from it) and ``rng`` (the perception range). Detections below ``baseline_threshold`` are
    ignored (``read``). A baseline sets up its own settings and state in ``setup`` (called last
    by the constructor), not in a constructor of its own."""

    name = ""

    def __init__(
        self,
        source: DetectionSource,
        config: MapperConfig | None = None,
        rng: PerceptionRange = RANGE_60x30,
    ) -> None:
        self.source = source
        self.config = config or MapperConfig()
        self.score_threshold = self.config.baseline_threshold
        self.rng = rng
        self.setup()

    def setup(self) -> None:
        """The baseline's own settings (read from ``self.config``) and state."""

    def read(self, frame: Frame) -> FrameInput:
        """The frame's checked detections above the score threshold (``read_frame``)."""
        return read_frame(self.source, frame, self.score_threshold)


class OnlineMapBaseline(Baseline):
    """A baseline that builds its global map frame by frame (``map``, with the config's
    smoothing and spacing) and merges crossings by the shared rule (``crossings``)."""

    def setup(self) -> None:
        self.map: GlobalMap = new_global_map(self.config)
        self.crossings = CrossingMerger(self.config.crossing_merge, self.rng)

    def reset(self) -> None:
        self.source.reset()
        self.map = new_global_map(self.config)
        self.crossings.reset()

    def finish(self) -> GlobalMap:
        return self.map
