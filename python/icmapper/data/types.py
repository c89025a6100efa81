"""Typed containers shared by every part of icmapper: map instances, world maps, camera rigs,
frames, sequences and per-frame / global ground truth.

Conventions (docs/architecture.md): metres, seconds, radians; world frame = the map/city frame with
z up; ego frame x forward, y left, z up; a pose is SE(3) ego->world as a (4, 4) float64 matrix;
classes 0 ped_crossing (closed), 1 divider, 2 boundary (open). This module holds no I/O.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

#: Number of points of a network instance (evenly spaced by arc length).
NUM_INSTANCE_POINTS = 20


class MapClass(enum.IntEnum):
    """Map element classes, in StreamMapNet's order."""

    PED_CROSSING = 0
    DIVIDER = 1
    BOUNDARY = 2

    @property
    def closed(self) -> bool:
        """Crossings are closed polygons; dividers and boundaries open polylines."""
        return self is MapClass.PED_CROSSING


CLASS_NAMES: tuple[str, ...] = ("ped_crossing", "divider", "boundary")
NUM_CLASSES = len(CLASS_NAMES)
#: How a map element changes on the road (city updates, issue 32), in this order.
CHANGE_TYPES: tuple[str, ...] = ("added", "removed", "moved")


@dataclass(frozen=True)
class PerceptionRange:
    """An ego-centred, axis-aligned perception range: x in [-half_x, half_x], y in
    [-half_y, half_y]."""

    half_x: float
    half_y: float

    @property
    def name(self) -> str:
        return f"{2 * self.half_x:g}x{2 * self.half_y:g}"

    @staticmethod
    def from_name(name: str) -> PerceptionRange:
        """Parses "60x30" / "100x50" (full extents, metres)."""
        try:
            sx, sy = name.lower().split("x")
            rng = PerceptionRange(float(sx) / 2.0, float(sy) / 2.0)
        except ValueError:
            raise ValueError(f"bad perception range {name!r}; expected e.g. '60x30'") from None
        if rng.half_x <= 0 or rng.half_y <= 0:
            raise ValueError(f"perception range {name!r} must be positive")
        return rng


RANGE_60x30 = PerceptionRange(30.0, 15.0)
RANGE_100x50 = PerceptionRange(50.0, 25.0)


@dataclass
class MapInstance:
    """One map element in the world frame.

    points: (n, 2) float64 world coordinates; a closed crossing is a ring without a repeated point.
    style: how it is painted ("solid_white", "dashed_white", "solid_yellow", "double_yellow",
    "dashed_yellow", "curb", "zebra", ...); "" when unknown.
    """

    id: int
    cls: MapClass
    points: NDArray[np.float64]
    closed: bool
    style: str = ""


@dataclass
class LaneSegment:
    """A lane of the lane graph: centreline (n, 2) float64 world, successor lane ids, width (m)."""

    id: int
    centerline: NDArray[np.float64]
    successors: tuple[int, ...]
    width: float = 3.5


@dataclass
class WorldMap:
    """The static world of a city or log: map instances (with true identity), drivable-area
    polygons (each (n, 2) float64) and the lane graph used to drive an ego through it; ``geo``:
    where its frame lies on Earth (a key of ``icmapper.georef.GEO_FRAMES``: an AV2 city code such
    as "PIT" or a nuScenes map location such as "boston-seaport"; "" when unknown)."""

    name: str
    instances: list[MapInstance]
    drivable: list[NDArray[np.float64]] = field(default_factory=list)
    lanes: dict[int, LaneSegment] = field(default_factory=dict)
    geo: str = ""


@dataclass
class CameraRig:
    """Cameras of a vehicle. intrinsics (C, 3, 3) float64 pixels; cam_to_ego (C, 4, 4) float64
    (camera frame: x right, y down, z forward); image_size (H, W) of every camera."""

    names: tuple[str, ...]
    intrinsics: NDArray[np.float64]
    cam_to_ego: NDArray[np.float64]
    image_size: tuple[int, int]

    @property
    def num_cameras(self) -> int:
        return len(self.names)


