"""Procedural synthetic cities: a seeded road network with map instances, drivable area and lanes.

`generate_city(seed)` builds a jittered grid of junction nodes (about 400 m x 400 m), removes a few
edges (giving 3-way junctions and corners), and turns every edge into a straight or curved
(quadratic Bezier) street with 1-4 lanes per direction, its own lane width, a centre divider
(dashed / solid / double yellow) or a raised median, dashed or solid white lane dividers, zebra
crossings next to junctions and sometimes mid-block. Junctions get rounded kerbs (morphological
closing of the meeting street bodies); dividers stop before the junction and its crossings.
Road boundaries are the rings of the union of the drivable pieces (outer kerbs, block kerbs,
medians). Lanes (centrelines + successors, turning lanes through junctions) let an ego drive.

With ``varied=True`` (domain randomisation towards real road geometry, for training) streets also
draw, from a separate random stream so that the plain cities of a seed stay as they are: lane
widths up to 5.5 m, a paved shoulder (0.5-3 m of asphalt between the outer lane and the kerb,
as on roads with parking or bike lanes), and streets whose lanes of one direction are not marked
(no lane dividers, only the centre line). Real logs (Argoverse 2) have all three; the plain
generator has none, and a detector trained on it draws a divider every 3-4 m and pulls the kerbs
in towards them. With ``junctions=True`` (the varied city, from one more stream) the crossings of
a junction sit at its edge instead of beyond its kerb corners, 3-6 m deep, half of them skewed up
to 0.4 x the street width: they touch at the junction's corners and ring it, as Argoverse 2's do.

This module only builds geometry; it holds no I/O and no rendering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import LineString, Point, Polygon
from shapely.ops import split, unary_union

from icmapper.data.sim.geometry import (
    arc_length,
    cubic_bezier,
    offset_curve,
    quadratic_bezier,
    resample_by_length,
    sub_curve,
    tangents,
)
from icmapper.data.types import LaneSegment, MapClass, MapInstance, WorldMap

#: Cities are split by seed so that train / val / test never share geography.
CITY_SEEDS: dict[str, range] = {
    "train": range(0, 10_000),
    "val": range(10_000, 10_100),
    "test": range(10_100, 10_200),
}

_GRID = 4  # nodes per side of the junction grid


@dataclass
class _Street:
    """One street between junction nodes a and b, with its centre curve (n, 2) from a to b."""

    a: int
    b: int
    curve: NDArray[np.float64]
    n_fwd: int  # lanes a -> b (on the right of the a -> b direction)
    n_bwd: int  # lanes b -> a
    width: float  # lane width (m)
    median: float  # raised median width (m), 0 when none
    centre_style: str  # style of the centre divider when there is no median
    lane_style: str  # style of the dividers between lanes of one direction
    shoulder: float = 0.0  # paved shoulder (m) between the outer lanes and the kerbs
    marked: bool = True  # lane dividers between lanes of one direction

    @property
    def length(self) -> float:
        return float(arc_length(self.curve)[-1])

    @property
    def hw_right(self) -> float:
        return self.median / 2 + self.n_fwd * self.width + self.shoulder

    @property
    def hw_left(self) -> float:
        return self.median / 2 + self.n_bwd * self.width + self.shoulder

    def direction_at(self, node: int) -> NDArray[np.float64]:
        """Unit vector (2,) pointing from `node` (a or b) into the street."""
        t = tangents(self.curve)
        return t[0] if node == self.a else -t[-1]

    def at(self, s: float, offset: float) -> NDArray[np.float64]:
        """Point (2,) at arc length s from a, shifted left (of a -> b) by offset."""
        cs = arc_length(self.curve)
        p = resample_by_length(self.curve, np.array([s]))[0]
        i = int(np.clip(np.searchsorted(cs, s), 1, len(cs) - 1))
        t = self.curve[i] - self.curve[i - 1]
        t = t / max(np.linalg.norm(t), 1e-12)
        return p + offset * np.array([-t[1], t[0]])

    def body(self) -> Polygon:
        """The full street carriageway from node a to node b (no median cut)."""
        right = offset_curve(self.curve, -self.hw_right)
        left = offset_curve(self.curve, self.hw_left)
        return Polygon(np.concatenate([right, left[::-1]]))


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"city seed must be an int, got {type(seed).__name__}")
    if seed < 0:
        raise ValueError(f"city seed must be >= 0, got {seed}")
    return int(seed)


def _grid_graph(rng: np.random.Generator) -> tuple[NDArray[np.float64], list[tuple[int, int]]]:
    """Jittered grid nodes (N, 2) and undirected edges, some removed (every node keeps degree >= 2
    and the graph stays connected)."""
    spacing = rng.uniform(105.0, 135.0)
    ij = np.array([(i, j) for j in range(_GRID) for i in range(_GRID)], dtype=np.float64)  # (N, 2)
    nodes = ij * spacing + rng.uniform(-12.0, 12.0, size=ij.shape)  # (N, 2)
    edges = []
    for j in range(_GRID):
        for i in range(_GRID):
            n = j * _GRID + i
            if i + 1 < _GRID:
                edges.append((n, n + 1))
            if j + 1 < _GRID:
                edges.append((n, n + _GRID))
    n_remove = int(rng.integers(1, 5))
    for cand in [edges[int(e)] for e in rng.permutation(len(edges))]:
        if n_remove == 0:
            break
        rest = [x for x in edges if x != cand]
        deg = np.bincount(np.array(rest).ravel(), minlength=len(nodes))
        if deg.min() < 2 or not _connected(len(nodes), rest):
            continue
        edges = rest
        n_remove -= 1
    return nodes, edges


def _connected(n: int, edges: list[tuple[int, int]]) -> bool:
    adj: dict[int, list[int]] = {i: [] for i in range(n)}
    for a, b in edges:
        adj[a].append(b)
        adj[b].append(a)
    seen, stack = {0}, [0]
    while stack:
        for m in adj[stack.pop()]:
            if m not in seen:
                seen.add(m)
                stack.append(m)
    return len(seen) == n


def _make_street(rng: np.random.Generator, a: int, b: int, nodes: NDArray) -> _Street:
    p0, p2 = nodes[a], nodes[b]
    d = p2 - p0
    length = float(np.linalg.norm(d))
    normal = np.array([-d[1], d[0]]) / length
    bend = rng.uniform(-0.16, 0.16) * length if rng.random() < 0.55 else 0.0
    p1 = (p0 + p2) / 2 + bend * normal
    curve = quadratic_bezier(p0, p1, p2, max(8, int(length / 1.0)))
    lanes = rng.choice([1, 1, 1, 2, 2, 2, 3, 4])
    n_fwd = int(lanes)
    n_bwd = int(np.clip(lanes + rng.choice([-1, 0, 0, 0, 1]), 1, 4))
    width = float(rng.uniform(2.9, 3.8))
    median = float(rng.uniform(1.5, 4.0)) if n_fwd + n_bwd >= 4 and rng.random() < 0.5 else 0.0
    if n_fwd + n_bwd == 2:
        centre = str(rng.choice(["dashed_yellow", "solid_yellow", "double_yellow", "dashed_white"]))
    else:
        centre = str(rng.choice(["double_yellow", "double_yellow", "solid_yellow"]))
    lane_style = "dashed_white" if rng.random() < 0.85 else "solid_white"
    return _Street(a, b, curve, n_fwd, n_bwd, width, median, centre, lane_style)


def _vary_street(st: _Street, rng: np.random.Generator) -> _Street:
    """``st`` with the real-road variety of ``generate_city(varied=True)`` (module docstring)."""
    from dataclasses import replace

    width = float(rng.uniform(2.9, 5.5)) if rng.random() < 0.6 else st.width
    shoulder = float(rng.uniform(0.5, 3.0)) if rng.random() < 0.5 else 0.0
    return replace(st, width=width, shoulder=shoulder, marked=bool(rng.random() >= 0.35))


def _dashed(style: str) -> bool:
    return style.startswith("dashed")


def generate_city(seed: int, varied: bool = False, junctions: bool = False) -> WorldMap:
    """Builds the synthetic city of `seed` (same seed, same city; ``varied``: with the real-road
    variety of the module docstring, named "sim-varied-city-<seed>"; ``junctions``: the varied city
    with its junction crossings at the junction's edge, named "sim-junction-city-<seed>").

    Returns a WorldMap named "sim-city-<seed>" with map instances (ids 1..N, unique and stable for
    the seed; dividers, crossings, then boundaries), drivable pieces (simple polygons (n, 2) whose
    union is the drivable area) and a lane graph (centrelines (n, 2) with successors, including
    turning lanes through junctions). Every lane has at least one successor.
    """
    seed = _check_seed(seed)
    rng = np.random.default_rng([seed, 0x5C17])
    nodes, edges = _grid_graph(rng)
    streets = [_make_street(rng, a, b, nodes) for a, b in edges]
    varied = varied or junctions
    if varied:
        vary = np.random.default_rng([seed, 0xD1CE])  # own stream: plain cities stay unchanged
        streets = [_vary_street(st, vary) for st in streets]
    # own stream too: a junction city is its varied city with crossings moved
    ring = np.random.default_rng([seed, 0x2196]) if junctions else None
    corner_r = float(rng.uniform(4.0, 9.0))  # kerb radius at junction corners

    # Junction radius per node: far enough along each arm that the arms no longer touch.
    arms: dict[int, list[int]] = {i: [] for i in range(len(nodes))}
    for k, st in enumerate(streets):
        arms[st.a].append(k)
        arms[st.b].append(k)
    radius = np.zeros(len(nodes))
    for n, ks in arms.items():
        dirs = np.array([streets[k].direction_at(n) for k in ks])  # (d, 2)
        ang = np.sort(np.arctan2(dirs[:, 1], dirs[:, 0]))
        gaps = np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]]))
        theta = float(np.clip(gaps.min(), np.deg2rad(40), np.pi))
        hw = max(max(streets[k].hw_left, streets[k].hw_right) for k in ks)
        radius[n] = hw / np.tan(theta / 2) + corner_r + 1.5

    instances: list[MapInstance] = []
    islands: list[Polygon] = []
    pieces: list[Polygon] = []

    def add(cls: MapClass, pts: NDArray, style: str, closed: bool = False) -> None:
        instances.append(
            MapInstance(len(instances) + 1, cls, np.asarray(pts, np.float64), closed, style)
        )

    crossings: list[NDArray[np.float64]] = []
    for st in streets:
        length = st.length
        ra, rb = radius[st.a], radius[st.b]
        s_a, s_b = ra + 0.5, length - rb - 0.5
        gaps: list[tuple[float, float]] = []  # arc-length spans with no divider paint
        for end, r_end in ((0, ra), (1, rb)):
            node = st.a if end == 0 else st.b
            if len(arms[node]) >= 3 or rng.random() < 0.3:
                if rng.random() < 0.75:
                    depth = float(rng.uniform(3.0, 5.0))
                    at, skew = r_end + 0.5, 0.0  # distance from the node, skew (m)
                    if ring is not None and len(arms[node]) >= 3:  # at the junction's edge
                        depth = float(ring.uniform(3.0, 6.0))
                        at = r_end - corner_r - 1.5 + float(ring.uniform(0.0, 1.0))
                        if ring.random() < 0.5:
                            skew = float(ring.uniform(-0.4, 0.4)) * (st.hw_left + st.hw_right)
                    c0 = at if end == 0 else length - at - depth
                    crossings.append(_crossing_ring(st, c0, c0 + depth, skew))
                    if end == 0:
                        s_a = c0 + depth + abs(skew) + 1.0
                    else:
                        s_b = c0 - abs(skew) - 1.0
        if st.median == 0.0 and s_b - s_a > 50.0 and rng.random() < 0.35:
            depth = float(rng.uniform(3.0, 5.0))
            c0 = float(rng.uniform(s_a + 15.0, s_b - 15.0 - depth))
            crossings.append(_crossing_ring(st, c0, c0 + depth))
            gaps.append((c0 - 1.0, c0 + depth + 1.0))
        spans = _spans(s_a, s_b, gaps)
        # Centre divider (or median island) and lane dividers, stopped before junctions/crossings.
        if st.median > 0.0:
            centre = LineString(sub_curve(st.curve, s_a + 1.0, s_b - 1.0))
            islands.append(centre.buffer(st.median / 2, quad_segs=6))
        else:
            for s0, s1 in spans:
                add(MapClass.DIVIDER, sub_curve(st.curve, s0, s1), st.centre_style)
        for side, n_lanes in ((-1.0, st.n_fwd), (1.0, st.n_bwd)):
            for k in range(1, n_lanes if st.marked else 1):
                off = side * (st.median / 2 + k * st.width)
                for s0, s1 in spans:
                    add(
                        MapClass.DIVIDER,
                        offset_curve(sub_curve(st.curve, s0, s1, 1.0), off),
                        st.lane_style,
                    )
        # Drivable pieces of the street body (split in two where a median cuts a hole).
        body = st.body()
        if st.median > 0.0:
            cut = islands[-1]
            mid = st.at(length / 2, 0.0)
            t = st.at(length / 2 + 1.0, 0.0) - mid
            t /= np.linalg.norm(t)
            nrm = np.array([-t[1], t[0]]) * (st.hw_left + st.hw_right + 5.0)
            pieces.extend(
                _polygons(split(body.difference(cut), LineString([mid - nrm, mid + nrm])))
            )
        else:
            pieces.append(body)
    for ring in crossings:
        add(MapClass.PED_CROSSING, ring, "zebra", closed=True)

    # Junction pieces: rounded kerbs by closing the meeting arm bodies near the node.
    all_islands = unary_union(islands) if islands else None
    lanes, corridors = _lane_graph(streets, arms, radius)
    for n, ks in arms.items():
        hw = max(max(streets[k].hw_left, streets[k].hw_right) for k in ks)
        r_clip = float(np.hypot(radius[n], hw)) + 1.0
        local = Point(nodes[n]).buffer(r_clip + corner_r + 5.0, quad_segs=12)
        caps = []  # kerb-side corners of every arm at the node; their hull fills the node itself
        for k in ks:
            st, d = streets[k], streets[k].direction_at(n)
            nrm = np.array([-d[1], d[0]])
            left, right = (st.hw_left, st.hw_right) if n == st.a else (st.hw_right, st.hw_left)
            caps += [nodes[n] + left * nrm, nodes[n] - right * nrm]
        hull = shapely.MultiPoint(np.array(caps)).convex_hull
        shape = unary_union(
            [streets[k].body().intersection(local) for k in ks] + [hull] + corridors[n]
        )
        closed = shape.buffer(corner_r, quad_segs=8).buffer(-corner_r, quad_segs=8)
        junction = closed.intersection(Point(nodes[n]).buffer(r_clip, quad_segs=16))
        if all_islands is not None:
            junction = junction.difference(all_islands)
        pieces.extend(_polygons(junction))

    # Road boundaries: every ring of the drivable union (outer kerb, block kerbs, medians).
    area = unary_union(pieces)
    if all_islands is not None:
        area = area.difference(all_islands)
    for poly in _polygons(area):
        for ring in [poly.exterior, *poly.interiors]:
            if Polygon(ring).area < 5.0:
                continue
            pts = np.asarray(ring.simplify(0.05).coords, dtype=np.float64)  # closed: last == first
            add(MapClass.BOUNDARY, pts, "curb")

    drivable = [np.asarray(p.exterior.coords, np.float64)[:-1] for p in pieces if p.area > 0.5]
    name = f"sim-{variety_prefix(varied, junctions)}city-{seed}"
    return WorldMap(name, instances, drivable, lanes)


def _spans(s0: float, s1: float, gaps: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """[s0, s1] minus the gap intervals, keeping pieces longer than 2 m."""
    out, cur = [], s0
    for g0, g1 in sorted(gaps):
        if g0 - cur > 2.0:
            out.append((cur, g0))
        cur = max(cur, g1)
    if s1 - cur > 2.0:
        out.append((cur, s1))
    return out


def variety_prefix(varied: bool, junctions: bool) -> str:
    """The name part of a city's variety: "", "varied-" or "junction-"."""
    return "junction-" if junctions else "varied-" if varied else ""


def _crossing_ring(st: _Street, s0: float, s1: float, skew: float = 0.0) -> NDArray[np.float64]:
    """Closed ring (4, 2) of a crossing over the full street width between arc lengths s0 < s1;
    ``skew`` metres moves its left side forward and its right side back (a parallelogram)."""
    return np.array(
        [
            st.at(s0 - skew / 2, -st.hw_right),
            st.at(s1 - skew / 2, -st.hw_right),
            st.at(s1 + skew / 2, st.hw_left),
            st.at(s0 + skew / 2, st.hw_left),
        ]
    )


def _polygons(geom: shapely.Geometry) -> list[Polygon]:
    """Polygons of a (Multi)Polygon / GeometryCollection, empty ones dropped."""
    if geom.is_empty:
        return []
    if isinstance(geom, Polygon):
        return [geom]
    return [g for g in getattr(geom, "geoms", []) if isinstance(g, Polygon) and not g.is_empty]


def _lane_graph(
    streets: list[_Street], arms: dict[int, list[int]], radius: NDArray
) -> tuple[dict[int, LaneSegment], dict[int, list[Polygon]]]:
    """Street lanes between junctions plus connector lanes through each junction. Returns the
    lanes and, per node, the corridors (lane polygons) of its connectors."""
    lanes: dict[int, LaneSegment] = {}
    corridors: dict[int, list[Polygon]] = {n: [] for n in arms}
    incoming: dict[int, list[tuple[int, int, int, int]]] = {
        n: [] for n in arms
    }  # lane, street, k, n
    outgoing: dict[int, list[tuple[int, int, int, int]]] = {n: [] for n in arms}
    for si, st in enumerate(streets):
        s_a, s_b = radius[st.a], st.length - radius[st.b]
        base = sub_curve(st.curve, s_a, s_b, 2.0)
        for direction, n_lanes in ((1, st.n_fwd), (-1, st.n_bwd)):
            for k in range(n_lanes):
                off = -direction * (st.median / 2 + (k + 0.5) * st.width)
                cl = offset_curve(base, off)
                if direction < 0:
                    cl = cl[::-1]
                lid = len(lanes)
                lanes[lid] = LaneSegment(lid, cl, (), st.width)
                start, end = (st.a, st.b) if direction > 0 else (st.b, st.a)
                outgoing[start].append((lid, si, k, n_lanes))
                incoming[end].append((lid, si, k, n_lanes))
    for n in arms:
        for lid, si, k, n_in in incoming[n]:
            cl_in = lanes[lid].centerline
            h_in = _heading(cl_in[-2], cl_in[-1])
            options = []
            for oid, so, ko, n_out in outgoing[n]:
                if so == si:
                    continue
                cl_out = lanes[oid].centerline
                delta = _wrap(_heading(cl_out[0], cl_out[1]) - h_in)
                options.append((oid, so, ko, n_out, delta))
            other_streets = {o[1] for o in options}
            chosen = []
            for oid, _so, ko, n_out, delta in options:
                target = min(k, n_out - 1)
                if len(other_streets) == 1 or abs(delta) < np.deg2rad(40):
                    ok = ko == target
                elif delta < 0:  # right turn: kerb lane to kerb lane
                    ok = k == n_in - 1 and ko == n_out - 1
                else:  # left turn: inner lane to inner lane
                    ok = k == 0 and ko == 0
                if ok:
                    chosen.append(oid)
            if not chosen and options:
                best = min(options, key=lambda o: abs(o[4]))
                chosen = [o[0] for o in options if o[1] == best[1] and o[2] == min(k, o[3] - 1)]
            succ = []
            for oid in chosen:
                cid = len(lanes)
                cl = _connector(cl_in, lanes[oid].centerline)
                lanes[cid] = LaneSegment(cid, cl, (oid,), lanes[lid].width)
                corridors[n].append(
                    LineString(cl).buffer(lanes[lid].width / 2 + 0.3, cap_style="flat")
                )
                succ.append(cid)
            lanes[lid].successors = tuple(succ)
    return lanes, corridors


def _heading(p: NDArray, q: NDArray) -> float:
    return float(np.arctan2(q[1] - p[1], q[0] - p[0]))


def _wrap(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)


def _connector(cl_in: NDArray, cl_out: NDArray) -> NDArray[np.float64]:
    """Cubic Bezier (n, 2) from the end of cl_in to the start of cl_out, tangent to both."""
    p0, p3 = cl_in[-1], cl_out[0]
    t0 = cl_in[-1] - cl_in[-2]
    t1 = cl_out[1] - cl_out[0]
    t0 = t0 / max(np.linalg.norm(t0), 1e-12)
    t1 = t1 / max(np.linalg.norm(t1), 1e-12)
    d = float(np.linalg.norm(p3 - p0))
    return cubic_bezier(p0, p0 + 0.4 * d * t0, p3 - 0.4 * d * t1, p3, max(6, int(d / 1.0) + 1))
