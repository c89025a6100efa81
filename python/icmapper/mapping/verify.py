"""Map verification: a finished map checked against the drive's own detections, for every method.

A learned detector now and then draws a line where the road has none (a piece in a junction box,
on a road without paint, a kerb along a lane line). The mapping methods keep such a piece as an
instance of its own, and the map keeps it however often the car passes the place again and the
detector draws nothing there. With ``MapperConfig.verify`` the map a method returns at the end of
a drive is checked against every frame of that drive: each instance gathers, frame by frame, the
evidence a city update gathers for a removal (``city.update.ChangeDetector``: an instance is
*expected* in a frame where enough of its points lie inside the range, *seen* where detections
of its class scoring at least ``track_threshold`` lie near enough of them, *missed* otherwise;
a car standing still counts once, ``min_travel``), and an instance expected in at least
``verify_frames`` frames and missed in at least ``verify_share`` of them is removed: the drive
itself says it is not there. A true piece seen only at the range edge, or only once because the
car passed it once, is expected in few frames and stays.

A line the method grew past what is there (a lane line drawn on into a junction, a kerb round a
corner the road does not take) keeps its backed part: an end of a lane line or kerb whose points
were expected in at least ``verify_frames`` frames and had no detection of their class within
``UpdateConfig.remove_gate`` (1 m) in at least ``verify_share`` of them is cut off, when it is
at least ``MIN_TRIM`` metres long. A stretch inside the line is left as it is (the line stays
one instance).

It works on the finished map only, so per-frame predictions (AP, tracking) do not change. Every
method is checked against the same detections (those scoring at least ``track_threshold``),
so a comparison gives every method the same clean-up; ``verify = false`` reports without it.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.city.update import ChangeDetector, Stored
    from icmapper.data.types import PerceptionRange
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.types import Detections

#: Shortest unbacked end (metres) cut off a lane line or kerb.
MIN_TRIM = 2.0


@dataclass
class Verdict:
    """What the check found: ``removed`` (ids, sorted) and ``trimmed`` (id -> the [start, stop)
    of its stored points that stay)."""

    removed: list[int] = field(default_factory=list)
    trimmed: dict[int, tuple[int, int]] = field(default_factory=dict)

    def apply(self, gmap: GlobalMap) -> Verdict:
        """Removes and cuts in ``gmap`` what the verdict names; returns the verdict."""
        for i in self.removed:
            gmap.remove(i)
        for i, (a, b) in self.trimmed.items():
            gmap.trim(i, a, b)
        return self


def gather(
    gmap: GlobalMap,
    frames: Iterable[tuple[NDArray[np.float64], Detections]],
    config: MapperConfig,
    rng: PerceptionRange,
) -> ChangeDetector:
    """The evidence of the drive's ``frames`` ((4, 4) ego -> world pose, the frame's
    detections) on every instance of ``gmap`` (a city update's, ``city.update``). ValueError
    naming the frame for a pose that is not a finite (4, 4) matrix or detections whose points
    are not (k, n, 2) finite values."""
    from icmapper.city.update import ChangeDetector, UpdateConfig

    thresholds = replace(
        UpdateConfig(),
        score_threshold=config.track_threshold,
        remove_frames=config.verify_frames,
        remove_share=config.verify_share,
        min_travel=config.min_travel,
    )
    evidence = ChangeDetector(gmap, rng, None, thresholds)  # no additions looked for
    for k, (pose, dets) in enumerate(frames):
        pose = np.asarray(pose, np.float64)
        pts = np.asarray(dets.points)
        if pose.shape != (4, 4) or not np.isfinite(pose).all():
            raise ValueError(f"frame {k}: the pose must be a finite (4, 4) matrix")
        if pts.ndim != 3 or pts.shape[0] != len(dets.classes) or pts.shape[-1] != 2:
            raise ValueError(f"frame {k}: detection points must be (k, n, 2), got {pts.shape}")
        if not np.isfinite(pts).all():
            raise ValueError(f"frame {k}: detection points must be finite")
        evidence.observe((0, k), pose, dets.classes, dets.scores, pts)
    return evidence


def _kept_stretch(s: Stored, config: MapperConfig) -> tuple[int, int]:
    """[start, stop) of a line's points left when its unbacked ends go (module docstring)."""
    e, near = s.point_expected, s.point_near  # (n,), (n,)
    bad = (e >= config.verify_frames) & (e - near >= config.verify_share * e)  # (n,)
    a, b = 0, len(bad)
    while a < b and bad[a]:
        a += 1
    while b > a and bad[b - 1]:
        b -= 1
    step = np.linalg.norm(np.diff(s.points, axis=0), axis=1)  # (n - 1,)
    if step[:a].sum() < MIN_TRIM:
        a = 0
    if step[max(b - 1, 0) :].sum() < MIN_TRIM:
        b = len(bad)
    return a, b


def check(
    gmap: GlobalMap,
    frames: Iterable[tuple[NDArray[np.float64], Detections]],
    config: MapperConfig,
    rng: PerceptionRange,
    keep: Collection[int] = (),
) -> Verdict:
    """What the drive's ``frames`` do not back in ``gmap`` (module docstring); ``keep``: ids
    left alone (a continued city map's earlier instances, which this drive did not build)."""
    verdict = Verdict()
    for i, s in sorted(gather(gmap, frames, config, rng).stored.items()):
        if i in keep:
            continue
        if s.evidence.mostly_missed(config.verify_frames, config.verify_share):
            verdict.removed.append(i)
        elif not s.closed:
            a, b = _kept_stretch(s, config)
            if (a, b) != (0, len(s.points)) and b - a >= 2:
                verdict.trimmed[i] = (a, b)
    return verdict
