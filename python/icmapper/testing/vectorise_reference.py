"""The former Python vectoriser (numpy / scipy / scikit-image / shapely / torch): the reference
of the engine's ``icmap_geom::vectorise`` in tests and benchmarks. Not part of the runtime:
``icmapper.models.vectorise.vectorise`` calls the engine; nothing in the package imports this
module outside tests and benchmarks.

It is ``models/vectorise.py`` as it was before the port (commit 4c267ec), unchanged but for the
function's name (``vectorise_reference``), the imports of the shared types and the rules added
since in both (ridge lines along the front or back edge dropped, cut where they bend; bands of
two kerbs drawn as their outline). What it does, step by step, is described in
``icmapper.models.vectorise`` and in the engine's module docs.

Where the engine cannot agree with it exactly (both are deterministic; the differences are in the
last bits of float32 arithmetic): torch's bilinear upsampling sums in float32 in an order that
depends on its CPU kernel (thread count, vector unit), the engine in float64 rounded once, so
upsampled probabilities differ by at most one float32 ulp; the probabilities of an ``upsample = 1``
call are used in their own dtype here (float64 for float64 input) and in float32 by the engine.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from icmapper.models.vectorise import (
    BEND_ARC,
    CROSSING,
    VectorInstances,
    VectoriseParams,
    resample_polyline,
)

if TYPE_CHECKING:
    from shapely.geometry import LineString, Polygon

_K8 = np.ones((3, 3), dtype=np.int64)


#: The 8 neighbour offsets in the order a path walk prefers them: edge neighbours before
#: diagonal ones, then by coordinate (the walk takes the first unvisited one).
_WALK = ((-1, 0), (0, -1), (0, 1), (1, 0), (-1, -1), (-1, 1), (1, -1), (1, 1))


def _order_branch(cells: NDArray[np.int64]) -> NDArray[np.int64]:
    """The cells (L, 2) of one skeleton branch (no junctions) in path order, from an end: the
    lowest (i, j) cell with at most one neighbour (the lowest cell when there is none), then
    always the first unvisited neighbour in ``_WALK`` order."""
    lo = cells.min(axis=0) - 1
    local = cells - lo  # (L, 2) inside a 1-cell border
    grid = np.full(tuple(local.max(axis=0) + 2), -1, np.int64)
    grid[local[:, 0], local[:, 1]] = np.arange(len(cells))
    nb = np.stack([grid[local[:, 0] + di, local[:, 1] + dj] for di, dj in _WALK], 1)  # (L, 8)
    ends = np.nonzero((nb >= 0).sum(1) <= 1)[0]
    pool = ends if len(ends) else np.arange(len(cells))
    cur = int(pool[np.lexsort((cells[pool, 1], cells[pool, 0]))[0]])
    nbl = nb.tolist()
    seen = [False] * len(cells)
    seen[cur] = True
    path = [cur]
    while True:
        cur = next((q for q in nbl[cur] if q >= 0 and not seen[q]), -1)
        if cur < 0:
            break
        seen[cur] = True
        path.append(cur)
    return cells[np.asarray(path, np.int64)]


def _fill(xy: NDArray[np.float64], half_cell: float) -> float:
    """The fraction of the minimum rotated rectangle of cell centres ``xy`` (M, 2), grown by half a
    cell, that the M cells cover."""
    from shapely.geometry import MultiPoint

    rect = MultiPoint(xy).minimum_rotated_rectangle.buffer(half_cell, join_style="mitre")
    return float(len(xy) * (2 * half_cell) ** 2 / rect.area) if rect.area > 0 else 1.0


def _skeleton_branches(
    mask: NDArray[np.bool_],
    metres: Callable[[NDArray[np.int64]], NDArray[np.float64]],
    min_length: float,
    through: float = 0.0,
    spur: float = 0.0,
) -> Iterator[tuple[NDArray[np.int64], LineString]]:
    """The skeleton of ``mask`` (X, Y) (scikit-image) cut at its junctions: each branch's cells
    (L, 2) in path order and its polyline in metres, for branches at least ``min_length`` long.

    With ``through`` > 0 (degrees) a line goes on through a junction: at each junction the two
    branch ends that continue each other most straightly (their courses within ``through`` of a
    straight line) are joined, greedily, best pair first, into one branch (lane lines and kerbs
    do not branch; a junction of their skeleton is where a line meets a spur or another line).
    A branch left with an unjoined end at a junction that is shorter than ``spur`` metres is a
    spur and is dropped."""
    from scipy import ndimage
    from shapely.geometry import LineString

    skel = skeletonize_mask(mask)
    degree = ndimage.convolve(skel.astype(np.int64), _K8, mode="constant") - 1
    junctions = ndimage.binary_dilation(skel & (degree >= 3), _K8) & skel
    labels, n = ndimage.label(skel & ~junctions, _K8)
    paths = [_order_branch(np.argwhere(labels == c)) for c in range(1, n + 1)]
    if through > 0 and n:
        paths = _through_junctions(paths, junctions, metres, through, spur)
    for path in paths:
        if len(path) < 2:
            continue
        line = LineString(metres(path))
        if line.length >= min_length:
            yield path, line


def skeletonize_mask(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """The one-cell-wide skeleton of ``mask`` (X, Y) (scikit-image)."""
    from skimage.morphology import skeletonize

    return np.asarray(skeletonize(mask), bool)


def _through_junctions(
    paths: list[NDArray[np.int64]],
    junctions: NDArray[np.bool_],
    metres: Callable[[NDArray[np.int64]], NDArray[np.float64]],
    through: float,
    spur: float,
) -> list[NDArray[np.int64]]:
    """Joins branches ``paths`` (cells in order) through the junction cells ``junctions`` (X, Y)
    and drops spurs (see ``_skeleton_branches``) -> the joined paths."""
    from scipy import ndimage

    jlab, _ = ndimage.label(junctions, _K8)
    pad = np.pad(jlab, 1)  # (X + 2, Y + 2): neighbours of border cells read 0
    ends: dict[int, list[tuple[int, int, NDArray[np.float64]]]] = {}  # junction -> (b, end, dir)
    for b, path in enumerate(paths):
        for e, (cell, inner) in enumerate(
            ((path[0], path[min(4, len(path) - 1)]), (path[-1], path[max(len(path) - 5, 0)]))
        ):
            near = pad[cell[0] : cell[0] + 3, cell[1] : cell[1] + 3]
            js = np.unique(near[near > 0])
            if len(js) == 0 or (e == 1 and len(path) == 1):
                continue
            out = metres(cell[None])[0] - metres(inner[None])[0]  # (2,) towards the junction
            norm = np.linalg.norm(out)
            direction = out / norm if norm > 0 else np.zeros(2)
            ends.setdefault(int(js[0]), []).append((b, e, direction))
    cos_min = np.cos(np.radians(through))
    link: dict[tuple[int, int], tuple[int, int]] = {}  # (branch, end) -> (branch, end)
    loose: set[int] = set()  # branches with an unjoined end at a junction
    for j in sorted(ends):
        cands = sorted(
            (float(-(a[2] @ b[2])), x, y)
            for x, a in enumerate(ends[j])
            for y, b in enumerate(ends[j])
            if x < y and a[0] != b[0]
        )
        used: set[int] = set()
        for straight, x, y in reversed(cands):  # straightest pair first
            if straight < cos_min or x in used or y in used:
                continue
            used |= {x, y}
            a, b = ends[j][x], ends[j][y]
            link[a[0], a[1]], link[b[0], b[1]] = (b[0], b[1]), (a[0], a[1])
        loose |= {ends[j][x][0] for x in range(len(ends[j])) if x not in used}
    out: list[NDArray[np.int64]] = []
    done = [False] * len(paths)
    for start in range(len(paths)):
        if done[start]:
            continue
        # walk to one end of the chain (a branch end without a link), or around a loop
        b, e = start, 0
        while (b, e) in link:
            b, e = link[b, e]
            e = 1 - e
            if b == start:
                break
        chain, cur, end = [], b, 1 - e  # ``end``: the end of ``cur`` the walk leaves by
        while not done[cur]:
            done[cur] = True
            p = paths[cur]
            chain.append(p if end == 1 else p[::-1])
            if (cur, end) not in link:
                break
            cur, end = link[cur, end]
            end = 1 - end
        joined = np.concatenate(chain)
        if len(chain) == 1 and start in loose and spur > 0:
            xy = metres(joined)  # (L, 2)
            if float(np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()) < spur:
                continue  # a spur off a line
        out.append(joined)
    return out


def _band_rectangle(xy: NDArray[np.float64], half_cell: float) -> Polygon:
    """A rectangle fitted robustly to the cells ``xy`` (M, 2) of one part of a split crossing
    mask: along its principal axis from the 1st to the 99th percentile, across it the width the
    10th-90th percentiles span in a uniform band. The corner a part shares with its neighbour sits
    in the tails and does not widen it, as it would widen the minimum rotated rectangle."""
    from shapely.geometry import Polygon

    centre = xy.mean(0)
    _, _, vt = np.linalg.svd(xy - centre, full_matrices=False)
    along, across = (xy - centre) @ vt[0], (xy - centre) @ vt[1]  # (M,), (M,)
    a0, a1 = np.percentile(along, [1, 99]) + np.array([-half_cell, half_cell])
    c10, c90 = np.percentile(across, [10, 90])
    mid, w = 0.5 * (c10 + c90), 0.5 * (c90 - c10) / 0.8 + half_cell
    corners = [(a0, mid - w), (a1, mid - w), (a1, mid + w), (a0, mid + w)]
    return Polygon([centre + u * vt[0] + v * vt[1] for u, v in corners])


def _crossing_parts(
    comp: NDArray[np.bool_],
    metres: Callable[[NDArray[np.int64]], NDArray[np.float64]],
    p: VectoriseParams,
    cell_area: float,
) -> list[NDArray[np.int64]]:
    """The cells (M_i, 2) of each crossing in one connected crossing mask ``comp`` (X, Y).

    Crossings that touch (the arms of an intersection, often a ring around it) form one mask whose
    rectangle would cover the whole intersection. Holes of inscribed radius up to ``max_hole`` are
    filled first (the outline mask of one wide crossing). A mask around a wider hole is cut along
    the sides of the hole's convex hull; a mask that fills less than ``rectangularity`` of its
    rectangle along the straight runs of its skeleton (branches shorter than ``min_length``
    dropped). Both are found by Douglas-Peucker with ``corner_tolerance``. Every cell goes to its
    nearest side or run, then the two parts whose union is most rectangular are joined while it
    stays above ``rectangularity``."""
    from scipy import ndimage
    from shapely.geometry import MultiPoint, Polygon

    half = 0.5 * float(np.sqrt(cell_area))
    # holes narrower than ``max_hole`` are the unpainted inside of one crossing's outline mask;
    # a wider one is the middle of an intersection the crossings surround
    holes = ndimage.binary_fill_holes(comp) & ~comp
    hole_radius = ndimage.distance_transform_edt(holes) * 2 * half  # (X, Y) metres
    labels, n = ndimage.label(holes, _K8)
    radius = np.asarray(ndimage.maximum(hole_radius, labels, np.arange(1, n + 1)) if n else [])
    wide = 1 + np.flatnonzero(radius > p.max_hole)  # labels of the wide holes
    comp = comp | (holes & ~np.isin(labels, wide))
    cells = np.argwhere(comp)  # (M, 2)
    ring = len(wide) > 0
    if p.rectangularity <= 0 or (not ring and _fill(metres(cells), half) >= p.rectangularity):
        return [cells]
    starts: list[NDArray[np.float64]] = []
    ends: list[NDArray[np.float64]] = []

    def add(v: NDArray[np.float64]) -> None:  # (V, 2) polyline -> its segments
        starts.extend(v[:-1])
        ends.extend(v[1:])

    if ring:  # around an intersection: the crossings lie along the sides of its hole
        for h in wide:
            hull = MultiPoint(metres(np.argwhere(labels == h))).convex_hull
            if isinstance(hull, Polygon):
                add(np.asarray(hull.exterior.simplify(p.corner_tolerance).coords, np.float64))
    else:  # along the straight runs of its skeleton
        for _, line in _skeleton_branches(comp, metres, p.min_length):
            add(np.asarray(line.simplify(p.corner_tolerance).coords, np.float64))
    if len(starts) < 2:
        return [cells]
    a, b_ = np.asarray(starts), np.asarray(ends)  # (S, 2) segment ends
    xy = metres(cells)  # (M, 2)
    ab = b_ - a  # (S, 2)
    t = np.einsum("msd,sd->ms", xy[:, None] - a[None], ab) / np.maximum((ab**2).sum(-1), 1e-12)
    near = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]  # (M, S, 2)
    owner = np.linalg.norm(xy[:, None] - near, axis=-1).argmin(1)  # (M,)
    parts = [cells[owner == s] for s in range(len(a)) if np.any(owner == s)]
    while len(parts) > 1:
        best, pair = p.rectangularity, None
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                f = _fill(metres(np.vstack([parts[i], parts[j]])), half)
                if f >= best:
                    best, pair = f, (i, j)
        if pair is None:
            break
        i, j = pair
        parts[i] = np.vstack([parts[i], parts[j]])
        del parts[j]
    return [q for q in parts if len(q) * cell_area >= p.min_area]


def _ridge_mask(
    prob: NDArray[np.floating], p: VectoriseParams, cell: tuple[float, float]
) -> NDArray[np.bool_]:
    """Cells on a bright ridge of ``prob`` (X, Y), cells of ``cell`` metres: above
    ``ridge_threshold`` where the smaller eigenvalue of the Hessian (Gaussian scale ``ridge_sigma``)
    is below -``ridge_curvature``. -> (X, Y) bool."""
    from skimage.feature import hessian_matrix, hessian_matrix_eigvals

    px = float(np.sqrt(cell[0] * cell[1]))  # metres per cell
    h = hessian_matrix(prob, sigma=p.ridge_sigma / px, order="rc", use_gaussian_derivatives=False)
    low = hessian_matrix_eigvals(h)[1]  # (X, Y) the smaller eigenvalue, per cell^2
    return (prob > p.ridge_threshold) & (low < -p.ridge_curvature * px * px)


def _along_edge(pts: NDArray[np.float32], half_x: float, margin: float, span: float) -> bool:
    """A line (P, 2) ego along the front or back edge of the grid: more than 80 % of its points
    within ``margin`` of |x| = half_x, spanning more than ``span`` in y (float64)."""
    if margin <= 0 or len(pts) == 0:
        return False
    q = np.asarray(pts, np.float64)
    if not (np.abs(q[:, 0]) > half_x - margin).mean() > 0.8:
        return False
    return float(q[:, 1].max() - q[:, 1].min()) > span


def _at(line: NDArray[np.float64], cum: NDArray[np.float64], t: float) -> NDArray[np.float64]:
    """The point at arc length ``t`` along ``line`` (L, 2), clamped to its ends."""
    if t <= 0:
        return line[0]
    if t >= cum[-1]:
        return line[-1]
    j = min(int(np.searchsorted(cum, t, side="right")) - 1, len(line) - 2)
    length = cum[j + 1] - cum[j]
    if length <= 0:
        return line[j]
    u = (t - cum[j]) / length
    return np.array([line[j, 0] + u * (line[j + 1, 0] - line[j, 0]),
                     line[j, 1] + u * (line[j + 1, 1] - line[j, 1])])  # fmt: skip


def _cut_at_bends(
    line: NDArray[np.float64], bend: float, min_length: float, offset: int = 0
) -> list[tuple[int, int]]:
    """A line (L, 2) cut at every vertex where it turns by more than ``bend`` degrees over
    ``BEND_ARC`` metres on either side (the sharpest first, the first of equals, then each side
    again): the pieces as inclusive vertex spans, in order; pieces shorter than ``min_length``
    left out (an uncut line comes back whole)."""
    steps = [math.sqrt(d[0] * d[0] + d[1] * d[1]) for d in np.diff(line, axis=0)]
    cum = np.concatenate([[0.0], np.cumsum(steps)])
    best, best_turn = -1, 0.0
    for i in range(1, len(line) - 1) if bend > 0 else ():
        a = line[i] - _at(line, cum, cum[i] - BEND_ARC)
        b = _at(line, cum, cum[i] + BEND_ARC) - line[i]
        na, nb = math.sqrt(a[0] * a[0] + a[1] * a[1]), math.sqrt(b[0] * b[0] + b[1] * b[1])
        if na <= 0 or nb <= 0:
            continue
        cos = (a[0] * b[0] + a[1] * b[1]) / (na * nb)
        turn = math.degrees(math.acos(min(1.0, max(-1.0, cos))))
        if turn > bend and (best < 0 or turn > best_turn):
            best, best_turn = i, turn
    if best < 0:
        return [(offset, offset + len(line) - 1)]
    out = []
    if cum[best] >= min_length:
        out += _cut_at_bends(line[: best + 1], bend, min_length, offset)
    if cum[-1] - cum[best] >= min_length:
        out += _cut_at_bends(line[best:], bend, min_length, offset + best)
    return out


def _vertex_cells(line: NDArray[np.float64], simple: NDArray[np.float64]) -> list[int]:
    """For each vertex of ``simple`` (a simplification of ``line``) the index of its point in
    ``line``, found forward."""
    at, k = [], 0
    for v in simple:
        while k + 1 < len(line) and not (line[k] == v).all():
            k += 1
        at.append(k)
    return at


def _outline_bands(
    mask: NDArray[np.bool_],
    metres: Callable[[NDArray[np.int64]], NDArray[np.float64]],
    branches: list[tuple[NDArray[np.int64], LineString]],
    p: VectoriseParams,
    cell: float,
) -> list[tuple[NDArray[np.int64], LineString]]:
    """The branches of a line class's ``mask`` with those of every band (a component whose
    skeleton lies farther than ``band * shrink`` from its edge over at least half its cells)
    replaced by the branches of its outline shrunk by ``shrink`` (kept branches first, then each
    band's, bands in label order)."""
    from scipy import ndimage

    if p.band <= 0 or not branches:
        return branches
    dt = ndimage.distance_transform_edt(mask)  # cells
    labels, n = ndimage.label(mask, _K8)
    thick, total = np.zeros(n + 1, np.int64), np.zeros(n + 1, np.int64)
    for path, _ in branches:
        c = labels[path[0, 0], path[0, 1]]
        total[c] += len(path)
        thick[c] += int((dt[path[:, 0], path[:, 1]] * cell > p.band * p.shrink).sum())
    band = (total > 0) & (2 * thick >= total)
    out = [b for b in branches if not band[labels[b[0][0, 0], b[0][0, 1]]]]
    for c in range(1, n + 1):
        if not band[c]:
            continue
        inner = (labels == c) & (dt * cell > p.shrink)
        pad = np.pad(inner, 1, constant_values=True)  # the grid's border is no edge
        interior = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
        edge = inner & ~interior
        if edge.any():
            out.extend(_skeleton_branches(edge, metres, p.min_length, p.through, p.spur))
    return out


def vectorise_reference(
    prob: NDArray[np.floating],
    half_x: float,
    half_y: float,
    params: VectoriseParams | None = None,
) -> VectorInstances:
    """What the former vectoriser returns for the arguments of
    ``icmapper.models.vectorise.vectorise`` (probabilities (K, X, Y), the BEV's half extents, the
    settings). ValueError on a wrong shape or non-finite probabilities."""
    import torch
    import torch.nn.functional as F
    from scipy import ndimage
    from shapely.geometry import MultiPoint, Polygon

    prob = np.asarray(prob)
    if prob.ndim != 3 or min(prob.shape) < 1:
        raise ValueError(f"vectorise: prob must be (K, X, Y), got {prob.shape}")
    p = (params or VectoriseParams()).for_grid(prob.shape[1], prob.shape[2], half_x, half_y)
    if not np.all(np.isfinite(prob)):
        raise ValueError("vectorise: probabilities contain NaN or inf")
    if p.upsample > 1:
        t = torch.from_numpy(np.ascontiguousarray(prob, dtype=np.float32))[None]
        prob = F.interpolate(t, scale_factor=p.upsample, mode="bilinear", align_corners=False)[0]
        prob = prob.numpy()
    k_num, nx, ny = prob.shape
    sx, sy = 2 * half_x / nx, 2 * half_y / ny

    def metres(ij: NDArray[np.int64]) -> NDArray[np.float64]:
        return np.stack([(ij[:, 0] + 0.5) * sx - half_x, (ij[:, 1] + 0.5) * sy - half_y], -1)

    classes: list[int] = []
    scores: list[float] = []
    points: list[NDArray[np.float32]] = []
    for k in range(k_num):
        if k in p.ridge_classes:
            mask = _ridge_mask(prob[k], p, (sx, sy))
        else:
            mask = prob[k] > p.threshold
        if not mask.any():
            continue
        if k == CROSSING:
            labels, n = ndimage.label(mask, _K8)
            for c in range(1, n + 1):
                comp = labels == c
                if comp.sum() * sx * sy < p.min_area:
                    continue
                parts = _crossing_parts(comp, metres, p, sx * sy)
                for cells in parts:
                    xy = metres(cells)
                    if len(parts) > 1:
                        rect = _band_rectangle(xy, 0.5 * sx)
                    elif p.hull_simplify > 0:
                        rect = MultiPoint(xy).convex_hull.buffer(0.5 * sx, join_style="mitre")
                        rect = rect.simplify(p.hull_simplify)
                    else:
                        rect = MultiPoint(xy).minimum_rotated_rectangle
                    if p.shrink > 0 and isinstance(rect, Polygon):
                        small = rect.buffer(-p.shrink, join_style="mitre")
                        rect = small if isinstance(small, Polygon) and small.area > 0 else rect
                    if not isinstance(rect, Polygon) or rect.area <= 0:
                        continue
                    ring = np.asarray(rect.exterior.coords, np.float64)[:-1]
                    classes.append(k)
                    scores.append(float(prob[k][cells[:, 0], cells[:, 1]].mean()))
                    points.append(resample_polyline(ring, p.num_points, closed=True))
            continue
        lines = list(_skeleton_branches(mask, metres, p.min_length, p.through, p.spur))
        if k not in p.ridge_classes:
            lines = _outline_bands(mask, metres, lines, p, sx)
        for path, line in lines:
            simple = np.asarray(line.simplify(p.simplify).coords, np.float64)
            ridge = k in p.ridge_classes
            spans = _cut_at_bends(simple, p.bend, p.min_length) if ridge else [(0, len(simple) - 1)]
            coords = np.asarray(line.coords, np.float64)
            at = _vertex_cells(coords, simple) if len(spans) > 1 else []
            for a, b in spans:
                pts = resample_polyline(simple[a : b + 1], p.num_points, closed=False)
                if ridge and _along_edge(pts, half_x, p.edge_margin, p.edge_span):
                    continue
                own = path[at[a] : at[b] + 1] if at else path  # a cut piece: its own cells
                classes.append(k)
                scores.append(float(prob[k][own[:, 0], own[:, 1]].mean()))
                points.append(pts)
    n_out = len(classes)
    return VectorInstances(
        np.asarray(classes, np.int64),
        np.asarray(scores, np.float32).reshape(n_out),
        np.stack(points) if n_out else np.zeros((0, p.num_points, 2), np.float32),
    )
