"""Ground truth: per-frame GT in the ego frame, GT ids stable over a sequence, the point orders
of a GT instance, and the global GT map of a sequence.

Per frame (`frame_gt`): every world instance is clipped to the perception range around the ego
pose (`icmapper.geom.clip_to_patch` in the world frame), each clipped piece becomes one GT instance
resampled to 20 points evenly by arc length (crossings along their closed contour), in the ego
frame.

GT ids (`PieceIds`): a world instance clipped into several pieces yields several GT instances.
Piece ids are `world_id * 1000 + c` where c counts the distinct pieces of that world instance
seen so far in the sequence (0 for the first). Pieces of the same world instance are linked from
frame to frame by Hungarian assignment on the Chamfer distance of their world-frame points with a
gate (`PIECE_GATE` m); a piece that matches no earlier piece of its instance gets the next c.
Sources without instance identity (nuScenes) use `derive_ids_by_matching` instead (DESIGN.md).

Global GT (`global_gt`): each world instance clipped to the union of the patches the ego visited.
Polylines: the arc-length intervals of the pieces clipped to each visited patch are unioned along
the instance and cut out of it (exact, no polygon union of patches); crossings: the union
(`geom.polygon_union`) of the crossing clipped to each visited patch. A world instance that falls
into k disjoint parts gives k global instances with ids `world_id * 1000 + j`, j in order along it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from icmapper.data.types import (
    NUM_INSTANCE_POINTS,
    FrameGT,
    MapInstance,
    PerceptionRange,
    Sequence,
    WorldMap,
    ego_to_world,
    pose_to_xy_yaw,
    world_to_ego,
)

#: Pieces per world instance encoded in a GT id: id = world_id * PIECE_FACTOR + piece counter.
PIECE_FACTOR = 1000
#: Gate (m, Chamfer) to link pieces of the same world instance between frames.
PIECE_GATE = 10.0
#: Default gate (m, Chamfer) when deriving ids without identity (nuScenes).
MATCH_GATE = 3.0
#: Pieces shorter than this (m) or crossings smaller than MIN_AREA (m^2) are dropped.
MIN_LENGTH = 1e-3
MIN_AREA = 1e-3


def _length(points: NDArray[np.float64], closed: bool) -> float:
    d = np.diff(points, axis=0)
    total = float(np.linalg.norm(d, axis=1).sum())
    if closed and len(points) > 1:
        total += float(np.linalg.norm(points[-1] - points[0]))
    return total


def _area(ring: NDArray[np.float64]) -> float:
    from icmapper import geom

    return abs(geom.signed_ring_area(ring))


@dataclass
class _Piece:
    world_id: int
    cls: int
    world_pts: NDArray[np.float64]  # (n, 2) the clipped piece, world frame
    points: NDArray[np.float64]  # (20, 2) resampled, world frame


class _WorldBoxes:
    """Axis-aligned bounding boxes of the world instances, for a quick patch pre-filter."""

    def __init__(self, world: WorldMap):
        self.lo = np.array([i.points.min(axis=0) for i in world.instances]).reshape(-1, 2)
        self.hi = np.array([i.points.max(axis=0) for i in world.instances]).reshape(-1, 2)

    def near(self, x: float, y: float, radius: float) -> NDArray[np.int64]:
        c = np.array([x, y])
        ok = np.all(self.lo <= c + radius, axis=1) & np.all(self.hi >= c - radius, axis=1)
        return np.nonzero(ok)[0]


_BOX_CACHE: dict[int, tuple[WorldMap, _WorldBoxes]] = {}


def _boxes(world: WorldMap) -> _WorldBoxes:
    hit = _BOX_CACHE.get(id(world))
    if hit is not None and hit[0] is world and len(hit[1].lo) == len(world.instances):
        return hit[1]
    boxes = _WorldBoxes(world)
    if len(_BOX_CACHE) > 64:
        _BOX_CACHE.clear()
    _BOX_CACHE[id(world)] = (world, boxes)
    return boxes


def _is_loop(points: NDArray[np.float64]) -> bool:
    return len(points) > 3 and bool(np.allclose(points[0], points[-1], atol=1e-9))


def clip_pieces(
    instance: MapInstance, pose_xy_yaw: tuple[float, float, float], rng: PerceptionRange
) -> list[NDArray[np.float64]]:
    """The pieces (each (m, 2) world frame) of one world instance inside the oriented range
    around the pose; degenerate pieces (zero length / area) dropped."""
    from icmapper import geom

    pieces = geom.clip_to_patch(
        instance.points, pose_xy_yaw, (rng.half_x, rng.half_y), closed=instance.closed
    )
    pieces = [np.asarray(p, dtype=np.float64) for p in pieces]
    if not instance.closed and _is_loop(instance.points) and len(pieces) > 1:
        # An open polyline that closes on itself (a boundary contour): the clipper sees its seam
        # as two ends, so re-join the piece that ends at the seam with the one that starts there.
        seam = instance.points[0]
        ends = [k for k, p in enumerate(pieces) if np.allclose(p[-1], seam, atol=1e-9)]
        starts = [k for k, p in enumerate(pieces) if np.allclose(p[0], seam, atol=1e-9)]
        if ends and starts and ends[-1] != starts[0]:
            joined = np.vstack([pieces[ends[-1]], pieces[starts[0]][1:]])
            pieces = [joined] + [p for k, p in enumerate(pieces) if k not in (ends[-1], starts[0])]
    out = []
    for p in pieces:
        if instance.closed:
            if len(p) >= 3 and _area(p) > MIN_AREA:
                out.append(p)
        elif len(p) >= 2 and _length(p, False) > MIN_LENGTH:
            out.append(p)
    return out


def _frame_pieces(world: WorldMap, pose: NDArray[np.float64], rng: PerceptionRange) -> list[_Piece]:
    from icmapper import geom

    x, y, yaw = pose_to_xy_yaw(pose)
    radius = float(np.hypot(rng.half_x, rng.half_y))
    out = []
    for k in _boxes(world).near(x, y, radius):
        inst = world.instances[int(k)]
        for p in clip_pieces(inst, (x, y, yaw), rng):
            pts = np.asarray(geom.resample(p, NUM_INSTANCE_POINTS, closed=inst.closed))
            out.append(_Piece(inst.id, int(inst.cls), p, pts))
    return out


@dataclass
class PieceIds:
    """Stateful assignment of stable GT ids to the pieces of world instances over a sequence
    (see the module docstring). One object per sequence, fed frames in order."""

    gate: float = PIECE_GATE
    _last: dict[int, list[tuple[int, NDArray[np.float64]]]] = field(default_factory=dict)
    _count: dict[int, int] = field(default_factory=dict)

    def assign(self, pieces: list[_Piece]) -> list[int]:
        """GT ids of the pieces of one frame (in the given order)."""
        from icmapper import geom

        ids = [0] * len(pieces)
        by_world: dict[int, list[int]] = {}
        for k, p in enumerate(pieces):
            by_world.setdefault(p.world_id, []).append(k)
        for wid, members in by_world.items():
            prev = self._last.get(wid, [])
            taken: dict[int, int] = {}
            if prev:
                cost = geom.chamfer_matrix(
                    [pieces[m].points for m in members], [q for _, q in prev]
                )  # (members, prev)
                rows, cols = linear_sum_assignment(cost)
                for r, c in zip(rows, cols, strict=True):
                    if cost[r, c] <= self.gate:
                        taken[r] = prev[c][0]
            for r, m in enumerate(members):
                if r in taken:
                    ids[m] = taken[r]
                else:
                    c = self._count.get(wid, 0)
                    if c >= PIECE_FACTOR:
                        raise ValueError(
                            f"world instance {wid} split into more than {PIECE_FACTOR} pieces"
                        )
                    self._count[wid] = c + 1
                    ids[m] = wid * PIECE_FACTOR + c
            # Remember the pieces seen now; pieces of this instance not seen now are kept too,
            # so a piece that re-enters the range later keeps its id.
            now = {ids[m]: pieces[m].points for m in members}
            self._last[wid] = list(now.items()) + [(i, q) for i, q in prev if i not in now]
        return ids


def _to_frame_gt(pieces: list[_Piece], ids: list[int], pose: NDArray[np.float64]) -> FrameGT:
    k = len(pieces)
    pts = np.zeros((k, NUM_INSTANCE_POINTS, 2), dtype=np.float32)
    for j, p in enumerate(pieces):
        pts[j] = world_to_ego(p.points, pose)
    return FrameGT(
        ids=np.asarray(ids, dtype=np.int64).reshape(k),
        classes=np.asarray([p.cls for p in pieces], dtype=np.int64).reshape(k),
        points=pts,
    )


def frame_gt(
    world: WorldMap,
    pose: NDArray[np.float64],
    rng: PerceptionRange,
    pieces_ids: PieceIds | None = None,
) -> FrameGT:
    """GT of one frame: world instances clipped to `rng` around `pose` ((4, 4) ego->world).

    Returns FrameGT with ids (k,), classes (k,), points (k, 20, 2) float32 ego frame. With
    `pieces_ids` (one `PieceIds` per sequence, frames fed in order) the ids are stable across
    frames; without it, piece j (in clipping order) of world instance w gets w * 1000 + j.
    """
    pieces = _frame_pieces(world, pose, rng)
    if pieces_ids is not None:
        ids = pieces_ids.assign(pieces)
    else:
        seen: dict[int, int] = {}
        ids = []
        for p in pieces:
            c = seen.get(p.world_id, 0)
            seen[p.world_id] = c + 1
            ids.append(p.world_id * PIECE_FACTOR + c)
    return _to_frame_gt(pieces, ids, pose)


def sequence_gt(seq: Sequence, rng: PerceptionRange) -> list[FrameGT]:
    """Per-frame GT of a whole sequence, ids stable over the sequence. Sources with identity
    (sim, av2) link pieces of world instances (`PieceIds`); sources without identity
    (``seq.gt_ids_by_matching``: nuScenes) derive ids by matching."""
    if seq.gt_ids_by_matching:
        frames = [frame_gt(seq.world, p, rng) for p in seq.poses]
        return derive_ids_by_matching(frames, seq.poses)
    tracker = PieceIds()
    return [frame_gt(seq.world, p, rng, tracker) for p in seq.poses]


def derive_ids_by_matching(
    frames_gt: list[FrameGT], poses: NDArray[np.float64], gate: float = MATCH_GATE
) -> list[FrameGT]:
    """Ids for GT without identity (the paper's rule for nuScenes): per class, the previous
    frame's GT warped into the current ego frame is matched to the current GT by Hungarian
    assignment on the Chamfer distance; pairs above `gate` (m) are not matched; unmatched current
    instances get new ids 0, 1, 2, ... in order of appearance. Returns new FrameGTs (same
    classes and points); `poses` (T, 4, 4) ego->world."""
    from icmapper import geom

    poses = np.asarray(poses, dtype=np.float64)
    if len(frames_gt) != len(poses):
        raise ValueError(f"{len(frames_gt)} frames of GT but {len(poses)} poses")
    out: list[FrameGT] = []
    next_id = 0
    prev: FrameGT | None = None
    for t, cur in enumerate(frames_gt):
        ids = np.full(len(cur), -1, dtype=np.int64)
        if prev is not None and len(prev) and len(cur):
            for c in np.unique(cur.classes):
                ci = np.nonzero(cur.classes == c)[0]
                pi = np.nonzero(prev.classes == c)[0]
                if len(pi) == 0:
                    continue
                warped = [
                    world_to_ego(ego_to_world(prev.points[j], poses[t - 1]), poses[t]) for j in pi
                ]
                cost = geom.chamfer_matrix(cur.points[ci], warped)  # (ci, pi)
                rows, cols = linear_sum_assignment(cost)
                for r, col in zip(rows, cols, strict=True):
                    if cost[r, col] <= gate:
                        ids[ci[r]] = prev.ids[pi[col]]
        for i in range(len(cur)):
            if ids[i] < 0:
                ids[i] = next_id
                next_id += 1
        gt = FrameGT(ids=ids, classes=cur.classes.copy(), points=cur.points.copy())
        out.append(gt)
        prev = gt
    return out


def point_orders(points: NDArray[np.floating], closed: bool) -> NDArray[np.floating]:
    """Equivalent point orders of one GT instance (n, 2) -> (n_orders, n, 2), same dtype.

    Open polyline: 2 orders (as given, reversed). Closed contour: every cyclic shift in both
    directions (2 n orders; order 0 is the input, orders n.. start from the reversed contour).
    """
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
        raise ValueError(f"points must have shape (n >= 2, 2), got {points.shape}")
    if not closed:
        return np.stack([points, points[::-1]])  # (2, n, 2)
    n = len(points)
    rev = points[::-1]
    fwd = [np.roll(points, -s, axis=0) for s in range(n)]
    bwd = [np.roll(rev, -s, axis=0) for s in range(n)]
    return np.stack(fwd + bwd)  # (2n, n, 2)


def _arc_start(line: NDArray[np.float64], point: NDArray[np.float64]) -> float:
    """Arc length along `line` of its point nearest to `point` (smallest arc length on ties)."""
    from icmapper import geom

    return float(geom.project_onto_polyline(point[None], line, tie_tol=1e-6)[1][0])


def _cut(line: NDArray[np.float64], s0: float, s1: float) -> NDArray[np.float64]:
    """The part of `line` between arc lengths s0 < s1 (interpolated ends, inner vertices kept)."""
    from icmapper import geom

    cum = geom.arc_lengths(line)  # (n,)
    inner = (cum > s0) & (cum < s1)
    start, stop = geom.points_at_lengths(line, [s0, s1])  # (2,), (2,)
    return np.vstack([start, line[inner], stop])


def _polyline_parts(
    line: NDArray[np.float64], pieces: list[NDArray[np.float64]], join_gap: float = 0.0
) -> list[NDArray[np.float64]]:
    """The union of `pieces` (sub-polylines of `line`) as disjoint sub-polylines, in order;
    pieces less than `join_gap` metres apart along `line` count as one (the gap included).

    Works on arc-length intervals; for a loop (first point == last) intervals may run past the
    seam and are unrolled on the doubled line.
    """
    total = _length(line, False)
    loop = _is_loop(line)
    intervals = sorted((s, s + _length(p, False)) for p in pieces for s in [_arc_start(line, p[0])])
    merged: list[list[float]] = []
    for s0, s1 in intervals:
        if merged and s0 <= merged[-1][1] + max(join_gap, 1e-6):
            merged[-1][1] = max(merged[-1][1], s1)
        else:
            merged.append([s0, s1])
    if loop and merged:
        if merged[-1][1] - merged[0][0] >= total - 1e-6 and len(merged) == 1:
            return [line]
        # An interval running past the seam continues at the start: absorb the ones it covers.
        while len(merged) > 1 and merged[-1][1] >= total + merged[0][0] - 1e-6:
            first = merged.pop(0)
            merged[-1][1] = max(merged[-1][1], first[1] + total)
        if merged[-1][1] - merged[0][0] >= total - 1e-6 and len(merged) == 1:
            return [line]
        line = np.vstack([line, line[1:]])
    return [_cut(line, s0, s1) for s0, s1 in merged if s1 - s0 > MIN_LENGTH]


def global_gt(seq: Sequence, rng: PerceptionRange, join_gap: float = 0.0) -> list[MapInstance]:
    """World instances clipped to the union of the patches (`rng` around every pose) the ego
    visited -> global GT instances in the world frame (see the module docstring for ids).
    `join_gap` (metres, 0: the protocol) joins the visited pieces of a line less than that apart
    along it: a what-if of the diagnosis (`scripts/map_experiment.py --gt-join-gap`), since a
    line at the edge of the range enters and leaves the visited patches as the car's heading
    wavers and is kept as a dashed line (docs/mapping.md, "What bounds GAP now")."""
    return visited_gt(seq.world, seq.poses, rng, join_gap)


def city_gt(seqs: list[Sequence], rng: PerceptionRange) -> list[MapInstance]:
    """The ground truth of a city map built from several drives through one world: the world
    instances clipped to the union of every patch visited by any drive (GlobalMapNet's
    cross-scene protocol). ValueError when the drives do not share one world."""
    if not seqs:
        raise ValueError("city_gt: no drives")
    names = {s.world.name for s in seqs}
    if len(names) != 1:
        raise ValueError(f"the drives of a city must share one world map, got {sorted(names)}")
    poses = np.concatenate([np.asarray(s.poses, np.float64) for s in seqs])  # (sum T, 4, 4)
    return visited_gt(seqs[0].world, poses, rng)


def visited_gt(
    world: WorldMap, poses: NDArray[np.float64], rng: PerceptionRange, join_gap: float = 0.0
) -> list[MapInstance]:
    """World instances clipped to the union of the patches (`rng` around every pose (T, 4, 4));
    `join_gap`: see `global_gt`."""
    if not join_gap >= 0:
        raise ValueError(f"visited_gt: join_gap must be >= 0, got {join_gap}")
    from icmapper import geom

    xyy = [pose_to_xy_yaw(p) for p in poses]
    radius = float(np.hypot(rng.half_x, rng.half_y))
    boxes = _boxes(world)
    near: dict[int, list[int]] = {}
    for f, (x, y, _) in enumerate(xyy):
        for k in boxes.near(x, y, radius):
            near.setdefault(int(k), []).append(f)
    out: list[MapInstance] = []
    for k in sorted(near):
        inst = world.instances[k]
        pieces = [p for f in near[k] for p in clip_pieces(inst, xyy[f], rng)]
        if not pieces:
            continue
        if inst.closed:
            parts = [np.asarray(r, dtype=np.float64) for r in geom.polygon_union(pieces)]
            parts = [r for r in parts if len(r) >= 3 and _area(r) > MIN_AREA]
        else:
            parts = _polyline_parts(inst.points, pieces, join_gap)
        for j, part in enumerate(parts):
            out.append(
                MapInstance(inst.id * PIECE_FACTOR + j, inst.cls, part, inst.closed, inst.style)
            )
    return out


def in_range_counts(
    points: NDArray[np.float64],
    poses: NDArray[np.float64],
    rng: PerceptionRange,
    margin: float = 0.0,
) -> NDArray[np.int64]:
    """Per point of ``points`` (m, 2) world frame: how many of ``poses`` (T, 4, 4) hold it in
    their range shrunk by ``margin`` metres (negative: grown)."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    if len(poses) == 0 or len(pts) == 0:
        return np.zeros(len(pts), np.int64)
    rel = pts[None, :, :] - poses[:, None, :2, 3]  # (T, m, 2)
    ego = np.einsum("tmk,tkj->tmj", rel, poses[:, :2, :2])  # (T, m, 2): R^T (p - t)
    hx, hy = rng.half_x - margin, rng.half_y - margin
    inside = (np.abs(ego[..., 0]) <= hx) & (np.abs(ego[..., 1]) <= hy)  # (T, m)
    return inside.sum(axis=0)
