"""How an observed crossing merges into its global instance (``MapperConfig.crossing_merge``).

The engine merges a crossing by polygon union (``GlobalMap.merge``). Union only grows: every
noisy observation of the same crossing widens the stored polygon, so the better a method tracks a
crossing (the more observations reach one instance), the larger its stored crossing becomes. With
the learned detector this made IC-Mapper's crossings worse than Post-Track's although it tracked
them better (validation drives: CD_ped 1.24 m against 1.13 m).

``"average"`` (the default) tells two kinds of view apart. An observation lying entirely inside
the range (every point at least ``EDGE_MARGIN`` metres from its edge) is a *complete* view; any
other is *cut* by the range edge.

- A view inside the range that encloses less than ``PARTIAL_AREA`` of the stored crossing's area
  is a *partial* detection (the detector saw part of a far crosswalk) and counts as cut: on the
  real intersections of av2-mini such views replaced a crosswalk built from cut views by a blob
  of its middle.
- Complete views are averaged: the first replaces what cut views built, and the stored ring is
  the running mean of the complete views since. Both rings are resampled to ``RING_POINTS`` points
  along the contour (dense enough that resampling again and again rounds a corner by less than
  0.2 m over 20 views), oriented counter-clockwise, aligned by the cyclic shift closest in the sum
  of squared distances, and the k-th complete view is blended with weight 1 / k. Noise then
  cancels instead of accumulating.
- A cut view extends a crossing not yet seen complete by union, but only when it reveals it: when
  at least ``REVEAL_FRACTION`` of its area lies outside the stored crossing (a crossing coming
  into range). Otherwise, and always once a complete view has been seen, it is left out: it shows
  no more of the crossing, and its union would only add its noise (on the validation drives the
  unions of cut views, mostly as a crossing leaves the range, made every method's crossings about
  0.3 m too wide).

The rule needs to know, per instance, how many complete views it has averaged: a
``CrossingMerger`` keeps that beside the map it merges into (``counts``; the mapper saves it with
its state). ``"union"`` is the engine's rule everywhere.

Every method that merges crossings with the engine reads the setting (IC-Mapper, Post-Track,
PolyMerge, and stage 2's online training map), so a comparison runs them under the same rule.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import PerceptionRange
from icmapper.geom import resample_many, signed_ring_area

if TYPE_CHECKING:
    from icmapper._icmap import GlobalMap

#: The rules of ``MapperConfig.crossing_merge``.
CROSSING_MERGES = ("average", "union")
#: Metres from the range edge within which an observation counts as cut by it.
EDGE_MARGIN = 1.0
#: Points of the rings averaged (along the contour).
RING_POINTS = 160
#: Share of a cut view's area that must lie outside the stored crossing for it to be merged.
REVEAL_FRACTION = 0.5
#: Square metres: a view enclosing less is degenerate (a collapsed ring) and is left out.
MIN_VIEW_AREA = 1.0
#: Share of the stored crossing's area under which a view inside the range is a partial
#: detection, handled as a cut view (docs/mapping.md, "Crossings seen in part").
PARTIAL_AREA = 0.5
#: Square metres a view cut by the range edge must enclose for a new crossing to enter the map
#: on its first sighting (``MapperConfig.confirm_score``): a crosswalk is about 3 x 8 m; a
#: smaller cut view may be the corner of a neighbouring one (real intersections: a sliver taken
#: in at once was absorbed into the crosswalk beside it, which then grew over both).
CONFIRM_AREA = 10.0


def is_complete(
    points_ego: NDArray[np.floating], rng: PerceptionRange, margin: float = EDGE_MARGIN
) -> bool:
    """True when every point (n, 2) ego metres lies at least ``margin`` inside the range."""
    p = np.asarray(points_ego, dtype=np.float64)
    return bool(
        np.all(np.abs(p[:, 0]) <= rng.half_x - margin)
        and np.all(np.abs(p[:, 1]) <= rng.half_y - margin)
    )


def _ccw(ring: NDArray[np.float64]) -> NDArray[np.float64]:
    return ring[::-1].copy() if signed_ring_area(ring) < 0 else ring


def average_rings(
    stored: NDArray[np.floating], new: NDArray[np.floating], weight: float, n: int = RING_POINTS
) -> NDArray[np.float64]:
    """(1 - weight) * stored + weight * new for two rings (m, 2) and (q, 2) (first point not
    repeated): both resampled to ``n`` points along their contour, counter-clockwise, ``new``
    shifted cyclically to the alignment closest to ``stored`` -> (n, 2) float64, CCW.
    ValueError for a weight outside [0, 1], rings with fewer than 3 points or non-finite points."""
    if not 0.0 <= weight <= 1.0:
        raise ValueError(f"average_rings: weight must be in [0, 1], got {weight}")
    rings = []
    for name, r in (("stored", stored), ("new", new)):
        r = np.asarray(r, dtype=np.float64)
        if r.ndim != 2 or r.shape[0] < 3 or r.shape[1] != 2:
            raise ValueError(f"average_rings: {name} ring must be (m >= 3, 2), got {r.shape}")
        if not np.all(np.isfinite(r)):
            raise ValueError(f"average_rings: {name} ring has NaN or inf points")
        rings.append(_ccw(resample_many(r[None], n, True)[0]))  # (n, 2)
    a, b = rings
    shifts = np.stack([np.roll(b, k, axis=0) for k in range(n)])  # (n, n, 2)
    k = int(((shifts - a[None]) ** 2).sum(axis=(1, 2)).argmin())
    return (1.0 - weight) * a + weight * shifts[k]


def _area_outside(view: NDArray[np.float64], stored: NDArray[np.float64]) -> float:
    """Share of the area of ring ``view`` (n, 2) outside ring ``stored`` (m, 2) (1.0 when the
    stored ring encloses no area; 0.0 when the view encloses none)."""
    from shapely.geometry import Polygon

    v, s = Polygon(view).buffer(0), Polygon(stored).buffer(0)
    if v.area <= 0.0:
        return 0.0
    if s.area <= 0.0:
        return 1.0
    return float(v.difference(s).area / v.area)


class CrossingMerger:
    """Merges crossing observations into the instances of one global map by ``rule``
    (``CROSSING_MERGES``) and keeps what the ``"average"`` rule needs: per instance id, how many
    complete views its stored ring averages (``counts``; 0: only cut views so far).

    ``inserted`` registers a crossing inserted from a view, ``merge`` merges a later view;
    ``reset`` starts a new map.
    """

    def __init__(self, rule: str, rng: PerceptionRange) -> None:
        if rule not in CROSSING_MERGES:
            raise ValueError(f"crossing merge must be one of {CROSSING_MERGES}, got {rule!r}")
        self.rule, self.rng = rule, rng
        self._counts: dict[int, int] = {}

    @property
    def counts(self) -> dict[int, int]:
        """Instance id -> complete views averaged (a copy)."""
        return dict(self._counts)

    def reset(self, counts: dict[int, int] | None = None) -> None:
        """Forgets every instance, or restores ``counts`` (``counts`` of a saved state)."""
        if counts is not None and any(int(v) < 0 for v in counts.values()):
            raise ValueError("crossing view counts must be >= 0")
        self._counts = {int(k): int(v) for k, v in (counts or {}).items()}

    def inserted(self, target: int, ego: NDArray[np.floating]) -> None:
        """Instance ``target`` was inserted from a view with points ``ego`` (n, 2) ego metres (a
        degenerate one counts as not seen whole, so that the first good complete view replaces
        it)."""
        whole = is_complete(ego, self.rng) and abs(signed_ring_area(ego)) >= MIN_VIEW_AREA
        self._counts[int(target)] = int(whole)

    def confirmable(self, ego: NDArray[np.floating]) -> bool:
        """Whether a view (n, 2) ego metres of a new crossing may enter the map at its first
        sighting: seen whole, or cut by the range edge but enclosing ``CONFIRM_AREA``."""
        return is_complete(ego, self.rng) or abs(signed_ring_area(ego)) >= CONFIRM_AREA

    def absorbed(self, gone: int, into: int) -> None:
        """Instance ``gone`` became part of ``into`` (``GlobalMap.absorb``): their complete views
        add up."""
        n = self._counts.pop(int(gone), 0) + self._counts.get(int(into), 0)
        if int(into) in self._counts or n:
            self._counts[int(into)] = n

    def merge(
        self,
        global_map: GlobalMap,
        target: int,
        world: NDArray[np.floating],
        ego: NDArray[np.floating],
        frame: int,
    ) -> bool:
        """Merges one observation, ``world`` (n, 2) world frame and the same points in the ego
        frame ``ego`` (n, 2), into instance ``target``. Returns False when the rule leaves the view
        out (a view cut by the range edge or partial that reveals nothing, or one enclosing less
        than ``MIN_VIEW_AREA``; the map is unchanged). KeyError for an unknown id, ValueError for
        bad geometry (the instance is unchanged)."""
        if self.rule == "union":
            global_map.merge(target, world, frame)
            return True
        _, stored = global_map.get(target)  # KeyError for an unknown id
        seen = self._counts.get(int(target), 0)
        pts, ego_pts = np.asarray(world, dtype=np.float64), np.asarray(ego, dtype=np.float64)
        for name, arr in (("world", pts), ("ego", ego_pts)):
            if arr.ndim != 2 or arr.shape[0] < 3 or arr.shape[1] != 2:
                raise ValueError(f"crossing view ({name}) must be (n >= 3, 2), got {arr.shape}")
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"crossing view ({name}) has NaN or inf points")
        if ego_pts.shape != pts.shape:
            raise ValueError(f"crossing view: world {pts.shape} and ego {ego_pts.shape} differ")
        area = abs(signed_ring_area(pts))
        if area < MIN_VIEW_AREA:
            return False  # a collapsed ring: no view of a crossing
        if is_complete(ego_pts, self.rng) and area >= PARTIAL_AREA * abs(
            signed_ring_area(np.asarray(stored, dtype=np.float64))
        ):  # seen whole, not in part
            new = pts if seen == 0 else average_rings(stored, pts, 1.0 / (seen + 1))
            global_map.replace(target, new, frame)
            self._counts[int(target)] = seen + 1
            return True
        if seen > 0:
            return False
        if _area_outside(pts, np.asarray(stored, np.float64)) < REVEAL_FRACTION:
            return False
        global_map.merge(target, pts, frame)
        return True
