"""PolyMerge-style baseline: rule-based online merging without track ids.

Each detection (world frame) is compared with the global instances of its class near the ego
(`GlobalMap.query` over the perception range enlarged by the buffer). Overlap is the larger of the
fractions of either instance's points lying within `buffer` metres of the other
(`splice.overlap_fraction`; crossings also count points inside). The best candidate with overlap >=
`min_overlap` absorbs the detection: a polyline by projection splicing (`splice.splice_polyline`:
the overlapped part replaced by the detection, the parts beyond its ends kept, so the instance
extends), a crossing by the shared crossing rule (``crossing_merge``, `mapping.crossings`).
Otherwise the detection is inserted as a new instance. Detections are handled one at a time, in
order, so two detections of one frame may merge into the same instance.

`StepResult.track_ids` holds the global instance each detection went into (the method has no
tracks; this is what it would report as identity).
"""

from __future__ import annotations

import numpy as np

from icmapper.data.types import Frame, MapClass
from icmapper.mapping.baselines.common import OnlineMapBaseline
from icmapper.mapping.methods import MethodInfo, register_method
from icmapper.mapping.passed import splice_view
from icmapper.mapping.splice import overlap_fraction
from icmapper.mapping.types import StepResult


class PolyMerge(OnlineMapBaseline):
    """Rule-based online merging without ids (see the module docstring).

    source: detections; score_threshold: detections below are ignored; buffer: overlap distance (m);
    min_overlap: overlap fraction needed to merge; rng: perception range (for the map query);
    smoothing / spacing: the global map's settings (crossing union, point spacing).
    """

    name = "polymerge"

    def setup(self) -> None:
        super().setup()
        self.buffer = self.config.polymerge_buffer
        self.min_overlap = self.config.polymerge_min_overlap

    def step(self, frame: Frame) -> StepResult:
        """Merges every detection of the frame into an overlapping instance or inserts it."""
        inp = self.read(frame)
        dets = inp.dets
        ids = np.full(len(dets), -1, np.int64)
        inserted: list[int] = []
        merged: list[int] = []
        half = (self.rng.half_x, self.rng.half_y)
        for i in range(len(dets)):
            cls = int(dets.classes[i])
            closed = MapClass(cls).closed
            world = inp.world[i]  # (n, 2)
            best, best_ov = -1, self.min_overlap - 1e-12
            for gid in self.map.query(inp.pose_xyyaw, half, self.buffer).tolist():
                g_cls, g_pts = self.map.get(gid)
                if int(g_cls) != cls:
                    continue
                ov = overlap_fraction(world, np.asarray(g_pts, np.float64), self.buffer, closed)
                if ov > best_ov:
                    best, best_ov = int(gid), ov
            if best < 0:
                best = int(self.map.insert(cls, world, frame.index))
                if closed:
                    self.crossings.inserted(best, dets.points[i])
                inserted.append(best)
            else:
                if closed:
                    self.crossings.merge(self.map, best, world, dets.points[i], frame.index)
                else:
                    _, stored = self.map.get(best)
                    ego = dets.points[i]  # not the stretch the car has passed (mapping.passed)
                    new = splice_view(stored, ego, world, self.config.merge_behind, self.buffer)
                    self.map.replace(best, new, frame.index)
                merged.append(best)
            ids[i] = best
        return StepResult(frame.index, dets, ids, dets.points.copy(), inserted, merged)


register_method(
    MethodInfo(
        PolyMerge.name,
        "PolyMerge-style rule-based merging by overlap, without ids",
        build=PolyMerge,
    )
)
