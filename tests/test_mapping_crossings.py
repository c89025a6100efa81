"""The crossing merge rule (icmapper.mapping.crossings): aligned ring averages, complete views
averaged, cut views merged only while they reveal more of a crossing, noise that cancels instead
of widening the crossing."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper._icmap import GlobalMap
from icmapper.data.types import RANGE_60x30
from icmapper.geom import resample_many
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger, average_rings, is_complete


def _rect(cx: float, cy: float, w: float, h: float, n: int = 20) -> np.ndarray:
    """A w x h rectangle centred on (cx, cy) as a CCW ring of n points (first not repeated)."""
    corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2 + [cx, cy]
    ring = np.vstack([corners, corners[:1]])
    seg = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    d = np.linspace(0, cum[-1], n + 1)[:-1]
    return np.stack([np.interp(d, cum, ring[:, 0]), np.interp(d, cum, ring[:, 1])], -1)


def _area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * abs(float((x * np.roll(y, -1) - np.roll(x, -1) * y).sum()))


def _ring_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance of a point of ring ``a`` to ring ``b`` (b sampled every ~1 cm)."""
    dense = resample_many(np.asarray(b, np.float64)[None], 4000, True)[0]
    return float(np.linalg.norm(a[:, None] - dense[None], axis=-1).min(1).max())


def test_average_of_one_ring_in_any_start_and_direction_is_the_ring() -> None:
    ring = _rect(3.0, -2.0, 8.0, 4.0, 40)
    shifted = np.roll(ring, 13, axis=0)[::-1]  # another start, clockwise
    for w in (0.0, 0.3, 1.0):
        out = average_rings(ring, shifted, w)
        assert out.shape == (160, 2)
        assert _ring_distance(out, ring) < 0.02  # on the rectangle
        assert _ring_distance(ring, out) < 0.05  # corners cut by at most a few cm


def test_average_blends_the_aligned_shapes() -> None:
    small, large = _rect(0, 0, 4, 4, 160), np.roll(_rect(0, 0, 8, 8, 160), 7, axis=0)
    half = average_rings(small, large, 0.5)
    assert _area(half) == pytest.approx(36.0, rel=0.02)  # the 6 x 6 square between them
    assert np.abs(half).max() == pytest.approx(3.0, abs=0.05)
    assert _area(average_rings(small, large, 0.25)) == pytest.approx(25.0, rel=0.02)


def test_average_rings_rejects_bad_input() -> None:
    ring = _rect(0, 0, 4, 4)
    with pytest.raises(ValueError, match="weight"):
        average_rings(ring, ring, 1.5)
    with pytest.raises(ValueError, match="new ring must be"):
        average_rings(ring, ring[:2], 0.5)
    bad = ring.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="stored ring has NaN"):
        average_rings(bad, ring, 0.5)


def test_is_complete_at_the_range_edge() -> None:
    assert is_complete(_rect(0, 0, 6, 4), RANGE_60x30)
    assert not is_complete(_rect(28, 0, 6, 4), RANGE_60x30)  # reaches x = 31 > 30 - 1
    assert not is_complete(_rect(0, 13, 6, 4), RANGE_60x30)  # y = 15: on the edge
    assert is_complete(_rect(26.0, 0, 4, 4), RANGE_60x30)  # x = 28, 2 m inside


def test_complete_views_average_out_and_union_widens() -> None:
    """Twenty noisy complete views of one 10 x 4 m crossing: averaged, the stored crossing stays
    the true one; by union it grows with every view."""
    truth = _rect(0, 0, 10, 4, 40)
    gen = np.random.default_rng(0)
    maps = {rule: GlobalMap(smoothing=0.5, spacing=1.0) for rule in ("average", "union")}
    rules = {rule: CrossingMerger(rule, RANGE_60x30) for rule in maps}
    for rule, gm in maps.items():
        gm.insert_with_id(7, 0, truth, frame=0)
        rules[rule].inserted(7, truth)
    assert rules["average"].counts == {7: 1}
    for frame in range(1, 21):
        view = _rect(*gen.normal(0, 0.4, 2), 10 + gen.normal(0, 0.5), 4 + gen.normal(0, 0.5), 40)
        for rule, gm in maps.items():  # ego = world here: the pose is the identity
            assert rules[rule].merge(gm, 7, view, view, frame)
    averaged, union = maps["average"].get(7)[1], maps["union"].get(7)[1]
    assert maps["average"].info(7)["observations"] == 21
    assert rules["average"].counts == {7: 21}
    assert _area(averaged) == pytest.approx(40.0, rel=0.1)
    assert _ring_distance(averaged, truth) < 0.5
    assert _area(union) > 1.5 * 40.0  # every noisy view widened it