@dataclass
class Frame:
    """One keyframe. pose (4, 4) float64 ego->world (full SE(3) for real logs; mapping uses its
    (x, y, yaw)); rig: this keyframe's camera parameters; images (C, 3, H, W) uint8 or None when
    the source has no images."""

    index: int
    timestamp: float
    pose: NDArray[np.float64]
    rig: CameraRig
    images: NDArray[np.uint8] | None = None


#: What a sequence's ``render(i)`` gives: images read from the log's own cameras, images
#: rendered by the simulator over the map, or none.
IMAGE_KINDS = ("real", "rendered", "none")


#: Keyframes per second of every source (nuScenes' keyframes; AV2 and the synthetic drives are
#: sampled to it) and so of what the learned detector's temporal memory and the tracker's
#: frame counts were built for (docs/mapping.md, "Keyframes 0.5 s apart").
KEYFRAME_HZ = 2.0


@dataclass
class Sequence:
    """A drive through a world: T keyframes (timestamps (T,) seconds, poses (T, 4, 4)), the world
    it drives through (ground truth with identity) and, optionally, the images of its frames.

    render(i) -> (C, 3, H, W) uint8 images of frame i: read from disk for real-image sources,
    rendered by the simulator otherwise (None: the sequence has no images); ``images`` says which
    ("real" | "rendered" | "none").
    rig: the sequence's nominal camera rig (frame 0's); ``frame_rigs`` (T rigs, or None when one
    rig holds for every frame) gives each keyframe's own camera parameters: for real logs the
    camera->reference-ego transform is composed through the ego poses at the camera and
    reference timestamps, so it changes from keyframe to keyframe (``rig_of(i)``).
    gt_ids_by_matching: the world's instances carry no identity usable across frames (nuScenes):
    ground-truth ids are derived by matching consecutive frames (``gt.derive_ids_by_matching``).
    """

    name: str
    source: str
    world: WorldMap
    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]
    rig: CameraRig
    render: Callable[[int], NDArray[np.uint8]] | None = None
    gt_ids_by_matching: bool = False
    frame_rigs: list[CameraRig] | None = None
    images: str = ""

    def __post_init__(self) -> None:
        if not self.images:
            self.images = "none" if self.render is None else "rendered"
        if self.images not in IMAGE_KINDS:
            raise ValueError(f"Sequence.images must be one of {IMAGE_KINDS}, got {self.images!r}")
        if self.frame_rigs is not None and len(self.frame_rigs) != len(self.timestamps):
            raise ValueError(
                f"sequence {self.name!r}: {len(self.frame_rigs)} frame rigs for "
                f"{len(self.timestamps)} frames"
            )

    def __len__(self) -> int:
        return int(self.timestamps.shape[0])

    def rig_of(self, i: int) -> CameraRig:
        """The camera rig of keyframe i (its own when the sequence has per-frame rigs)."""
        return self.rig if self.frame_rigs is None else self.frame_rigs[i]

    def frame(self, i: int, with_images: bool = True) -> Frame:
        if not -len(self) <= i < len(self):
            raise IndexError(
                f"frame {i} out of range for sequence {self.name!r} of {len(self)} frames"
            )
        i %= len(self)
        images = self.render(i) if (with_images and self.render is not None) else None
        return Frame(i, float(self.timestamps[i]), self.poses[i], self.rig_of(i), images)

    def select(self, indices: NDArray[np.int64], name: str | None = None) -> Sequence:
        """A sequence of the frames ``indices`` (k,) of this one, in that order (repeats
        allowed): their timestamps, poses, rigs and images, the same world; named ``name`` (by
        default this one's). ValueError for an index out of range."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)  # (k,)
        if len(idx) == 0 or idx.min() < 0 or idx.max() >= len(self):
            raise ValueError(f"sequence {self.name!r}: frame indices must lie in [0, {len(self)})")
        render = self.render

        def selected(i: int) -> NDArray[np.uint8]:
            assert render is not None
            return render(int(idx[i]))

        return Sequence(
            name or self.name,
            self.source,
            self.world,
            np.asarray(self.timestamps, np.float64)[idx],
            np.asarray(self.poses, np.float64)[idx],
            self.rig,
            selected if render is not None else None,
            self.gt_ids_by_matching,
            [self.frame_rigs[j] for j in idx] if self.frame_rigs is not None else None,
            self.images,
        )

    def keyframes(self, hz: float = KEYFRAME_HZ) -> Sequence:
        """The frames nearest to every 1 / ``hz`` seconds from the first (``hz`` defaults to the
        keyframe rate icmapper's detector and tracker are built for: docs/mapping.md,
        "Keyframes 0.5 s apart"); a sequence already at that rate or slower comes back whole."""
        from icmapper.data.extract import subsample_indices

        return self.select(subsample_indices(self.timestamps, hz))


@dataclass
class FrameGT:
    """Ground truth of one frame in the ego frame, for one perception range.

    ids (k,) int64 stable across frames; classes (k,) int64; points (k, 20, 2) float32 ego frame,
    evenly spaced by arc length (closed crossings along the contour, first point not repeated).
    """

    ids: NDArray[np.int64]
    classes: NDArray[np.int64]
    points: NDArray[np.float32]

    def __len__(self) -> int:
        return int(self.ids.shape[0])


def pose_to_xy_yaw(pose: NDArray[np.float64]) -> tuple[float, float, float]:
    """(4, 4) SE(3) ego->world -> (x, y, yaw) for the 2-D map engine."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4):
        raise ValueError(f"pose must have shape (4, 4), got {pose.shape}")
    if not np.all(np.isfinite(pose)):
        raise ValueError("pose contains NaN or inf")
    return float(pose[0, 3]), float(pose[1, 3]), float(np.arctan2(pose[1, 0], pose[0, 0]))


