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

It works on the finished map only, so per-frame predictions (AP, tracking) do not change. Every
method is checked against the same detections (those scoring at least ``track_threshold``),
so a comparison gives every method the same clean-up; ``verify = false`` reports without it.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap
    from icmapper.data.types import PerceptionRange
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.types import Detections


def _nowhere(points: NDArray[np.float64]) -> NDArray[np.bool_]:
    """No ground counts as covered: verification looks for no additions."""
    return np.zeros(len(points), bool)


def unbacked(
    gmap: GlobalMap,
    frames: Iterable[tuple[NDArray[np.float64], Detections]],
    config: MapperConfig,
    rng: PerceptionRange,
    keep: Collection[int] = (),
) -> list[int]:
    """The ids of ``gmap``'s instances that the drive's ``frames`` ((4, 4) ego -> world pose,
    the frame's detections) do not back (module docstring), sorted; ``keep``: ids never
    returned (a continued city map's earlier instances, which this drive did not build)."""
    from icmapper.city.update import ChangeDetector, UpdateConfig

    thresholds = replace(
        UpdateConfig(),
        score_threshold=config.track_threshold,
        remove_frames=config.verify_frames,
        remove_share=config.verify_share,
        min_travel=config.min_travel,
    )
    evidence = ChangeDetector(gmap, rng, _nowhere, thresholds)
    for k, (pose, dets) in enumerate(frames):
        evidence.observe((0, k), pose, dets.classes, dets.scores, dets.points)
    return [
        i
        for i, s in sorted(evidence.stored.items())
        if i not in keep and s.evidence.mostly_missed(config.verify_frames, config.verify_share)
    ]


def verify_map(
    gmap: GlobalMap,
    frames: Iterable[tuple[NDArray[np.float64], Detections]],
    config: MapperConfig,
    rng: PerceptionRange,
    keep: Collection[int] = (),
) -> list[int]:
    """Removes from ``gmap`` the instances ``unbacked`` names; returns their ids."""
    gone = unbacked(gmap, frames, config, rng, keep)
    for i in gone:
        gmap.remove(i)
    return gone
