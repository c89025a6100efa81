"""Property tests (hypothesis) of the engine's Python surface, under a memory limit: for any input
a call returns a finite, well-formed result or raises ValueError / TypeError / KeyError — never a
non-finite value from finite input, a panic, an abort or an unbounded allocation. Where an
independent oracle exists (shapely, numpy) the values are compared. A bounded run is part of the
suite (``ICMAPPER_HYPOTHESIS_EXAMPLES`` examples per property, default 150); a longer run:
``ICMAPPER_HYPOTHESIS_EXAMPLES=20000 .venv/bin/python -m pytest tests/test_geom_properties.py``.
"""

from __future__ import annotations

import os
import resource
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from icmapper import geom
from icmapper._icmap import GlobalMap

EXAMPLES = int(os.environ.get("ICMAPPER_HYPOTHESIS_EXAMPLES", "150"))
SETTINGS = settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    derandomize=True,  # the same examples every run (the suite is deterministic)
)
#: Errors a bad input may raise (anything else, or a crash, fails the property).
CLEAN = (ValueError, TypeError, KeyError, OverflowError)

#: Any float: normal, tiny, huge, denormal, zero, inf, nan.
ANY = st.floats(allow_nan=True, allow_infinity=True, width=64)
#: Coordinates of a map frame in metres (the engine's supported domain is far larger).
METRES = st.floats(-1e5, 1e5, allow_nan=False, allow_infinity=False)


def _points(elements: st.SearchStrategy[float], min_n: int = 0, max_n: int = 30):
    return hnp.arrays(
        np.float64, st.tuples(st.integers(min_n, max_n), st.just(2)), elements=elements
    )


