"""Post-Track: per-frame detections linked into tracks by class and Chamfer distance (Hungarian
assignment with a gate), mapped with the engine's merge.

As a tracking baseline it is the paper's Post-Track: ids come after detection, from geometry only
(`positional_affinity`, gate g metres <=> score threshold exp(-g / scale)), with tracks kept for
`max_age` unseen frames. As a mapping method it uses those ids in place of IC-Mapper's learned
association and has no fusion: each detection is inserted into the global map under its track id
(new track) or merged into that instance with the same engine merge as IC-Mapper (curve fit for
polylines; crossings by ``crossing_merge``, `mapping.crossings`). A track that is lost and
re-found gets a new id, and so a second, overlapping global instance: that is the baseline's known
weakness.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import Frame, MapClass
from icmapper.mapping.baselines.common import OnlineMapBaseline
from icmapper.mapping.methods import MethodInfo, register_method
from icmapper.mapping.passed import merge_view
from icmapper.mapping.tracker import Tracker, positional_affinity
from icmapper.mapping.types import StepResult


class PostTrack(OnlineMapBaseline):
    """Post-Track ids + engine merge (see the module docstring).

    source: where detections come from. Settings (``MapperConfig``): ``baseline_threshold``
    (detections below are ignored), ``gate`` (largest Chamfer distance in metres of a link between
    a detection and a track, seen from the current ego frame), ``max_age`` (frames a track survives
    unseen), ``positional_scale`` (length scale of the positional affinity), ``smoothing`` /
    ``spacing`` (the global map's curve-fit smoothing and point spacing).
    """

    name = "post-track"

    def setup(self) -> None:
        super().setup()
        cfg = self.config
        self.tracker = Tracker(
            threshold=float(np.exp(-cfg.gate / cfg.positional_scale)), max_age=cfg.max_age
        )

    def reset(self) -> None:
        super().reset()
        self.tracker.reset()

    def step(self, frame: Frame) -> StepResult:
        """Detects, links detections to tracks, inserts / merges each into the global map."""
        inp = self.read(frame)
        dets = inp.dets
        _, trk_cls, trk_pts, _ = self.tracker.tracks_in_ego(frame.pose)  # (t,), (t, 20, 2)
        scale = self.config.positional_scale
        aff = positional_affinity(dets.points, dets.classes, trk_pts, trk_cls, scale)  # (k, t)
        ids = self.tracker.assign(aff, dets.classes, dets.points, frame.pose)  # (k,)
        inserted: list[int] = []
        merged: list[int] = []
        for i, tid in enumerate(ids.tolist()):
            if self._update(
                int(tid), int(dets.classes[i]), inp.world[i], dets.points[i], frame.index
            ):
                merged.append(tid)
            else:
                inserted.append(tid)
        return StepResult(frame.index, dets, ids, dets.points.copy(), inserted, merged)

    def _update(
        self, tid: int, cls: int, world: NDArray[np.float64], ego: NDArray[np.floating], frame: int
    ) -> bool:
        """Puts one detection (n, 2) world (``ego``: the same points in the ego frame) into the map
        under id `tid`; True if it was merged."""
        if tid in self.map:
            if MapClass(cls).closed:
                self.crossings.merge(self.map, tid, world, ego, frame)
            else:  # not the stretch the car has passed (mapping.passed)
                merge_view(self.map, tid, ego, world, self.config.merge_behind, frame)
            return True
        self.map.insert_with_id(tid, cls, world, frame)
        if MapClass(cls).closed:
            self.crossings.inserted(tid, ego)
        return False


register_method(
    MethodInfo(
        PostTrack.name,
        "Post-Track: positional tracking after detection, engine merge",
        build=PostTrack,
    )
)
