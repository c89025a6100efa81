"""What every baseline shares: reading one frame's detections from the source, checking them,
applying the score threshold and taking them to the world frame; creating the global map.

Checks happen before anything is changed, so a bad frame (NaN points, bad pose) raises ValueError
and leaves the method's map and state as they were.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, ego_to_world, pose_to_xy_yaw
from icmapper.mapping.types import Detections, DetectionSource

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.mapping.config import MapperConfig


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
