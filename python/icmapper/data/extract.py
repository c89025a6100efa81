"""Map-element extraction helpers shared by the Argoverse 2 and nuScenes readers.

Pure numpy on (n, 2) float64 polylines: quaternions to SE(3), StreamMapNet's overlap rules for
de-duplicating dividers and for removing dividers that lie on a road boundary, StreamMapNet's
end-to-end line connection, road boundaries from a polygon union (through `icmapper.geom`), pose
subsampling, and the lazy renderer used by the readers' sequences. No file I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.data.errors import DataError
from icmapper.data.types import CameraRig, WorldMap, pose_to_xy_yaw, xy_yaw_to_pose

#: StreamMapNet's buffer for its overlap rules (metres, each line buffered by this much).
OVERLAP_BUFFER = 0.3
#: StreamMapNet's overlap threshold: buffered intersection area > this * the shorter length.
OVERLAP_RATIO = 0.2
#: StreamMapNet's end-point tolerance when connecting split lines (metres).
CONNECT_EPS = 0.1


def quat_to_matrix(q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit quaternion (4,) as (w, x, y, z) -> (3, 3) rotation matrix (normalised first)."""
    q = np.asarray(q, dtype=np.float64)
    n = float(np.linalg.norm(q))
    if q.shape != (4,) or not np.isfinite(n) or n < 1e-9:
        raise ValueError(f"bad quaternion {q!r}")
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def se3(q: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quaternion (w, x, y, z) and translation (3,) -> (4, 4) SE(3) matrix."""
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(q)
    m[:3, 3] = np.asarray(t, dtype=np.float64)
    return m


def interpolate_poses(
    stamps_ns: NDArray[np.int64],
    quats: NDArray[np.float64],
    trans: NDArray[np.float64],
    query_ns: NDArray[np.int64],
    where: str = "poses",
) -> NDArray[np.float64]:
    """Poses at `query_ns` (Q,) from sorted samples (stamps_ns (N,), quats (N, 4) w x y z,
    trans (N, 3)) -> (Q, 4, 4): translation linear in time, rotation by slerp; a query equal to a
    sample gives that sample exactly. A query outside [first, last] raises DataError naming
    `where`."""
    q = np.asarray(query_ns, dtype=np.int64)
    if len(q) and (q.min() < stamps_ns[0] or q.max() > stamps_ns[-1]):
        raise DataError(
            f"{where}: timestamp {int(q.min() if q.min() < stamps_ns[0] else q.max())} ns is "
            f"outside the poses' time range [{int(stamps_ns[0])}, {int(stamps_ns[-1])}]"
        )
    j = np.clip(np.searchsorted(stamps_ns, q, side="right") - 1, 0, len(stamps_ns) - 1)  # (Q,)
    out = np.empty((len(q), 4, 4))
    for k, (t, i) in enumerate(zip(q.tolist(), j.tolist(), strict=True)):
        if stamps_ns[i] == t or i + 1 >= len(stamps_ns):
            out[k] = se3(quats[i], trans[i])
            continue
        a = (t - int(stamps_ns[i])) / float(int(stamps_ns[i + 1]) - int(stamps_ns[i]))
        q0 = quats[i] / np.linalg.norm(quats[i])
        q1 = quats[i + 1] / np.linalg.norm(quats[i + 1])
        dot = float(q0 @ q1)
        if dot < 0.0:
            q1, dot = -q1, -dot
        if dot > 0.9995:
            qi = q0 + a * (q1 - q0)
        else:
            th = np.arccos(dot)
            qi = (np.sin((1 - a) * th) * q0 + np.sin(a * th) * q1) / np.sin(th)
        out[k] = se3(qi, (1 - a) * trans[i] + a * trans[i + 1])
    return out


def planar(pose: NDArray[np.float64]) -> NDArray[np.float64]:
    """(4, 4) SE(3) -> the planar pose (x, y, yaw) as (4, 4) with z = 0, roll = pitch = 0."""
    return xy_yaw_to_pose(*pose_to_xy_yaw(pose))


def dedup_points(points: NDArray[np.float64], eps: float = 1e-6) -> NDArray[np.float64]:
    """Drops consecutive repeated points of an (n, 2) polyline."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) < 2:
        return points
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(points, axis=0), axis=1) > eps
    return points[keep]


