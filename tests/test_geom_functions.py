"""icmapper.geom functions against independent oracles: numpy (arc length, brute-force Chamfer),
shapely (clipping, union) and scipy (splprep/splev smoothing spline)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from icmapper import geom
from icmapper.testing.geom_reference import patch_polygon, to_ego
from scipy.interpolate import splev, splprep
from shapely.geometry import LineString, Polygon

# ---------------------------------------------------------------------------------------------
# helpers (oracles)


def arc_interp(points: np.ndarray, n: int, closed: bool) -> np.ndarray:
    """numpy arc-length interpolation: (m, 2) -> (n, 2) evenly spaced (closed: no repeat)."""
    pts = np.vstack([points, points[:1]]) if closed else points  # (m', 2)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)  # (m' - 1,)
    s = np.concatenate([[0.0], np.cumsum(seg)])  # (m',)
    t = np.linspace(0.0, s[-1], n, endpoint=not closed)  # (n,)
    return np.stack([np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])], axis=1)


def shoelace(ring: np.ndarray) -> float:
    """Signed area of a ring (n, 2) without repeated first point (CCW positive)."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Hausdorff distance between point sets (n, 2), (m, 2)."""
    d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)  # (n, m)
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def random_graph_polyline(rng: np.random.Generator, n: int = 40) -> np.ndarray:
    """A non-self-intersecting wiggly polyline (x monotone in a rotated frame), (n, 2)."""
    t = np.sort(rng.uniform(-60, 60, n))  # (n,)
    y = np.cumsum(rng.normal(0, 2.0, n))  # (n,)
    yaw = rng.uniform(-math.pi, math.pi)
    c, s = math.cos(yaw), math.sin(yaw)
    off = rng.uniform(-15, 15, 2)
    return np.stack([c * t - s * y, s * t + c * y], axis=1) + off  # (n, 2)


def random_star_ring(rng: np.random.Generator, n: int = 12, r: float = 20.0) -> np.ndarray:
    """A simple (star-shaped, possibly concave) CCW ring (n, 2) without repeated point."""
    ang = np.sort(rng.uniform(0, 2 * math.pi, n))  # (n,)
    rad = rng.uniform(0.3 * r, r, n)  # (n,)
    centre = rng.uniform(-20, 20, 2)
    return centre + np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)


def random_patch(rng: np.random.Generator) -> tuple[tuple[float, float, float], float, float]:
    pose = (float(rng.uniform(-10, 10)), float(rng.uniform(-10, 10)), float(rng.uniform(-4, 4)))
    return pose, float(rng.uniform(5, 35)), float(rng.uniform(5, 20))


# ---------------------------------------------------------------------------------------------
# resample


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("seed", range(5))
def test_resample_matches_numpy_arc_length(seed: int, closed: bool) -> None:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-50, 50, (int(rng.integers(3, 30)), 2))  # (m, 2)
    for n in (3, 7, 20, 101):
        got = geom.resample(pts, n, closed=closed)
        assert got.shape == (n, 2) and got.dtype == np.float64
        np.testing.assert_allclose(got, arc_interp(pts, n, closed), atol=1e-9)


def test_resample_float32_and_lists_and_strided() -> None:
    pts = np.array([[0, 0], [3, 4], [3, 10], [-2, 10]], dtype=np.float64)
    ref = geom.resample(pts, 9)
    np.testing.assert_allclose(geom.resample(pts.astype(np.float32), 9), ref, atol=1e-5)
    np.testing.assert_allclose(geom.resample(pts.tolist(), 9), ref, atol=1e-12)
    np.testing.assert_allclose(geom.resample(pts.astype(np.int32), 9), ref, atol=1e-12)
    big = np.zeros((8, 4))
    big[::2, 1:3] = pts  # a strided, non-contiguous view
    np.testing.assert_allclose(geom.resample(big[::2, 1:3], 9), ref, atol=1e-12)
    np.testing.assert_allclose(geom.resample(np.asfortranarray(pts), 9), ref, atol=1e-12)


@pytest.mark.parametrize("closed", [False, True])
@pytest.mark.parametrize("spacing", [0.3, 1.0, 2.5])
def test_resample_spacing_count_and_positions(spacing: float, closed: bool) -> None:
    rng = np.random.default_rng(7)
    pts = rng.uniform(-20, 20, (10, 2))  # (10, 2)
    closed_pts = np.vstack([pts, pts[:1]]) if closed else pts
    length = float(np.linalg.norm(np.diff(closed_pts, axis=0), axis=1).sum())
    want = (
        max(3, math.ceil(length / spacing)) if closed else max(2, math.ceil(length / spacing) + 1)
    )
    got = geom.resample_spacing(pts, spacing, closed=closed)
    assert got.shape == (want, 2)
    np.testing.assert_allclose(got, arc_interp(pts, want, closed), atol=1e-9)


