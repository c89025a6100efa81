"""The engine's polyline splice (``geom.splice_polyline``, ``GlobalMap.splice``) against the
numpy implementation it replaced (kept here as the reference), on random cases and the edge
cases of the orientation rule; bad input raises and leaves the map unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper import GlobalMap
from icmapper.geom import project_onto_polyline, resample_spacing, splice_polyline


def _orient_like_ref(stored: np.ndarray, new: np.ndarray) -> np.ndarray:
    _, s = project_onto_polyline(new, stored)  # (q,)
    length = float(np.sum(np.linalg.norm(np.diff(stored, axis=0), axis=1)))
    tol = 1e-6 * max(length, 1.0)
    if s[-1] - s[0] > tol:
        return new
    if s[0] - s[-1] > tol:
        return new[::-1]
    if s.mean() >= length / 2:
        forward = np.linalg.norm(new[0] - stored[-1]) <= np.linalg.norm(new[-1] - stored[-1])
    else:
        forward = np.linalg.norm(new[-1] - stored[0]) <= np.linalg.norm(new[0] - stored[0])
    return new if forward else new[::-1]


def splice_ref(stored: np.ndarray, new: np.ndarray, overlap: float) -> np.ndarray:
    """The former numpy ``mapping.splice.splice_polyline``."""
    p = np.asarray(stored, dtype=np.float64)
    q = _orient_like_ref(p, np.asarray(new, dtype=np.float64))
    covered = project_onto_polyline(p, q)[0] <= overlap  # (m,)
    _, s_q = project_onto_polyline(q[[0, -1]], p)  # (2,)
    s_p = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    before = p[(s_p <= s_q[0]) & ~covered]
    after = p[(s_p > s_q[1]) & ~covered]
    return np.concatenate([before, q, after])


def _random_line(gen: np.random.Generator, n: int, origin: np.ndarray) -> np.ndarray:
    steps = gen.normal(0, 1, (n - 1, 2)) + gen.normal(0, 2, 2)  # a wandering line with a drift
    return origin + np.concatenate([[np.zeros(2)], np.cumsum(steps, axis=0)])


def test_engine_splice_matches_the_numpy_reference() -> None:
    gen = np.random.default_rng(0)
    for case in range(400):
        stored = _random_line(gen, int(gen.integers(2, 30)), gen.normal(0, 3, 2))
        if case % 3 == 0:  # a noisy copy of a stretch of it, either direction
            i, j = sorted(gen.choice(len(stored), 2, replace=False))
            new = stored[i : j + 1] + gen.normal(0, 0.3, (j - i + 1, 2))
            new = new if case % 2 else new[::-1]
            if len(new) < 2:
                new = np.vstack([new, new[-1:] + 1.0])
        else:
            new = _random_line(
                gen, int(gen.integers(2, 20)), stored[int(gen.integers(len(stored)))]
            )
        overlap = float(gen.choice([0.0, 0.5, 1.0, 3.0]))
        got, want = splice_polyline(stored, new, overlap), splice_ref(stored, new, overlap)
        assert got.shape == want.shape, case
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9, err_msg=f"case {case}")


def test_orientation_edge_cases_match() -> None:
    stored = np.array([[0.0, 0.0], [10.0, 0.0]])
    for new in (
        np.array([[12.0, 3.0], [12.0, 8.0]]),  # beyond the end, both ends project to it
        np.array([[12.0, 8.0], [12.0, 3.0]]),
        np.array([[-2.0, 8.0], [-2.0, 3.0]]),  # before the start
        np.array([[-2.0, 3.0], [-2.0, 8.0]]),
        np.array([[5.0, 1.0], [5.0, 4.0]]),  # across the middle, perpendicular
    ):
        for overlap in (0.0, 1.0, 5.0):
            np.testing.assert_allclose(
                splice_polyline(stored, new, overlap), splice_ref(stored, new, overlap), atol=1e-12
            )


def test_map_splice_is_replace_of_the_spliced_polyline() -> None:
    gen = np.random.default_rng(1)
    for _ in range(30):
        stored = _random_line(gen, 12, np.zeros(2))
        new = stored[3:8] + gen.normal(0, 0.3, (5, 2))
        a, b = GlobalMap(0.5, 1.0), GlobalMap(0.5, 1.0)
        for m in (a, b):
            m.insert_with_id(4, 2, stored, frame=0)
        a.splice(4, new, 0.5, frame=2)
        b.replace(4, splice_ref(b.get(4)[1], new, 0.5), frame=2)
        np.testing.assert_allclose(a.get(4)[1], b.get(4)[1], atol=1e-9)
        assert a.info(4) == b.info(4)
    # the stored geometry is resampled at the map's spacing, as on insert
    m = GlobalMap(0.5, 2.0)
    m.insert_with_id(1, 1, np.array([[0.0, 0.0], [20.0, 0.0]]))
    m.splice(1, np.array([[4.0, 0.2], [8.0, 0.2]]), 0.5, frame=1)
    want = resample_spacing(
        splice_polyline(resample_spacing(np.array([[0.0, 0.0], [20.0, 0.0]]), 2.0),
                        np.array([[4.0, 0.2], [8.0, 0.2]]), 0.5),
        2.0,
    )  # fmt: skip
    np.testing.assert_allclose(m.get(1)[1], want, atol=1e-12)


def test_splice_rejects_bad_input_and_keeps_the_map() -> None:
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    with pytest.raises(ValueError, match="new polyline"):
        splice_polyline(line, line[:1], 0.5)
    with pytest.raises(ValueError, match="stored polyline"):
        splice_polyline(line[:1], line, 0.5)
    with pytest.raises(ValueError, match="non-finite"):
        splice_polyline(line, np.array([[1.0, np.nan], [2.0, 0.0]]), 0.5)
    with pytest.raises(ValueError, match="overlap"):
        splice_polyline(line, line, -0.1)
    with pytest.raises(ValueError, match="overlap"):
        splice_polyline(line, line, float("inf"))
    m = GlobalMap()
    m.insert_with_id(1, 1, line, frame=0)
    m.insert_with_id(2, 0, np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0]]), frame=0)
    before = (m.get(1)[1].copy(), m.info(1))
    for bad in (np.full((3, 2), np.nan), line[:1], np.array([[1e9, 0.0], [0.0, 0.0]])):
        with pytest.raises(ValueError):
            m.splice(1, bad, 0.5, frame=1)
    with pytest.raises(ValueError, match="overlap"):
        m.splice(1, line, -1.0, frame=1)
    np.testing.assert_array_equal(m.get(1)[1], before[0])
    assert m.info(1) == before[1]
    with pytest.raises(ValueError, match="crossing"):
        m.splice(2, line, 0.5, frame=1)
    with pytest.raises(KeyError):
        m.splice(99, line, 0.5, frame=1)


def test_a_line_does_not_fold_onto_itself() -> None:
    """A stored line whose end hooks off by 0.9 m, and a view that runs on past it (sim:val:4,
    sim-10041-1, frame 16): the store's splice and merge of a divider or a kerb end the stored
    line where it comes back beside the view, instead of joining the hook's tip behind the view's
    end (a line folded back on itself, drawn longer by every later view). A kerb around a median
    (its other side 1.4 m away) keeps its U-turn: the kerbs' fold gap is 1.0 m, the lane lines'
    1.5 m."""
    hooked = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [20.0, -0.9]])
    median = np.array([[0.0, 0.0], [20.0, 0.0], [20.5, -0.7], [20.0, -1.4], [8.0, -1.4]])
    view = np.array([[26.0, 0.1], [18.0, 0.1], [12.0, 0.1]])
    for merge in ("splice", "merge"):
        m = GlobalMap(0.5, 0.5)
        m.insert_with_id(1, 1, hooked, frame=0)  # a divider
        m.insert_with_id(2, 2, hooked, frame=0)  # a boundary
        m.insert_with_id(3, 2, median, frame=0)  # a kerb around a median
        m.insert_with_id(4, 1, median, frame=0)  # a divider drawn so: folded
        for i in (1, 2, 3, 4):
            if merge == "splice":
                m.splice(i, view, 0.5, frame=1)
            else:
                m.merge(i, view, frame=1)
        for i in (1, 2):
            line = m.get(i)[1]
            assert np.all(np.diff(line[:, 0]) > -1e-9), (merge, i)  # never turns back
            assert line[-1, 0] == pytest.approx(26.0, abs=0.3), (merge, i)
            assert line[0, 0] == pytest.approx(0.0)
        kerb, divider = m.get(3)[1], m.get(4)[1]
        assert kerb[:, 1].min() < -1.3 and kerb[-1, 0] < 10.0, merge  # around the median
        assert divider[:, 1].min() > -1.3, merge  # a lane line 1.4 m beside itself is a fold


def _two_kerbs_one_view(
    a: np.ndarray, b: np.ndarray, view: np.ndarray
) -> list[tuple[str, tuple[np.ndarray, np.ndarray]]]:
    """Kerbs ``a`` and ``b`` stored, then ``view`` spliced into each, and merged by curve fit into
    each in a fresh map: [(how, (a after, b after))] for "splice" and "merge"."""
    out = []
    for merge in ("splice", "merge"):
        m = GlobalMap(0.5, 0.5)
        m.insert_with_id(1, 2, a, frame=0)
        m.insert_with_id(2, 2, b, frame=0)
        for i in (1, 2):
            if merge == "splice":
                m.splice(i, view, 0.5, frame=1)
            else:
                m.merge(i, view, frame=1)
        out.append((merge, (m.get(1)[1], m.get(2)[1])))
    return out


def test_a_fold_cut_is_bounded() -> None:
    """A kerb that comes back beside a view and then goes on far from it (sim:test:4,
    sim-10158-2: a view rounding a corner met a long kerb twice, and the unbounded cut dropped
    120 m of it) keeps that side whole; a kerb whose end folds back along the view loses the
    fold."""
    onward = np.array([[0.0, 0.0], [20.0, 0.0], [20.4, -0.4], [14.0, -0.8], [14.0, -60.0]])
    folded = np.array([[0.0, 0.0], [20.0, 0.0], [20.4, -0.4], [14.0, -0.8], [6.0, -0.8]])
    view = np.array([[4.0, 0.0], [16.0, 0.0]])
    for merge, (kept, cut) in _two_kerbs_one_view(onward, folded, view):
        assert kept[:, 1].min() < -59.0, merge  # the kerb going on is kept
        back = cut
        back = back[back[:, 1] < -0.3]  # the hook's points, off the view's line
        assert back[:, 0].min() > 14.0, merge  # the fold back along the view is cut


def test_a_kerb_drawn_past_a_corner_loses_the_overshoot() -> None:
    """A kerb the detector drew a few metres past a corner and a view that turns the corner: the
    overshoot (within ``KERB_SLACK``, 8 m, of what a cut may drop off the line) is cut, not
    joined behind the view's end, where every later view along the new side drew the fold longer
    (sim:val:12, sim-10016-7: 143 m)."""
    stored = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [20.8, 0.0], [23.0, 0.0], [26.0, 0.0]])
    view = np.array([[4.0, 0.1], [12.0, 0.1], [20.2, 0.2], [20.4, 5.0], [20.4, 15.0]])
    longer = np.vstack([stored, [[40.0, 0.0]]])  # 20 m past the corner: a kerb going on
    for merge, (kerb, kept) in _two_kerbs_one_view(stored, longer, view):
        assert kerb[:, 0].max() < 21.0 and kerb[-1, 1] > 14.0, merge  # ends where the view does
        assert kept[:, 0].max() > 39.0, merge  # the kerb going on is kept


def test_a_view_across_the_seam_of_a_loop_keeps_the_loop() -> None:
    """A kerb around a block whose end has come back to its start, and a view around the corner
    where the two meet: spliced or merged whole, the view replaced the stretch between its ends'
    projections, the whole loop (sim:val:32, sim-10082-27: 360 m cut to 38 m in one frame).
    The store's line rules merge each piece of the view into its own stretch."""
    ring = np.array([[0.0, 2.0], [0.0, 20.0], [40.0, 20.0], [40.0, 0.0], [2.0, 0.0]])
    view = np.array([[6.0, 0.1], [3.0, 0.1], [0.1, 0.1], [0.1, 3.0], [0.1, 6.0]])
    for merge in ("splice", "merge"):
        m = GlobalMap(0.5, 0.5)
        m.insert_with_id(1, 2, ring, frame=0)
        if merge == "splice":
            m.splice(1, view, 0.5, frame=1)
        else:
            m.merge(1, view, frame=1)
        kerb = m.get(1)[1]
        length = float(np.linalg.norm(np.diff(kerb, axis=0), axis=1).sum())
        assert length > 100.0, (merge, length)  # 114 m of kerb stay
        assert np.abs(kerb[:, 1] - 20.0).min() < 0.3, merge  # the far side is kept