def test_cut_views_extend_a_crossing_only_while_they_reveal_it() -> None:
    """A crossing first seen cut at the range edge grows by union while a cut view shows more of
    it; the first complete view replaces what the cut views built; cut views after it are left
    out."""
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    rule = CrossingMerger("average", RANGE_60x30)
    first = _rect(27.5, 0, 5, 4)  # x 25..30: the part in range of a crossing reaching x = 33
    gm.insert_with_id(1, 0, first, frame=0)
    rule.inserted(1, first)
    assert rule.counts == {1: 0}  # cut by the edge: not complete
    # seen again 2 m on (ego = world - 2): x 21..32, cut at ego x 30; 6 of its 11 m new -> union
    more_world = _rect(26.5, 0, 11, 4)
    more_ego = more_world - [2.0, 0.0]
    assert rule.merge(gm, 1, more_world, more_ego, 1)
    assert _area(gm.get(1)[1]) == pytest.approx(44.0, rel=0.05)
    # the same part again, shifted by 0.3 m: nearly all inside the stored crossing -> left out
    before = gm.get(1)[1].copy()
    assert not rule.merge(gm, 1, more_world + [0.3, 0.2], more_ego + [0.3, 0.2], 2)
    np.testing.assert_array_equal(gm.get(1)[1], before)
    assert gm.info(1)["observations"] == 2  # a view left out is not an observation
    # seen whole 6 m on (ego x 15..27): replaces the cut views' crossing
    full_world = _rect(27.0, 0, 12, 4, 60)
    full_ego = full_world - [6.0, 0.0]
    assert rule.merge(gm, 1, full_world, full_ego, 3)
    assert _ring_distance(gm.get(1)[1], full_world) < 0.05
    assert rule.counts == {1: 1}
    # a cut view that would add a lot is left out once the crossing was seen whole
    assert not rule.merge(gm, 1, _rect(35.0, 0, 12, 4), _rect(30.0, 0, 12, 4), 4)
    assert _ring_distance(gm.get(1)[1], full_world) < 0.05
    # the next complete view is averaged with weight 1/2
    shifted = full_world + [0.0, 1.0]
    assert rule.merge(gm, 1, shifted, full_ego + [0.0, 1.0], 5)
    assert _ring_distance(gm.get(1)[1], full_world + [0.0, 0.5]) < 0.05
    assert rule.counts == {1: 2}


def test_noisy_cut_views_do_not_widen_a_crossing() -> None:
    """A crossing always cut by the side of the range (it reaches y = 17): twenty noisy views
    leave it about as large as the first, where union grows it by more than half."""
    gen = np.random.default_rng(1)
    maps = {rule: GlobalMap(smoothing=0.5, spacing=1.0) for rule in ("average", "union")}
    rules = {rule: CrossingMerger(rule, RANGE_60x30) for rule in maps}
    first = _rect(0, 10.0, 4, 10, 40)  # y 5..15 in range: on the edge
    for rule, gm in maps.items():
        gm.insert_with_id(3, 0, first, frame=0)
        rules[rule].inserted(3, first)
    for frame in range(1, 21):
        view = _rect(*gen.normal([0, 10], 0.4), 4 + gen.normal(0, 0.5), 10, 40)
        for rule, gm in maps.items():
            rules[rule].merge(gm, 3, view, view, frame)
    assert rules["average"].counts == {3: 0}
    assert _area(maps["average"].get(3)[1]) < 1.2 * 40.0
    assert _area(maps["union"].get(3)[1]) > 1.5 * 40.0