# ---------------------------------------------------------------------------------------------
# clipping


@pytest.mark.parametrize("seed", range(25))
def test_clip_polyline_matches_shapely(seed: int) -> None:
    rng = np.random.default_rng(seed)
    pts = random_graph_polyline(rng)
    pose, hx, hy = random_patch(rng)
    margin = float(rng.uniform(0, 5))
    pieces = geom.clip_to_patch(pts, pose, (hx, hy), margin=margin)
    poly = patch_polygon(pose, hx + margin, hy + margin)
    ref = shapely.line_merge(LineString(pts).intersection(poly))
    ref_lines = [g for g in getattr(ref, "geoms", [ref]) if g.geom_type == "LineString"]
    ref_lines = [g for g in ref_lines if not g.is_empty and g.length > 1e-9]
    assert len(pieces) == len(ref_lines)
    assert sum(LineString(p).length for p in pieces) == pytest.approx(
        sum(g.length for g in ref_lines), rel=1e-9, abs=1e-9
    )
    # pieces come in the polyline's order: their start points progress along the input line
    starts = [LineString(pts).project(shapely.Point(p[0])) for p in pieces]
    assert starts == sorted(starts)
    for p in pieces:
        assert p.shape[1] == 2 and p.shape[0] >= 2
        ego = to_ego(p, pose)
        assert np.all(np.abs(ego[:, 0]) <= hx + margin + 1e-9)
        assert np.all(np.abs(ego[:, 1]) <= hy + margin + 1e-9)
        best = min(hausdorff(p, np.asarray(g.coords)) for g in ref_lines)
        assert best < 1e-7


def test_clip_polyline_inside_outside() -> None:
    pts = np.array([[-1.0, 0.0], [1.0, 0.5]])
    (piece,) = geom.clip_to_patch(pts, (0, 0, 0), (5, 5))
    np.testing.assert_allclose(piece, pts)
    assert geom.clip_to_patch(pts + 100, (0, 0, 0), (5, 5)) == []


