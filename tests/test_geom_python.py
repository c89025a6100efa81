"""The Python-side functions of icmapper.geom (batched forms beside the engine's) against
independent oracles: shapely (interpolation, distances to lines), scipy cdist (nearest distances)
and the engine's single-instance functions."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from icmapper import geom
from scipy.spatial.distance import cdist


def brute_chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """The definition: (mean nearest a->b + mean nearest b->a) / 2, all pairs by cdist."""
    d = cdist(a, b)  # (n, m)
    return 0.5 * (d.min(axis=1).mean() + d.min(axis=0).mean())


def shapely_samples(points: np.ndarray, num: int, closed: bool) -> np.ndarray:
    """num points by shapely interpolation: open at j / (num - 1), closed at j / num of the
    length along the closed contour."""
    line = shapely.LineString(np.vstack([points, points[:1]]) if closed else points)
    frac = np.arange(num) / num if closed else np.linspace(0.0, 1.0, num)
    return shapely.get_coordinates(line.interpolate(frac, normalized=True))  # (num, 2)


# ---------------------------------------------------------------------------------------------
# resampling


@pytest.mark.parametrize("closed", [False, True])
def test_resample_many_matches_shapely(closed: bool) -> None:
    rng = np.random.default_rng(0)
    pts = np.cumsum(rng.normal(size=(12, 20, 2)), axis=1)  # (12, 20, 2)
    ours = geom.resample_many(pts, 200, closed)  # (12, 200, 2)
    assert ours.shape == (12, 200, 2) and ours.dtype == np.float64
    for k in range(12):
        np.testing.assert_allclose(ours[k], shapely_samples(pts[k], 200, closed), atol=1e-9)
        # row k is the engine's resample of row k
        np.testing.assert_array_equal(ours[k], geom.resample(pts[k], 200, closed))


def test_resample_many_mixed_rows_and_degenerate_rows() -> None:
    rng = np.random.default_rng(1)
    pts = np.cumsum(rng.normal(size=(5, 7, 2)), axis=1)  # (5, 7, 2)
    pts[2] = pts[2, :1]  # zero length: all points equal
    closed = np.array([False, True, True, False, True])
    out = geom.resample_many(pts, 30, closed)  # (5, 30, 2)
    np.testing.assert_array_equal(out[2], np.repeat(pts[2, :1], 30, axis=0))
    for k in (0, 1, 3, 4):
        np.testing.assert_allclose(out[k], shapely_samples(pts[k], 30, closed[k]), atol=1e-9)
    one = geom.resample_many(pts[:, :1], 4, closed)  # single-point rows
    np.testing.assert_array_equal(one, np.repeat(pts[:, :1], 4, axis=1))
    assert geom.resample_many(np.zeros((0, 20, 2)), 200).shape == (0, 200, 2)


@pytest.mark.parametrize(("num", "closed"), [(1, False), (1, True), (2, True), (2, False)])
def test_resample_many_few_points(num: int, closed: bool) -> None:
    """Counts the engine refuses (open 1, closed 1 and 2) follow the same arc positions."""
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    out = geom.resample_many(square[None], num, closed)[0]  # (num, 2)
    np.testing.assert_allclose(out, shapely_samples(square, num, closed), atol=1e-12)


def test_resample_many_bad_input_names_the_problem() -> None:
    pts = np.zeros((3, 5, 2))
    pts[:, :, 0] = np.arange(5)
    pts[1, 2, 1] = np.nan
    with pytest.raises(ValueError, match="row 1"):
        geom.resample_many(pts, 10)
    with pytest.raises(ValueError, match=r"\(N, n, 2\)"):
        geom.resample_many(np.zeros((5, 2)), 10)
    with pytest.raises(ValueError, match="n_out"):
        geom.resample_many(np.ones((1, 5, 2)), 0)


def test_points_at_lengths_and_arc_lengths_match_shapely() -> None:
    rng = np.random.default_rng(2)
    pts = np.cumsum(rng.normal(size=(15, 2)), axis=0)  # (15, 2)
    line = shapely.LineString(pts)
    cum = geom.arc_lengths(pts)  # (15,)
    assert cum[0] == 0.0 and cum[-1] == pytest.approx(line.length, rel=1e-12)
    ref = [0.0] + [shapely.LineString(pts[: k + 1]).length for k in range(1, 15)]
    np.testing.assert_allclose(cum, ref, rtol=1e-12)
    s = np.array([-3.0, 0.0, 0.37 * line.length, line.length, line.length + 5.0])
    ours = geom.points_at_lengths(pts, s)  # (5, 2)
    ref = shapely.get_coordinates(line.interpolate(np.clip(s, 0.0, line.length)))
    np.testing.assert_allclose(ours, ref, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# Chamfer distances


@pytest.mark.parametrize("backend", ["engine", "numpy"])
def test_chamfer_pairs_against_the_definition(backend: str) -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=(40, 30, 2)) * 20  # (40, 30, 2)
    b = a + rng.normal(size=(40, 25, 2)).mean(axis=1, keepdims=True) + rng.normal(size=(40, 30, 2))
    b = b[:, :25]  # (40, 25, 2): unequal sizes
    ours = geom.chamfer_pairs(a, b, backend)  # (40,)
    ref = [brute_chamfer(a[p], b[p]) for p in range(40)]
    np.testing.assert_allclose(ours, ref, atol=1e-12)
    assert geom.chamfer_pairs(a[:0], b[:0], backend).shape == (0,)


def test_chamfer_pairs_errors() -> None:
    with pytest.raises(ValueError, match="2 sets in a, 3 in b"):
        geom.chamfer_pairs(np.zeros((2, 4, 2)), np.zeros((3, 4, 2)))
    with pytest.raises(ValueError, match="backend"):
        geom.chamfer_pairs(np.zeros((1, 4, 2)), np.zeros((1, 4, 2)), "torch")
    with pytest.raises(ValueError, match=r"\(N, n, 2\)"):
        geom.chamfer_pairs(np.zeros((1, 4, 3)), np.zeros((1, 4, 2)))


def test_paired_nearest_sq_against_cdist() -> None:
    rng = np.random.default_rng(4)
    a = rng.normal(size=(6, 41, 2)) * 30 + 1e4  # far from the origin: centring matters
    b = rng.normal(size=(6, 17, 2)) * 30 + 1e4
    ab, ba = geom.paired_nearest_sq(a, b)  # (6, 41), (6, 17)
    for p in range(6):
        d = cdist(a[p], b[p]) ** 2  # (41, 17)
        np.testing.assert_allclose(ab[p], d.min(axis=1), atol=1e-8)
        np.testing.assert_allclose(ba[p], d.min(axis=0), atol=1e-8)


@pytest.mark.parametrize("n", [50, 1500])  # below and above geom.CLOUD_ENGINE_PAIRS
def test_cloud_chamfer_against_the_definition(n: int) -> None:
    rng = np.random.default_rng(5)
    a = rng.uniform(0, 300, size=(n, 2))  # (n, 2)
    b = rng.uniform(0, 300, size=(n - 7, 2))  # (n - 7, 2)
    assert (n * (n - 7) > geom.CLOUD_ENGINE_PAIRS) == (n == 1500)
    assert geom.cloud_chamfer(a, b) == pytest.approx(brute_chamfer(a, b), abs=1e-9)


@pytest.mark.parametrize("n", [5, 1500])
def test_cloud_chamfer_bad_input(n: int) -> None:
    a = np.ones((n, 2))
    with pytest.raises(ValueError):
        geom.cloud_chamfer(a, np.zeros((0, 2)))
    bad = a.copy()
    bad[-1, 0] = np.inf
    with pytest.raises(ValueError):
        geom.cloud_chamfer(a, bad)
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        geom.cloud_chamfer(a[None], a)


# ---------------------------------------------------------------------------------------------
# Point-to-segment distances


def test_point_to_segments_matches_shapely() -> None:
    rng = np.random.default_rng(6)
    pts = np.cumsum(rng.normal(size=(4, 9, 2)), axis=1)  # (4, 9, 2)
    sets = np.cumsum(rng.normal(size=(3, 6, 2)), axis=1)  # (3, 6, 2)
    closed = np.array([True, False, True])
    out = geom.point_to_segments(pts, geom.polyline_segments(sets, closed))  # (4, 3, 9)
    assert out.shape == (4, 3, 9)
    for j in range(3):
        shape = shapely.LinearRing(sets[j]) if closed[j] else shapely.LineString(sets[j])
        for a in range(4):
            ref = shapely.distance(shapely.points(pts[a]), shape)  # (9,)
            np.testing.assert_allclose(out[a, j], ref, atol=1e-9)


def test_point_to_segments_chunks_and_degenerate_segments() -> None:
    rng = np.random.default_rng(7)
    pts = rng.normal(size=(20, 50, 2)) * 10  # (20, 50, 2): B n m = 250,000, chunks of 8 rows
    sets = rng.normal(size=(100, 50, 2)) * 10  # (100, 50, 2)
    segs = geom.polyline_segments(sets, False)  # (100, 50, 2, 2)
    out = geom.point_to_segments(pts, segs)  # (20, 100, 50)
    for a, b in [(0, 0), (9, 57), (19, 99)]:
        ref = shapely.distance(shapely.points(pts[a]), shapely.LineString(sets[b]))
        np.testing.assert_allclose(out[a, b], ref, atol=1e-9)
    # a set of one repeated point: its segments are points
    dot = np.full((1, 3, 2), 2.0)
    d = geom.point_to_segments(np.array([[[2.0, 5.0]]]), geom.polyline_segments(dot, True))
    assert d[0, 0, 0] == pytest.approx(3.0)


def test_polyline_segments_layout_and_errors() -> None:
    pts = np.arange(12.0).reshape(2, 3, 2)  # (2, 3, 2)
    seg = geom.polyline_segments(pts, np.array([False, True]))  # (2, 3, 2, 2)
    np.testing.assert_array_equal(seg[0, 2], [pts[0, 2], pts[0, 2]])  # open: degenerate last
    np.testing.assert_array_equal(seg[1, 2], [pts[1, 2], pts[1, 0]])  # closed: closing edge
    np.testing.assert_array_equal(seg[:, :2, 1], pts[:, 1:])
    with pytest.raises(ValueError, match=r"\(B, m, 2, 2\)"):
        geom.point_to_segments(pts, pts)


def test_project_onto_polyline_matches_shapely() -> None:
    import shapely
    from icmapper.geom import project_onto_polyline

    rng = np.random.default_rng(3)
    for _ in range(20):
        line = np.cumsum(rng.normal(size=(int(rng.integers(2, 12)), 2)), axis=0)
        pts = rng.normal(size=(30, 2)) * 3
        d, s = project_onto_polyline(pts, line)
        ls = shapely.LineString(line)
        ref_d = shapely.distance(shapely.points(pts), ls)
        np.testing.assert_allclose(d, ref_d, atol=1e-9)
        # the arc length names a point at that distance (ties may pick another segment)
        at = shapely.line_interpolate_point(ls, s)
        np.testing.assert_allclose(shapely.distance(shapely.points(pts), at), ref_d, atol=1e-9)
    # ties: a point equidistant from two segments takes the earlier one (smaller arc length)
    v = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    _, s = project_onto_polyline(np.array([[3.0, -1.0]]), v, tie_tol=1e-9)
    assert s[0] == pytest.approx(2.0)