def polyline_length(points: NDArray[np.float64]) -> float:
    """Length of an open (n, 2) polyline."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum()) if len(points) > 1 else 0.0


def overlaps(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    """StreamMapNet's rule: area(buffer(a, 0.3) ∩ buffer(b, 0.3)) > 0.2 * min(len a, len b).

    The area is approximated without a polygon library: along the shorter line (sampled every
    0.1 m) the strip shared by two 0.3 m buffers at distance d is (0.6 - d) wide.
    """
    la, lb = polyline_length(a), polyline_length(b)
    short, other = (a, b) if la <= lb else (b, a)
    lo_s, hi_s = short.min(axis=0), short.max(axis=0)
    lo_o, hi_o = other.min(axis=0), other.max(axis=0)
    pad = 2 * OVERLAP_BUFFER
    if np.any(lo_s > hi_o + pad) or np.any(lo_o > hi_s + pad):
        return False
    # Only the segments of `other` near the shorter line matter.
    seg_lo = np.minimum(other[:-1], other[1:])  # (k, 2)
    seg_hi = np.maximum(other[:-1], other[1:])  # (k, 2)
    near = np.all(seg_lo <= hi_s + pad, axis=1) & np.all(seg_hi >= lo_s - pad, axis=1)  # (k,)
    if not near.any():
        return False
    if min(la, lb) <= 0.0:
        return False
    from icmapper import geom

    dense = geom.resample_spacing(short, 0.1)  # (m, 2) about 0.1 m apart
    ds = min(la, lb) / (len(dense) - 1)  # arc length per sample
    k = np.flatnonzero(near)  # (K,)
    segs = np.stack([other[k], other[k + 1]], axis=1)[None]  # (1, K, 2, 2)
    d = geom.point_to_segments(dense[None], segs)[0, 0]  # (m,) to the nearest near segment
    area = float(np.maximum(0.0, 2 * OVERLAP_BUFFER - d).sum() * ds)
    return area > OVERLAP_RATIO * min(la, lb)


@dataclass
class Line:
    """A polyline being extracted: id, (n, 2) points, paint style."""

    id: int
    points: NDArray[np.float64]
    style: str


def remove_repeated_lines(lines: list[Line]) -> list[Line]:
    """Keeps the first of every group of overlapping lines (dividers listed by both lanes)."""
    kept: list[Line] = []
    for line in lines:
        if not any(overlaps(line.points, k.points) for k in kept):
            kept.append(line)
    return kept


def remove_boundary_dividers(
    dividers: list[Line], boundaries: list[NDArray[np.float64]]
) -> list[Line]:
    """Drops the dividers that overlap a road boundary (StreamMapNet's rule)."""
    return [d for d in dividers if not any(overlaps(d.points, b) for b in boundaries)]


def connect_lines(lines: list[Line]) -> list[Line]:
    """Joins lines whose end points meet (within 0.1 m), as StreamMapNet's `connect_lines` does.

    A joined line keeps the smallest member id and the style of its longest member.
    """
    pending = [(ln, polyline_length(ln.points)) for ln in lines]
    out: list[Line] = []
    while pending:
        cur, cur_len = pending.pop(0)
        best_style = (cur_len, cur.style)
        merged = True
        while merged:
            merged = False
            for i, (other, other_len) in enumerate(pending):
                p, q = cur.points, other.points
                if np.linalg.norm(p[-1] - q[0]) < CONNECT_EPS:
                    pts = np.vstack([p, q[1:]])
                elif np.linalg.norm(p[-1] - q[-1]) < CONNECT_EPS:
                    pts = np.vstack([p, q[-2::-1]])
                elif np.linalg.norm(p[0] - q[-1]) < CONNECT_EPS:
                    pts = np.vstack([q, p[1:]])
                elif np.linalg.norm(p[0] - q[0]) < CONNECT_EPS:
                    pts = np.vstack([q[::-1], p[1:]])
                else:
                    continue
                best_style = max(best_style, (other_len, other.style))
                cur = Line(min(cur.id, other.id), pts, best_style[1])
                pending.pop(i)
                merged = True
                break
        out.append(cur)
    return out


#: Holes of a drivable-area union smaller than this (m^2) are slivers between polygons that do
#: not quite abut, not islands: they give no boundary.
MIN_HOLE_AREA = 1.0


def union_contours(polygons: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """Contours of the union of polygons, each as an OPEN polyline that closes on itself
    ((m + 1, 2): first point repeated at the end): the outer rings (largest area first), then
    the holes of the union (islands fully enclosed by the union: medians, blocks; largest first,
    slivers below `MIN_HOLE_AREA` dropped), as StreamMapNet takes exteriors and interiors.

    Outer rings come from `icmapper.geom.polygon_union` (the engine); holes from shapely's union,
    since the engine's union returns outer rings only.
    """
    from icmapper import geom

    rings = [p for p in (dedup_points(p) for p in polygons) if len(p) >= 3]
    if not rings:
        return []
    out = []
    for ring in geom.polygon_union(rings):
        ring = np.asarray(ring, dtype=np.float64)
        if len(ring) >= 3:
            out.append(np.vstack([ring, ring[:1]]))
    return out + union_holes(rings)


def union_holes(rings: list[NDArray[np.float64]]) -> list[NDArray[np.float64]]:
    """The holes of the union of (n, 2) rings as closed (m + 1, 2) polylines, largest first."""
    import shapely

    polys = [shapely.make_valid(shapely.Polygon(r)) for r in rings]
    union = shapely.union_all(polys)
    holes = []
    for g in shapely.get_parts(union):
        if not isinstance(g, shapely.Polygon):
            continue
        for interior in g.interiors:
            hole = shapely.Polygon(interior)
            if hole.area >= MIN_HOLE_AREA:
                pts = dedup_points(np.asarray(interior.coords, dtype=np.float64)[:-1])
                if len(pts) >= 3:
                    holes.append((hole.area, np.vstack([pts, pts[:1]])))
    holes.sort(key=lambda h: -h[0])
    return [h for _, h in holes]


def subsample_indices(timestamps: NDArray[np.float64], hz: float) -> NDArray[np.int64]:
    """Indices of the samples nearest to t0, t0 + 1/hz, ... (sorted, unique) for (n,) seconds."""
    if hz <= 0 or not np.isfinite(hz):
        raise ValueError(f"hz must be positive, got {hz}")
    t = np.asarray(timestamps, dtype=np.float64)
    targets = np.arange(t[0], t[-1] + 1e-9, 1.0 / hz)  # (k,) never past the last pose
    idx = np.clip(np.searchsorted(t, targets), 1, len(t) - 1)
    left_closer = (targets - t[idx - 1]) <= (t[idx] - targets)
    idx = np.where(left_closer, idx - 1, idx)
    if len(t) == 1:
        idx = np.zeros(1, dtype=np.int64)
    return np.unique(idx).astype(np.int64)


class LazyRenderer:
    """Callable `render(i) -> (C, 3, H, W) uint8` for a sequence: builds `sim.Renderer` on first
    use (so that sequences are cheap to create and picklable for DataLoader workers) and renders
    frame i at its planar pose."""

    def __init__(self, world: WorldMap, rig: CameraRig, poses: NDArray[np.float64], seed: int):
        self.world = world
        self.rig = rig
        self.poses = poses
        self.seed = int(seed)
        self._renderer = None

    def __call__(self, i: int) -> NDArray[np.uint8]:
        if self._renderer is None:
            from icmapper.data import sim

            self._renderer = sim.Renderer(self.world, self.rig, self.seed)
        return self._renderer.render(self.poses[i])

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_renderer"] = None
        return state