@pytest.mark.parametrize("seed", range(25))
def test_clip_polygon_matches_shapely_area(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    ring = random_star_ring(rng)
    pose, hx, hy = random_patch(rng)
    out = geom.clip_to_patch(ring, pose, (hx, hy), closed=True)
    ref = Polygon(ring).intersection(patch_polygon(pose, hx, hy))
    if ref.area < 1e-9:
        assert out == [] or abs(shoelace(out[0])) < 1e-9
        return
    assert len(out) == 1
    clipped = out[0]
    assert not np.allclose(clipped[0], clipped[-1])  # the first point is not repeated
    assert abs(shoelace(clipped)) == pytest.approx(ref.area, rel=1e-9)
    ego = to_ego(clipped, pose)
    assert np.all(np.abs(ego) <= np.array([hx, hy]) + 1e-9)


# ---------------------------------------------------------------------------------------------
# spline fit

# Measured agreement of fit_curve with scipy splprep/splev on the noisy arcs below (noise sigma
# 0.1 m, 25-60 points, 8 seeds): the fitted points lie on scipy's curve within 8e-7 m (s = 0.5)
# and 2.3e-5 m (s = 0); the tolerances leave a margin over those measurements.
FIT_TOL = {0.5: 1e-5, 0.0: 1e-4}  # metres, distance of the returned points to scipy's curve


def noisy_curve(rng: np.random.Generator) -> np.ndarray:
    n = int(rng.integers(25, 60))
    t = np.linspace(0, 1, n)  # (n,)
    r = rng.uniform(20, 60)
    ang = t * rng.uniform(0.5, 1.5)  # (n,)
    pts = np.stack([r * np.sin(ang), r * (1 - np.cos(ang))], axis=1)  # (n, 2)
    return pts + rng.normal(0, 0.1, pts.shape)


def scipy_fit(points: np.ndarray, s: float, n_eval: int = 4000) -> np.ndarray:
    tck, _ = splprep([points[:, 0], points[:, 1]], s=s, k=3)
    x, y = splev(np.linspace(0, 1, n_eval), tck)
    return np.stack([x, y], axis=1)  # (n_eval, 2)


@pytest.mark.parametrize("s", [0.5, 0.0])
@pytest.mark.parametrize("seed", range(8))
def test_fit_curve_matches_scipy(seed: int, s: float) -> None:
    """fit_curve agrees with scipy splprep(s, k=3)/splev: every returned point lies on scipy's
    curve within FIT_TOL[s] (measured: 8e-7 m for s = 0.5, 2.3e-5 m for s = 0), the ends are
    scipy's ends, the points are about `spacing` apart and cover the whole curve."""
    rng = np.random.default_rng(seed)
    pts = noisy_curve(rng)
    got = geom.fit_curve(pts, s=s, spacing=1.0)  # (k, 2)
    ref = scipy_fit(pts, s)  # (4000, 2) dense
    ref_line = LineString(ref)
    assert shapely.distance(shapely.points(got), ref_line).max() < FIT_TOL[s]
    np.testing.assert_allclose(got[0], ref[0], atol=FIT_TOL[s])
    np.testing.assert_allclose(got[-1], ref[-1], atol=FIT_TOL[s])
    step = np.linalg.norm(np.diff(got, axis=0), axis=1)  # (k - 1,)
    assert step.max() <= 1.0 + 1e-6 and step.min() > 0.5  # about `spacing` apart
    # coverage: every point of scipy's curve is near the returned polyline (chordal error only)
    assert shapely.distance(shapely.points(ref), LineString(got)).max() < 0.3


def distance_to_spline(points: np.ndarray, tck: object) -> np.ndarray:
    """Exact distance of each point (k, 2) to scipy's spline curve: the nearest of 20001 dense
    samples refined by Newton's method on the squared distance (precise to ~1e-13 m)."""
    dense_u = np.linspace(0.0, 1.0, 20001)
    dense = np.stack(splev(dense_u, tck), axis=1)  # (20001, 2)
    out = np.empty(len(points))
    for i, p in enumerate(points):
        v = float(dense_u[np.argmin(((dense - p) ** 2).sum(1))])
        for _ in range(8):
            c, d1, d2 = (np.array(splev(v, tck, der=d)) for d in (0, 1, 2))
            v = min(1.0, max(0.0, v - ((c - p) @ d1) / (d1 @ d1 + (c - p) @ d2)))
        out[i] = np.linalg.norm(np.array(splev(v, tck)) - p)
    return out


@pytest.mark.parametrize("s", [0.1, 0.5, 1.0])
def test_fit_curve_on_scipy_curve_precisely(s: float) -> None:
    """Merge-like inputs (25-90 points, N(0, 0.1 m) noise, world coordinates up to 5 km): every
    returned point lies on scipy's splprep curve to 1e-8 m (measured worst 1.5e-11 m), the ends
    are scipy's ends."""
    worst = 0.0
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        m = int(rng.integers(25, 90))
        t = np.linspace(0.0, rng.uniform(20.0, 60.0), m)  # (m,)
        pts = np.stack([t, 0.3 * np.sin(t / rng.uniform(3.0, 17.0)) + (t / 30.0) ** 2], axis=1)
        pts = pts + rng.normal(0.0, 0.1, (m, 2)) + rng.uniform(-5000.0, 5000.0, 2)  # (m, 2)
        got = geom.fit_curve(pts, s=s, spacing=1.0)  # (k, 2)
        tck, _ = splprep([pts[:, 0], pts[:, 1]], s=s, k=3)
        worst = max(worst, float(distance_to_spline(got, tck).max()))
        np.testing.assert_allclose(got[0], splev(0.0, tck), atol=1e-8, rtol=0)
        np.testing.assert_allclose(got[-1], splev(1.0, tck), atol=1e-8, rtol=0)
    assert worst < 1e-8


def test_fit_curve_few_points_degree_drops() -> None:
    two = np.array([[0.0, 0.0], [10.0, 0.0]])
    got = geom.fit_curve(two, s=0.0, spacing=1.0)
    np.testing.assert_allclose(got, arc_interp(two, 11, False), atol=1e-9)
    three = np.array([[0.0, 0.0], [5.0, 2.0], [10.0, 0.0]])
    got3 = geom.fit_curve(three, s=0.0, spacing=0.5)
    tck, _ = splprep([three[:, 0], three[:, 1]], s=0.0, k=2)
    ref3 = np.stack(splev(np.linspace(0, 1, 2000), tck), axis=1)
    assert shapely.distance(shapely.points(got3), LineString(ref3)).max() < 1e-4
    np.testing.assert_allclose(got3[[0, -1]], three[[0, -1]], atol=1e-9)


# ---------------------------------------------------------------------------------------------
# merge


def test_merge_polyline_overlap_continuation_reversed() -> None:
    rng = np.random.default_rng(3)
    line = np.stack([np.linspace(0, 60, 61), np.zeros(61)], axis=1)  # (61, 2)
    glob = line[:31]  # x in [0, 30]
    det = line[20:51] + rng.normal(0, 0.05, (31, 2))  # x in [20, 50], overlapping
    merged = geom.merge_polyline(glob, det, s=0.5, spacing=1.0)
    assert merged[0, 0] == pytest.approx(0.0, abs=0.3)
    assert merged[-1, 0] == pytest.approx(50.0, abs=0.3)
    assert np.abs(merged[:, 1]).max() < 0.2
    # the reversed detection gives the same extent, and the global direction is kept
    merged_rev = geom.merge_polyline(glob, det[::-1], s=0.5, spacing=1.0)
    assert merged_rev[0, 0] == pytest.approx(0.0, abs=0.3)
    assert merged_rev[-1, 0] == pytest.approx(50.0, abs=0.3)
    # a detection contained in the global keeps its extent
    inside = geom.merge_polyline(glob, line[10:20], s=0.5, spacing=1.0)
    assert inside[0, 0] == pytest.approx(0.0, abs=0.3)
    assert inside[-1, 0] == pytest.approx(30.0, abs=0.3)
    # a global pointing -x keeps pointing -x
    back = geom.merge_polyline(glob[::-1], det, s=0.5, spacing=1.0)
    assert back[0, 0] == pytest.approx(50.0, abs=0.3)
    assert back[-1, 0] == pytest.approx(0.0, abs=0.3)


# ---------------------------------------------------------------------------------------------
# union


def random_quad(rng: np.random.Generator) -> np.ndarray:
    """A rotated rectangle (a crossing), CCW, (4, 2)."""
    c = rng.uniform(-10, 10, 2)
    w, h, a = rng.uniform(2, 12), rng.uniform(2, 6), rng.uniform(0, math.pi)
    box = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    return box @ rot.T + c


@pytest.mark.parametrize("seed", range(20))
def test_polygon_union_matches_shapely(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    rings = [random_quad(rng) for _ in range(int(rng.integers(1, 5)))]
    out = geom.polygon_union(rings)
    ref = shapely.union_all([Polygon(r) for r in rings])
    ref_polys = list(getattr(ref, "geoms", [ref]))
    assert len(out) == len(ref_polys)
    areas = [shoelace(r) for r in out]
    assert all(a > 0 for a in areas)  # counter-clockwise
    assert areas == sorted(areas, reverse=True)  # largest first
    want = sorted((Polygon(p.exterior).area for p in ref_polys), reverse=True)
    # geo's BooleanOps snaps to a fixed-point grid: areas agree to ~1e-9 relative (measured)
    np.testing.assert_allclose(areas, want, rtol=1e-7)


def test_polygon_union_array_input() -> None:
    a = np.array([[0, 0], [2, 0], [2, 2], [0, 2]], dtype=np.float32)
    out = geom.polygon_union(np.stack([a, a + 1]))  # (2, 4, 2)
    assert len(out) == 1 and shoelace(out[0]) == pytest.approx(7.0)


# ---------------------------------------------------------------------------------------------
# Chamfer


def chamfer_np(a: np.ndarray, b: np.ndarray) -> float:
    d = np.linalg.norm(a[:, None] - b[None], axis=2)  # (n, m)
    return float((d.min(axis=1).mean() + d.min(axis=0).mean()) / 2)


@pytest.mark.parametrize("seed", range(5))
def test_chamfer_distance_brute_force(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(0, 5, (int(rng.integers(1, 40)), 2))
    b = rng.normal(1, 5, (int(rng.integers(1, 40)), 2))
    assert geom.chamfer_distance(a, b) == pytest.approx(chamfer_np(a, b), rel=1e-12)
    assert geom.chamfer_distance(a, a) == 0.0


def test_chamfer_matrix_brute_force() -> None:
    rng = np.random.default_rng(11)
    a = rng.normal(0, 5, (6, 20, 2))  # (A, n, 2)
    b = [rng.normal(0, 5, (int(k), 2)) for k in rng.integers(2, 30, 4)]  # ragged list
    got = geom.chamfer_matrix(a, b)
    assert got.shape == (6, 4) and got.dtype == np.float64
    want = np.array([[chamfer_np(x, y) for y in b] for x in a])  # (6, 4)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    np.testing.assert_allclose(
        geom.chamfer_matrix(list(a), a.astype(np.float32)).diagonal(), 0, atol=1e-5
    )
