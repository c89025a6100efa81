"""Data: typed containers (types), synthetic cities and renderer (sim), Argoverse 2 and nuScenes
readers (av2, nuscenes), ground truth (gt), torch datasets (datasets), source specs (sources)."""

from icmapper.data.types import (
    CLASS_NAMES,
    NUM_CLASSES,
    NUM_INSTANCE_POINTS,
    CameraRig,
    Frame,
    FrameGT,
    LaneSegment,
    MapClass,
    MapInstance,
    PerceptionRange,
    RANGE_60x30,
    RANGE_100x50,
    Sequence,
    WorldMap,
    ego_to_world,
    pose_to_xy_yaw,
    world_to_ego,
    xy_yaw_to_pose,
)

__all__ = [
    "CLASS_NAMES",
    "NUM_CLASSES",
    "NUM_INSTANCE_POINTS",
    "RANGE_60x30",
    "RANGE_100x50",
    "CameraRig",
    "Frame",
    "FrameGT",
    "LaneSegment",
    "MapClass",
    "MapInstance",
    "PerceptionRange",
    "Sequence",
    "WorldMap",
    "ego_to_world",
    "pose_to_xy_yaw",
    "world_to_ego",
    "xy_yaw_to_pose",
]