@pytest.fixture(autouse=True)
def memory_limit() -> Iterator[None]:
    """The process may grow by 2 GiB at most while a property runs (an unbounded allocation
    fails cleanly with MemoryError inside the engine call instead of taking the machine)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm", encoding="ascii") as fh:
        vm = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    limit = vm + 2 * 2**30
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _finite(a: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(a)))


@SETTINGS
@given(pts=_points(ANY), n=st.integers(-5, 10**13), closed=st.booleans())
def test_resample_any_input(pts: np.ndarray, n: int, closed: bool) -> None:
    try:
        out = geom.resample(pts, n, closed=closed)
    except CLEAN:
        return
    assert out.shape == (n, 2) and _finite(out) and _finite(pts)


@SETTINGS
@given(pts=_points(METRES, 2), n=st.integers(2, 400))
def test_resample_keeps_the_ends_and_the_length(pts: np.ndarray, n: int) -> None:
    """n points on the polyline: its two ends, evenly spaced along it (every point at arc length
    k L / (n - 1) of the input, found by numpy interpolation), so the resampled polyline is
    never longer than the input and its points are in order along it."""
    try:
        out = geom.resample(pts, n)
    except ValueError:  # degenerate (zero-length) input
        assert np.allclose(pts, pts[0]) or len(np.unique(pts, axis=0)) < 2
        return
    assert out.shape == (n, 2)
    np.testing.assert_allclose(out[[0, -1]], pts[[0, -1]], atol=1e-6)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])  # (m,)
    t = np.linspace(0.0, s[-1], n)  # (n,) the even arc lengths
    want = np.stack([np.interp(t, s, pts[:, 0]), np.interp(t, s, pts[:, 1])], axis=1)  # (n, 2)
    scale = max(1.0, float(np.abs(pts).max()))
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-9 * scale + 1e-9 * s[-1])
    length = float(np.linalg.norm(np.diff(out, axis=0), axis=1).sum())
    assert length <= s[-1] * (1 + 1e-9) + 1e-9 * scale


@SETTINGS
@given(a=_points(ANY, 0, 12), b=_points(ANY, 0, 12))
def test_chamfer_any_input(a: np.ndarray, b: np.ndarray) -> None:
    try:
        d = geom.chamfer_distance(a, b)
    except CLEAN:
        return
    assert np.isfinite(d) and d >= 0 and _finite(a) and _finite(b)


@SETTINGS
@given(a=_points(METRES, 1, 15), b=_points(METRES, 1, 15))
def test_chamfer_matches_numpy(a: np.ndarray, b: np.ndarray) -> None:
    d = np.linalg.norm(a[:, None] - b[None], axis=-1)
    ref = (d.min(1).mean() + d.min(0).mean()) / 2
    got = geom.chamfer_distance(a, b)
    assert got == pytest.approx(ref, rel=1e-9, abs=1e-9)
    assert geom.chamfer_distance(b, a) == pytest.approx(got, rel=1e-12, abs=1e-12)


@SETTINGS
@given(
    ring=_points(ANY, 0, 10),
    pose=st.tuples(ANY, ANY, ANY),
    half=st.tuples(ANY, ANY),
    closed=st.booleans(),
)
def test_clip_any_input(ring: np.ndarray, pose: tuple, half: tuple, closed: bool) -> None:
    try:
        pieces = geom.clip_to_patch(ring, pose, half, closed=closed)
    except CLEAN:
        return
    for p in pieces:
        assert p.ndim == 2 and p.shape[1] == 2 and _finite(p)


@SETTINGS
@given(rings=st.lists(_points(ANY, 0, 8), max_size=3))
def test_union_any_input(rings: list[np.ndarray]) -> None:
    try:
        out = geom.polygon_union(rings)
    except CLEAN:
        return
    for r in out:
        assert r.ndim == 2 and r.shape[1] == 2 and _finite(r)


@SETTINGS
@given(
    centre=st.tuples(METRES, METRES),
    squares=st.lists(
        st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(0.5, 10)),
        min_size=1,
        max_size=4,
    ),
)
@example(centre=(0.0, 0.0), squares=[(0, 1.5, 1), (1.5, 0, 1), (0, -1.5, 1), (-1.5, 0, 1)])
@example(  # two rings of equal area, far from the origin (found by hypothesis)
    centre=(46964.0, 770.0),
    squares=[(0.0, 0.0, 1.0), (0.0, 0.0, 1.0), (6.0, 1.0, 1.0), (9.0, 0.0, 1.2919593992350635)],
)
def test_union_matches_shapely_ring_by_ring(centre: tuple, squares: list) -> None:
    """As test_geom_functions.test_polygon_union_matches_shapely: one outer ring per polygon of
    shapely's union, counter-clockwise, largest first, each covering its polygon's exterior
    (holes included: the engine drops them, so each ring's area is the exterior's and the holes'
    area is what the rings hold beyond shapely's union; the explicit example has a hole)."""
    import shapely

    rings = [
        np.array([[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h]]) + centre
        for x, y, h in squares
    ]
    out = geom.polygon_union(rings)
    ref = shapely.union_all([shapely.Polygon(r) for r in rings])
    ref_polys = list(getattr(ref, "geoms", [ref]))
    assert len(out) == len(ref_polys)
    got = [shapely.Polygon(r) for r in out]
    assert all(g.exterior.is_ccw for g in got)
    areas = [g.area for g in got]  # largest first; rings of equal area (to the engine's
    # snapping grid, ~1e-9 relative) may come in either order
    assert all(a >= b - 1e-7 * max(1.0, b) for a, b in zip(areas, areas[1:], strict=False))
    matched = set()
    for p in ref_polys:
        outer = shapely.Polygon(p.exterior)
        # each polygon of shapely's union has its own ring: the one it differs least from (the
        # grid the engine's boolean ops snap to moves vertices by ~1e-9 relative)
        k = min(range(len(got)), key=lambda j: got[j].symmetric_difference(outer).area)
        matched.add(k)
        tol = 1e-7 * max(1.0, outer.area)
        assert got[k].symmetric_difference(outer).area <= tol
        assert got[k].area == pytest.approx(outer.area, rel=1e-7)
        holes = sum(shapely.Polygon(h).area for h in p.interiors)
        assert got[k].area - holes == pytest.approx(p.area, rel=1e-7, abs=tol)
    assert len(matched) == len(out)


@SETTINGS
@given(
    cls=st.integers(-3, 5),
    pts=_points(ANY, 0, 10),
    frame=st.integers(-(2**70), 2**70),
    smoothing=ANY,
    spacing=ANY,
)
def test_globalmap_any_input(cls: int, pts: np.ndarray, frame: int, smoothing: float,
                             spacing: float) -> None:  # fmt: skip
    try:
        m = GlobalMap(smoothing=smoothing, spacing=spacing)
    except CLEAN:
        return
    assert np.isfinite(m.smoothing) and m.smoothing >= 0 and np.isfinite(m.spacing)
    try:
        i = m.insert(cls, pts, frame=frame)
    except CLEAN:
        assert len(m) == 0
        return
    c, stored = m.get(i)
    assert c == cls and _finite(stored) and len(m) == 1
    try:
        m.merge(i, pts[::-1], frame=frame)
    except CLEAN:
        pass
    assert _finite(m.get(i)[1])
    try:
        ids, classes, sampled, mask = m.sample_patch((0.0, 0.0, 0.0), (30.0, 15.0), n_points=20)
    except CLEAN:
        return
    assert sampled.shape == (len(ids), 20, 2) and _finite(sampled)