def test_a_partial_view_inside_the_range_does_not_replace_a_crossing() -> None:
    """A far crosswalk built from cut views (12 x 4 m) and then seen inside the range only in part
    (3 x 4 m of its middle, under ``PARTIAL_AREA`` of it): the partial view is handled as a cut
    one, so the crossing is kept; a view of most of it (10 x 4 m) is complete and replaces it;
    once seen whole, a partial view does not shrink the average."""
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    rule = CrossingMerger("average", RANGE_60x30)
    built = _rect(20.0, 10.0, 12, 4, 60)
    gm.insert_with_id(1, 0, built, frame=0)
    rule.inserted(1, built + [0.0, 5.0])  # ego y 13..17: cut by the side of the range
    assert rule.counts == {1: 0}
    middle = _rect(20.0, 10.0, 3, 4, 40)
    assert not rule.merge(gm, 1, middle, middle - [10.0, 0.0], 1)  # inside the range, partial
    assert _ring_distance(gm.get(1)[1], built) < 0.05 and rule.counts == {1: 0}
    most = _rect(20.5, 10.0, 10, 4, 60)
    assert rule.merge(gm, 1, most, most - [10.0, 0.0], 2)  # 10 / 12 of it: complete
    assert _ring_distance(gm.get(1)[1], most) < 0.05 and rule.counts == {1: 1}
    assert not rule.merge(gm, 1, middle, middle - [10.0, 0.0], 3)
    assert _ring_distance(gm.get(1)[1], most) < 0.05 and rule.counts == {1: 1}


def test_a_collapsed_view_is_left_out() -> None:
    """A complete view enclosing (almost) no area does not replace or move the crossing; a
    crossing inserted from such a view is replaced by the first good complete view."""
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    rule = CrossingMerger("average", RANGE_60x30)
    good = _rect(0, 0, 8, 4, 40)
    gm.insert_with_id(1, 0, good, frame=0)
    rule.inserted(1, good)
    flat = _rect(0, 0, 8, 0.05, 40)  # 0.4 m^2
    assert not rule.merge(gm, 1, flat, flat, 1)
    assert _ring_distance(gm.get(1)[1], good) < 0.05 and rule.counts == {1: 1}
    gm.insert_with_id(2, 0, flat + [20, 0], frame=0)
    rule.inserted(2, flat + [20, 0])
    assert rule.counts[2] == 0  # not seen whole
    assert rule.merge(gm, 2, good + [20, 0], good + [20, 0], 1)
    assert _area(gm.get(2)[1]) == pytest.approx(32.0, rel=0.02)


def test_crossing_merger_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="crossing merge must be"):
        CrossingMerger("mean", RANGE_60x30)
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    ring = _rect(0, 0, 6, 4)
    gm.insert_with_id(1, 0, ring, frame=0)
    rule = CrossingMerger("average", RANGE_60x30)
    rule.inserted(1, ring)
    with pytest.raises(KeyError):
        rule.merge(gm, 99, ring, ring, 1)
    bad = ring.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"\(ego\) has NaN"):
        rule.merge(gm, 1, ring, bad, 1)  # NaN in the ego frame is not a cut view
    with pytest.raises(ValueError, match=r"\(world\) has NaN"):
        rule.merge(gm, 1, bad, ring, 1)
    with pytest.raises(ValueError, match="differ"):
        rule.merge(gm, 1, ring, ring[:-1], 1)
    with pytest.raises(ValueError, match=r"must be \(n >= 3, 2\)"):
        rule.merge(gm, 1, ring[:2], ring[:2], 1)
    assert gm.info(1)["observations"] == 1  # nothing merged
    with pytest.raises(ValueError, match=">= 0"):
        rule.reset({1: -1})
    rule.reset({4: 2})
    assert rule.counts == {4: 2}
    rule.reset()
    assert rule.counts == {}


def test_mapper_config_names_the_crossing_rule() -> None:
    assert MapperConfig().crossing_merge == "average"
    assert MapperConfig.from_dict({"crossing_merge": "union"}).crossing_merge == "union"
    with pytest.raises(ValueError, match="crossing_merge"):
        MapperConfig(crossing_merge="mean")


def test_a_new_crossing_confirms_at_once_unless_a_sliver_at_the_range_edge() -> None:
    """``CrossingMerger.confirmable``: a whole view, or a cut view enclosing ``CONFIRM_AREA``, may
    enter the map at its first sighting; a sliver cut by the range edge may not."""
    from icmapper.mapping.crossings import CONFIRM_AREA

    cm = CrossingMerger("average", RANGE_60x30)
    assert cm.confirmable(_rect(0, 0, 3, 8))  # whole, 24 m^2
    assert cm.confirmable(_rect(0, 0, 1, 1))  # whole however small
    cut = _rect(28.5, 0, 3, 8)  # 27-30 m: cut by the front edge, 24 m^2
    assert not is_complete(cut, RANGE_60x30) and _area(cut) >= CONFIRM_AREA
    assert cm.confirmable(cut)
    sliver = _rect(29.0, 14.0, 2.6, 1.2)  # the corner of the range
    assert not cm.confirmable(sliver)