#: Degrees the ego must turn, below the travel of ``stands_still``, to count as moving.
STILL_TURN = 5.0


def stands_still(
    xyyaw: tuple[float, float, float],
    last: tuple[float, float, float] | None,
    min_travel: float,
) -> bool:
    """Whether the ego at (x, y, yaw) still stands where it was at ``last``: within
    ``min_travel`` metres, turned less than ``STILL_TURN`` degrees (``last`` None or
    ``min_travel`` 0: False). The mapper's ``MapperConfig.min_travel`` and the city update's
    ``UpdateConfig.min_travel`` read it."""
    if last is None or min_travel <= 0:
        return False
    moved = float(np.hypot(xyyaw[0] - last[0], xyyaw[1] - last[1]))
    turned = abs((xyyaw[2] - last[2] + np.pi) % (2 * np.pi) - np.pi)
    return moved < min_travel and turned < np.radians(STILL_TURN)


def xy_yaw_to_pose(x: float, y: float, yaw: float, z: float = 0.0) -> NDArray[np.float64]:
    """(x, y, yaw) -> (4, 4) SE(3) ego->world (flat ground)."""
    c, s = np.cos(yaw), np.sin(yaw)
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:3, 3] = [x, y, z]
    return pose


def world_to_ego(points: NDArray[np.float64], pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 2) world points -> (n, 2) ego points for the (4, 4) ego->world pose (planar)."""
    r = pose[:2, :2]  # (2, 2)
    return (np.asarray(points, dtype=np.float64) - pose[:2, 3]) @ r  # (n, 2)


def ego_to_world(points: NDArray[np.floating], pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 2) ego points -> (n, 2) world points for the (4, 4) ego->world pose (planar)."""
    return np.asarray(points, dtype=np.float64) @ pose[:2, :2].T + pose[:2, 3]  # (n, 2)
