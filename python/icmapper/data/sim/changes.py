"""Changed synthetic cities: the same city after road works, with the true changes known.

``change_world(world, poses, rng, seed)`` returns a copy of a ``WorldMap`` in which, near the given
drives (every change lies where the drives see it), a few map elements changed and everything else
is untouched (the same instances, ids and points, the same lane graph, so the same drives):

- ``removed`` crossing / divider: the instance is gone;
- ``added`` crossing: a zebra 4 m deep across the street at a divider's middle (kerb to kerb);
- ``added`` divider: a new lane line parallel to a divider, 1.5-1.9 m beside it;
- ``moved`` divider: repainted 0.5-2 m sideways (further than that from every other lane line);
- ``moved`` boundary: a kerb section of 15-30 m pushed 2-3 m outwards (a lane added), with 5 m
  ramps at its ends; the drivable area grows by the strip between the old and the new kerb.

Each change is a ``TrueChange`` (the geometry after the change; a removal's before it; a move
keeps both), at least 15 m from the others. Deterministic from (world, poses, seed).
``changed_city_drives`` gives the drives of ``sim_city_drives`` through the changed city (the
``sim-city-changed`` source) with the changes. This module only builds geometry; no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import LineString, MultiLineString, Polygon

from icmapper.data.gt import in_range_counts
from icmapper.data.sim.geometry import arc_length, offset_curve, sub_curve, tangents
from icmapper.data.types import (
    CLASS_NAMES,
    MapClass,
    MapInstance,
    PerceptionRange,
    RANGE_60x30,
    Sequence,
    WorldMap,
    pose_to_xy_yaw,
)

#: Minimum distance (m) between the geometries of two changes of one world.
CHANGE_SPACING = 15.0


@dataclass(frozen=True)
class TrueChange:
    """One true change of a world: ``change`` (added | removed | moved), class, the world
    instance id (a new id for an addition), ``points`` (n, 2) world frame: the geometry after the
    change (a removal: before it), ``before`` (m, 2): a move's geometry before it (None else),
    ``closed`` (a crossing ring)."""

    change: str
    cls: int
    instance: int
    points: NDArray[np.float64]
    closed: bool
    before: NDArray[np.float64] | None = None

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "change": self.change,
            "class": CLASS_NAMES[self.cls],
            "instance": self.instance,
            "closed": self.closed,
            "points": np.round(self.points, 4).tolist(),
        }
        if self.before is not None:
            out["before"] = np.round(self.before, 4).tolist()
        return out

    @staticmethod
    def from_json(raw: dict[str, Any]) -> TrueChange:
        before = raw.get("before")
        return TrueChange(
            str(raw["change"]),
            CLASS_NAMES.index(raw["class"]),
            int(raw["instance"]),
            np.asarray(raw["points"], np.float64).reshape(-1, 2),
            bool(raw["closed"]),
            None if before is None else np.asarray(before, np.float64).reshape(-1, 2),
        )


@dataclass(frozen=True)
class ChangeCounts:
    """How many changes of each kind ``change_world`` makes (fewer where the drives offer no
    suitable place)."""

    crossing_removed: int = 1
    crossing_added: int = 1
    divider_removed: int = 2
    divider_added: int = 1
    divider_moved: int = 2
    kerb_moved: int = 1


def _visible_counts(
    world: WorldMap, poses: NDArray[np.float64], rng: PerceptionRange
) -> dict[int, int]:
    """Instance index -> frames (of poses (T, 4, 4)) in which >= 5 m of it (a crossing: half of
    its ring) lies inside the range."""
    from icmapper import geom

    lo = np.array([m.points.min(axis=0) for m in world.instances])  # (N, 2)
    hi = np.array([m.points.max(axis=0) for m in world.instances])  # (N, 2)
    reach = float(np.hypot(rng.half_x, rng.half_y))
    counts: dict[int, int] = {}
    for pose in poses:
        x, y, yaw = pose_to_xy_yaw(pose)
        c = np.array([x, y])
        near = np.nonzero(np.all(lo <= c + reach, axis=1) & np.all(hi >= c - reach, axis=1))[0]
        for k in near.tolist():
            inst = world.instances[k]
            pieces = geom.clip_to_patch(
                inst.points, (x, y, yaw), (rng.half_x, rng.half_y), closed=inst.closed
            )
            if inst.closed:
                whole = abs(geom.signed_ring_area(inst.points))
                seen = sum(abs(geom.signed_ring_area(p)) for p in pieces)
                ok = seen >= 0.5 * whole
            else:
                ok = sum(float(arc_length(p)[-1]) for p in pieces) >= 5.0
            if ok:
                counts[k] = counts.get(k, 0) + 1
    return counts


def _min_dist(a: NDArray[np.float64], others: list[NDArray[np.float64]]) -> float:
    """Smallest distance from the polyline a (n, 2) to any polyline of ``others``."""
    if not others:
        return float("inf")
    line = LineString(a)
    return min(line.distance(LineString(o) if len(o) > 1 else shapely.Point(o[0])) for o in others)


def _dense(points: NDArray[np.float64], spacing: float = 1.0) -> NDArray[np.float64]:
    length = float(arc_length(points)[-1])
    return sub_curve(points, 0.0, length, spacing)  # (m, 2)


class _Builder:
    """The world being changed, with the bookkeeping of ``change_world``."""

    def __init__(
        self,
        world: WorldMap,
        poses: NDArray[np.float64],
        rng: PerceptionRange,
        seed: int,
    ) -> None:
        self.world = world
        self.poses, self.rng = poses, rng
        self.rnd = np.random.default_rng([int(seed), 0xC4A6])
        self.visible = _visible_counts(world, poses, rng)
        self.instances = list(world.instances)
        self.drivable = list(world.drivable)
        self.changes: list[TrueChange] = []
        self.used: set[int] = set()  # world instance ids already changed
        self.next_id = max((m.id for m in world.instances), default=0) + 1

    def candidates(self, cls: MapClass, min_frames: int = 3) -> list[MapInstance]:
        """The visible, unchanged world instances of ``cls`` in a seeded random order."""
        ks = [
            k
            for k, n in sorted(self.visible.items())
            if n >= min_frames
            and self.world.instances[k].cls == cls
            and self.world.instances[k].id not in self.used
        ]
        return [self.world.instances[ks[int(i)]] for i in self.rnd.permutation(len(ks))]

    def seen_run(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """The longest stretch (k, 2) of the polyline ``points`` (densified to 1 m) whose points
        are in range of >= 3 poses; (0, 2) when none."""
        dense = _dense(points)  # (m, 2)
        seen = np.concatenate([[0], in_range_counts(dense, self.poses, self.rng) >= 3, [0]])
        edges = np.flatnonzero(np.diff(seen.astype(np.int64)))  # run starts and ends
        if len(edges) == 0:
            return np.zeros((0, 2))
        starts, stops = edges[0::2], edges[1::2]
        k = int(np.argmax(stops - starts))
        return dense[starts[k] : stops[k]]

    def spaced(self, pts: NDArray[np.float64]) -> bool:
        """Whether ``pts`` lies at least CHANGE_SPACING from every change made so far."""
        geoms = [c.points for c in self.changes] + [
            c.before for c in self.changes if c.before is not None
        ]
        return _min_dist(pts, geoms) >= CHANGE_SPACING

    def of_class(self, cls: MapClass, skip: int = -1) -> list[NDArray[np.float64]]:
        return [m.points for m in self.instances if m.cls == cls and m.id != skip]

    def record(self, change: TrueChange) -> None:
        self.changes.append(change)
        self.used.add(change.instance)

    def remove(self, cls: MapClass) -> bool:
        for inst in self.candidates(cls):
            if not self.spaced(inst.points):
                continue
            self.instances = [m for m in self.instances if m.id != inst.id]
            self.record(TrueChange("removed", int(cls), inst.id, inst.points, inst.closed))
            return True
        return False

    def beside(
        self, line: NDArray[np.float64], off: float, skip: int, divider_gap: float, kerb_gap: float
    ) -> NDArray[np.float64] | None:
        """``line`` shifted ``off`` metres to one side (sides tried in a seeded order): the first
        that keeps CHANGE_SPACING from other changes, ``divider_gap`` from the other dividers
        (``skip``: the divider's own id) and ``kerb_gap`` from the kerbs; None if neither."""
        for sign in self.rnd.permutation([-1.0, 1.0]).tolist():
            new = offset_curve(line, sign * off)  # (m, 2)
            if not self.spaced(new):
                continue
            if _min_dist(new, self.of_class(MapClass.DIVIDER, skip=skip)) < divider_gap:
                continue
            if _min_dist(new, self.of_class(MapClass.BOUNDARY)) >= kerb_gap:
                return new
        return None

    def move_divider(self) -> bool:
        for inst in self.candidates(MapClass.DIVIDER):
            d = float(self.rnd.uniform(0.5, 2.0))
            new = self.beside(_dense(inst.points), d, inst.id, d + 0.5, 0.5)
            if new is not None:
                self._replace(inst, new)
                self.record(
                    TrueChange("moved", int(MapClass.DIVIDER), inst.id, new, False, inst.points)
                )
                return True
        return False

    def add_divider(self) -> bool:
        for inst in self.candidates(MapClass.DIVIDER):
            off = float(self.rnd.uniform(1.5, 1.9))
            dense = self.seen_run(inst.points)
            length = float(arc_length(dense)[-1]) if len(dense) > 1 else 0.0
            frac = float(self.rnd.uniform(0.6, 1.0))
            s0 = float(self.rnd.uniform(0.0, 1.0 - frac)) * length
            if frac * length < 8.0:
                continue
            piece = sub_curve(dense, s0, s0 + frac * length)
            new = self.beside(piece, off, -1, 1.4, 1.0)
            if new is not None:
                self._add(MapClass.DIVIDER, new, False, inst.style)
                return True
        return False

    def add_crossing(self) -> bool:
        kerbs = MultiLineString([LineString(p) for p in self.of_class(MapClass.BOUNDARY)])
        crossings = self.of_class(MapClass.PED_CROSSING)
        for inst in self.candidates(MapClass.DIVIDER):
            dense = self.seen_run(inst.points)
            if len(dense) < 2 or float(arc_length(dense)[-1]) < 16.0:
                continue
            i = len(dense) // 2
            p, t = dense[i], tangents(dense)[i]
            n = np.array([-t[1], t[0]])
            ends = []
            for sign in (1.0, -1.0):
                hit = LineString([p, p + sign * 30.0 * n]).intersection(kerbs)
                if hit.is_empty:
                    break
                ends.append(shapely.shortest_line(shapely.Point(p), hit).coords[1])
            if len(ends) != 2:
                continue
            left, right = np.asarray(ends[0]), np.asarray(ends[1])
            ring = np.array([right - 2 * t, right + 2 * t, left + 2 * t, left - 2 * t])  # (4, 2)
            if not self.spaced(ring) or _min_dist(ring, crossings) < 10.0:
                continue
            if Polygon(ring).area < 20.0 or (in_range_counts(ring, self.poses, self.rng) < 3).any():
                continue
            self._add(MapClass.PED_CROSSING, ring, True, "zebra")
            return True
        return False

    def move_kerb(self) -> bool:
        drivable = shapely.union_all([Polygon(p).buffer(0) for p in self.drivable])
        for inst in self.candidates(MapClass.BOUNDARY):
            dense = _dense(inst.points, 0.5)  # (m, 2)
            s = arc_length(dense)  # (m,)
            span, ramp = float(self.rnd.uniform(15.0, 30.0)), 5.0
            d = float(self.rnd.uniform(2.0, 3.0))
            total = span + 2 * ramp
            if s[-1] < total + 4.0:
                continue
            seen = in_range_counts(dense, self.poses, self.rng) >= 3  # (m,)
            width = int(np.ceil(total / 0.5)) + 1  # points of a window
            cum = np.concatenate([[0], np.cumsum(~seen)])  # unseen points before each index
            starts = np.flatnonzero(cum[width:] == cum[:-width])  # windows seen throughout
            starts = starts[(s[starts] > 1.0) & (s[starts] < s[-1] - total - 1.0)]
            for j in self.rnd.permutation(starts)[:12].tolist():
                s0 = float(s[j])
                window = (s >= s0) & (s <= s0 + total)  # (m,)
                sec = dense[window]  # (w, 2)
                u = s[window] - s0  # (w,)
                w = np.clip(np.minimum(u, total - u) / ramp, 0.0, 1.0)  # (w,)
                w = w * w * (3 - 2 * w)  # smooth ramps
                t = tangents(sec)  # (w, 2)
                nrm = np.stack([-t[:, 1], t[:, 0]], axis=1)  # (w, 2) left normal
                mid = sec[len(sec) // 2]
                inside = drivable.contains(shapely.Point(mid + 0.5 * nrm[len(sec) // 2]))
                out = -1.0 if inside else 1.0  # away from the drivable area
                new_sec = sec + (out * d * w)[:, None] * nrm  # (w, 2)
                if not self.spaced(new_sec):
                    continue
                # the road widens into the sidewalk: nothing else within 5 m of the new kerb
                if _min_dist(new_sec, self.of_class(MapClass.BOUNDARY, skip=inst.id)) < 5.0:
                    continue
                rest = [dense[s < s0 - 10.0], dense[s > s0 + total + 10.0]]  # not its ramps
                if _min_dist(new_sec, [r for r in rest if len(r) > 1]) < 5.0:
                    continue
                others = self.of_class(MapClass.DIVIDER) + self.of_class(MapClass.PED_CROSSING)
                if _min_dist(new_sec, others) < 1.0:
                    continue
                new = np.concatenate([dense[s < s0], new_sec, dense[s > s0 + total]])  # (m', 2)
                self._replace(inst, new)
                strip = Polygon(np.concatenate([sec, new_sec[::-1]])).buffer(0)
                self.drivable += [np.asarray(g.exterior.coords)[:-1] for g in _polygons(strip)]
                self.record(
                    TrueChange("moved", int(MapClass.BOUNDARY), inst.id, new_sec, False, sec)
                )
                return True
        return False

    def _replace(self, inst: MapInstance, points: NDArray[np.float64]) -> None:
        self.instances = [
            replace(m, points=points) if m.id == inst.id else m for m in self.instances
        ]

    def _add(self, cls: MapClass, points: NDArray[np.float64], closed: bool, style: str) -> None:
        new = MapInstance(self.next_id, cls, points, closed, style)
        self.next_id += 1
        self.instances.append(new)
        self.record(TrueChange("added", int(cls), new.id, points, closed))


def _polygons(geom: shapely.Geometry) -> list[Polygon]:
    if isinstance(geom, Polygon):
        return [] if geom.is_empty else [geom]
    return [g for g in getattr(geom, "geoms", []) if isinstance(g, Polygon) and not g.is_empty]


def change_world(
    world: WorldMap,
    poses: NDArray[np.float64],
    seed: int,
    rng: PerceptionRange = RANGE_60x30,
    counts: ChangeCounts = ChangeCounts(),
) -> tuple[WorldMap, list[TrueChange]]:
    """The world after changes near the drives of ``poses`` (T, 4, 4), and the true changes (see
    the module docstring). Changes are placed on instances the drives see in >= 3 frames;
    everything else is kept as it is (the same objects). The world keeps its name: it is the
    same city."""
    b = _Builder(world, poses, rng, seed)
    steps = (
        [lambda: b.remove(MapClass.PED_CROSSING)] * counts.crossing_removed
        + [b.add_crossing] * counts.crossing_added
        + [lambda: b.remove(MapClass.DIVIDER)] * counts.divider_removed
        + [b.add_divider] * counts.divider_added
        + [b.move_divider] * counts.divider_moved
        + [b.move_kerb] * counts.kerb_moved
    )
    for step in steps:
        step()
    changed = WorldMap(world.name, b.instances, b.drivable, world.lanes, world.geo)
    return changed, b.changes


@lru_cache(maxsize=8)
def _changed_city(
    split: str, index: int, num: int, seed: int
) -> tuple[WorldMap, tuple[TrueChange, ...]]:
    from icmapper.data.sim.sequences import sim_city_drives

    base = sim_city_drives(split, index, num, image_size=(8, 8))
    poses = np.concatenate([s.poses for s in base])  # (sum T, 4, 4)
    world, changes = change_world(base[0].world, poses, seed)
    return world, tuple(changes)


def changed_city_drives(
    split: str,
    index: int,
    num: int,
    seed: int = 0,
    image_size: tuple[int, int] = (128, 352),
) -> tuple[list[Sequence], list[TrueChange]]:
    """The ``num`` drives of ``sim_city_drives(split, index, num)`` (the same routes, times and
    names with "-c<seed>" after the city) through the city changed by ``change_world`` with
    ``seed`` near those drives, and the true changes."""
    from icmapper.data.sim.sequences import sim_city_drives

    world, changes = _changed_city(split, index, num, int(seed))
    out = []
    for k, seq in enumerate(sim_city_drives(split, index, num, image_size, world=world)):
        seq.name = seq.name.rsplit("-", 1)[0] + f"-c{seed}-{k}"
        out.append(seq)
    return out, list(changes)


#: The changes of each repainted training drive (``sim-repainted``), in two passes (each keeps
#: its changes CHANGE_SPACING apart, so the moves and additions of the first get their places
#: before the removals): more lane lines than a city update's, so that the paint departs from
#: the lane layout in many frames.
REPAINT_COUNTS = (
    replace(ChangeCounts(*[0] * 6), divider_added=2, divider_moved=4),  # lane lines only
    ChangeCounts(divider_removed=2, divider_added=0, divider_moved=0),
)


def repainted_sequences(
    split: str,
    num: int,
    seed: int = 0,
    image_size: tuple[int, int] = (128, 352),
    counts: tuple[ChangeCounts, ...] = REPAINT_COUNTS,
) -> list[Sequence]:
    """The drives of ``sim_sequences(split, num, seed)`` (the same cities, routes and lighting),
    each through its city changed by ``change_world`` near that drive (one pass per entry of
    ``counts``; seeded by the city and the drive), named "sim-repainted-<city>-<drive>"
    (source ``sim-repainted``). For training: the lane layout stays, the paint does not follow
    it, so a detector learns the lines from the paint."""
    from icmapper.data.sim.city import generate_city
    from icmapper.data.sim.driver import drive
    from icmapper.data.sim.sequences import sim_city_seeds, sim_sequence

    out = []
    for k, city in enumerate(sim_city_seeds(split, num, seed)):
        world = generate_city(city)
        poses = drive(world, k)[1]  # (T, 4, 4) the route of sim_sequence(city, k)
        changed = world
        for p, c in enumerate(counts):
            pass_seed = (city * 4099 + k) * 7 + p
            changed, _ = change_world(changed, poses, seed=pass_seed, counts=c)
        seq = sim_sequence(city, k, image_size, world=changed)
        seq.name = f"sim-repainted-{city}-{k}"
        out.append(seq)
    return out


def spec_true_changes(spec: str) -> list[TrueChange] | None:
    """The true changes of the drives of a ``sim-city-changed:<split>:INDEX:N[:SEED]`` spec (as
    ``open_source`` reads it); None for a spec of another kind (no known changes)."""
    from icmapper.data.sources import split_options

    base, _ = split_options(spec)
    kind, _, rest = base.partition(":")
    if kind != "sim-city-changed":
        return None
    parts = rest.split(":")
    seed = int(parts[3]) if len(parts) == 4 else 0
    return list(_changed_city(parts[0], int(parts[1]), int(parts[2]), seed)[1])
