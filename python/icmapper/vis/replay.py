"""A run folder paired with its source, frame by frame: what the pictures and the viewer show.

A run (``icmapper.eval.runfmt``) stores per-frame predictions (after fusion, with track ids), the
poses and the final global map with its bookkeeping; camera images and ground truth are recomputed
from the run's source spec (``open_source``), and the source's poses are checked against the run's
(``check_run_frames``), so a picture never pairs a run with the wrong drive.

**The map so far.** A run does not store the global map of every frame, and replaying a method
from its stored predictions would not reproduce it in general (IC-Mapper's tentative tracks and
re-identification aliases, offline baselines that build their map at the end, detector settings
the run does not record). What the run does record exactly is each global instance's bookkeeping
(``GlobalMap.info``: first and last frame it was inserted into / merged at, observations). So "the
map so far" at frame t is every instance of the final map whose ``first_frame <= t``, drawn with
its *final* shape; instances still being observed (``last_frame >= t``) are told apart from those
already left behind. That is exact about which instances the map held at t and approximate about
their shapes (an instance grows and is refitted while it is observed). For an offline method every
instance has the frame where the map was built.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import (
    CameraRig,
    FrameGT,
    MapInstance,
    PerceptionRange,
    Sequence,
)
from icmapper.eval.runfmt import FramePredictions, Run, RunSequence, read_run

#: Image size (H, W) of camera images rendered for pictures.
PICTURE_IMAGE_SIZE = (192, 528)


@dataclass
class MapItem:
    """One instance of a stored global map: points (n, 2) float64 world frame, and its
    bookkeeping (first / last frame it was inserted into or merged at, observations)."""

    id: int
    cls: int
    points: NDArray[np.float64]
    closed: bool
    first_frame: int
    last_frame: int
    observations: int


def load_map_items(path: str | os.PathLike) -> list[MapItem]:
    """The instances of a native map file (``.icmap``), in id order. Needs the engine."""
    from icmapper import GlobalMap

    try:
        gm = GlobalMap.load(str(path))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot load the global map ({exc})") from None
    out = []
    for i in gm.ids().tolist():
        cls, pts = gm.get(int(i))
        info = gm.info(int(i))
        out.append(
            MapItem(
                id=int(i),
                cls=int(cls),
                points=np.asarray(pts, dtype=np.float64),
                closed=bool(info["closed"]),
                first_frame=int(info["first_frame"]),
                last_frame=int(info["last_frame"]),
                observations=int(info["observations"]),
            )
        )
    return out


@dataclass
class FrameView:
    """Everything a picture of frame t shows.

    t: position in the run; frame_index: index in the source sequence; pose (4, 4) ego->world;
    predictions: the run's predictions of the frame (ego frame); gt: the frame's ground truth
    (None without the source); images (C, 3, H, W) uint8 and rig: the cameras (None where the
    source has no images or was not opened); map_so_far: see the module docstring.
    """

    t: int
    frame_index: int
    timestamp: float
    pose: NDArray[np.float64]
    predictions: FramePredictions
    gt: FrameGT | None
    images: NDArray[np.uint8] | None
    rig: CameraRig | None
    map_so_far: list[MapItem] = field(default_factory=list)


@dataclass
class RunReplay:
    """One sequence of a run, with its source sequence (None when the source is not opened)."""

    run: Run
    seq: RunSequence
    source: Sequence | None
    rng: PerceptionRange
    map_items: list[MapItem]

    def __len__(self) -> int:
        return len(self.seq)

    @property
    def name(self) -> str:
        return self.seq.name

    @cached_property
    def gt_frames(self) -> list[FrameGT] | None:
        """Per-frame ground truth, ids stable over the sequence (None without the source)."""
        if self.source is None:
            return None
        from icmapper.data.gt import sequence_gt

        return sequence_gt(self.source, self.rng)

    @cached_property
    def global_gt(self) -> list[MapInstance] | None:
        """The ground-truth global map of the drive (None without the source)."""
        if self.source is None:
            return None
        from icmapper.data.gt import global_gt

        return global_gt(self.source, self.rng)

    def map_so_far(self, t: int) -> list[MapItem]:
        """Instances of the final map inserted by the run's frame t (module docstring)."""
        f = int(self.seq.frame_index[self._check(t)])
        return [m for m in self.map_items if m.first_frame <= f]

    def _check(self, t: int) -> int:
        if not isinstance(t, (int, np.integer)) or not 0 <= t < len(self):
            raise IndexError(f"frame {t} out of range for {self.name!r} ({len(self)} frames)")
        return int(t)

    def frame(self, t: int, with_images: bool = True) -> FrameView:
        """The view of the run's frame t (images rendered / read when ``with_images``)."""
        t = self._check(t)
        pred = self.seq.frame(t)
        images = rig = None
        gt = None
        if self.source is not None:
            src = self.source.frame(pred.frame_index, with_images=with_images)
            images, rig = src.images, self.source.rig
            gts = self.gt_frames
            gt = gts[pred.frame_index] if gts is not None else None
        return FrameView(
            t=t,
            frame_index=pred.frame_index,
            timestamp=pred.timestamp,
            pose=np.asarray(pred.pose, dtype=np.float64),
            predictions=pred,
            gt=gt,
            images=images,
            rig=rig,
            map_so_far=self.map_so_far(t),
        )


def pick_sequence(run: Run, sequence: str | int | None) -> RunSequence:
    """The run's sequence named ``sequence``, or at that position (None: the first)."""
    if not run.sequences:
        raise ValueError(f"run {run.path} holds no sequences")
    names = [s.name for s in run.sequences]
    if sequence is None:
        return run.sequences[0]
    if isinstance(sequence, str) and sequence in names:
        return run.sequences[names.index(sequence)]
    if isinstance(sequence, int) or sequence.isdigit():
        k = int(sequence)
        if 0 <= k < len(names):
            return run.sequences[k]
    raise ValueError(f"run {run.path} has no sequence {sequence!r}; it has {names}")


def open_replay(
    run_dir: str | os.PathLike,
    sequence: str | int | None = None,
    image_size: tuple[int, int] = PICTURE_IMAGE_SIZE,
    with_source: bool = True,
    render: bool = True,
) -> RunReplay:
    """Reads the run folder and opens its source (``with_source``) for images and ground truth.

    sequence: a sequence name or position (None: the first). image_size (H, W): the size camera
    images are rendered / resized to (the rig's intrinsics follow it). render: False opens the
    source without images (ground truth only). Raises RunFormatError / ValueError naming the
    problem; a source that cannot be opened names the spec and suggests ``with_source=False``.
    """
    from icmapper.eval.evaluate import check_run_frames

    run = read_run(run_dir)
    rs = pick_sequence(run, sequence)
    rng = PerceptionRange.from_name(run.range_name)
    items = load_map_items(rs.global_map_path) if rs.global_map_path is not None else []
    source = None
    if with_source:
        from icmapper.data.sources import open_source

        try:
            seqs = open_source(run.source, image_size=tuple(image_size), render=render)
        except (ValueError, OSError) as exc:
            raise ValueError(
                f"cannot open the run's source {run.source!r} for images and ground truth "
                f"({exc}); run without the source (--no-source) to see predictions only"
            ) from None
        sub = [s for s in seqs if s.name == rs.name]
        if not sub:
            raise ValueError(f"sequence {rs.name!r} is not in the run's source {run.source!r}")
        one = Run(run.path, run.method, run.source, run.range_name, [rs])
        source = check_run_frames(one, sub)[0]
    return RunReplay(run, rs, source, rng, items)
