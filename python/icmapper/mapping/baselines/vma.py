"""Post-track & VMA-merge: Post-Track ids, then VMA-style rule-based merging.

Instead of IC-Mapper's curve fit, a newer observation of a track edits the stored instance:
*substitution* — the stored points within `overlap` metres of the new observation are replaced by
it — and *concatenation* — the stored points beyond either end of the new observation are kept and
joined to it in order (`splice.splice_polyline`). For a crossing, the new ring replaces the stored
one where they overlap and the stored vertices it does not cover are kept (convex hull of both;
`splice_ring`). The edited geometry is written back with the engine's `replace`, so the instance
keeps its id and its bookkeeping (first frame, number of observations).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

from icmapper.data.types import MapClass
from icmapper.mapping.baselines.post_track import PostTrack
from icmapper.mapping.methods import MethodInfo, register_method
from icmapper.mapping.passed import splice_view
from icmapper.mapping.splice import inside_ring, ring_distance


class VmaMerge(PostTrack):
    """Post-Track ids + substitution / concatenation merging.

    Settings as PostTrack's, plus ``vma_overlap``: distance (m) within which a stored point counts
    as seen again by the new observation.
    """

    name = "vma"

    def _update(
        self, tid: int, cls: int, world: NDArray[np.float64], ego: NDArray[np.floating], frame: int
    ) -> bool:
        if tid not in self.map:
            self.map.insert_with_id(tid, cls, world, frame)
            return False
        _, stored = self.map.get(tid)
        if MapClass(cls).closed:
            new = splice_ring(np.asarray(stored, np.float64), world, self.config.vma_overlap)
        else:  # not the stretch the car has passed (mapping.passed)
            cfg = self.config
            new = splice_view(stored, ego, world, cfg.merge_behind, cfg.vma_overlap)
        self.map.replace(tid, new, frame)
        return True


def splice_ring(
    stored: NDArray[np.float64], new: NDArray[np.float64], overlap: float
) -> NDArray[np.float64]:
    """Substitution / concatenation for a crossing: the new ring (q, 2) replaces the stored ring
    (m, 2) where they overlap; stored vertices outside the new ring and farther than `overlap` from
    it (parts not seen this time) are kept. The result is the convex hull of both sets, CCW (r, 2):
    crossings are convex in practice, and the hull keeps the ring simple."""
    far = (ring_distance(stored, new) > overlap) & ~inside_ring(stored, new)  # (m,)
    pts = np.concatenate([new, stored[far]])
    try:
        return pts[ConvexHull(pts).vertices]
    except QhullError:
        return new  # degenerate (collinear) points: keep the new observation as it is


register_method(
    MethodInfo(
        VmaMerge.name, "Post-track & VMA-merge: substitution and concatenation", build=VmaMerge
    )
)
