"""The crossing merge rule (icmapper.mapping.crossings): aligned ring averages, complete views
averaged and cut views extended, noise that cancels instead of widening the crossing."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper._icmap import GlobalMap
from icmapper.data.types import RANGE_60x30
from icmapper.geom import resample_many
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import average_rings, is_complete, merge_crossing


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
    for gm in maps.values():
        gm.insert_with_id(7, 0, truth, frame=0)
    for frame in range(1, 21):
        view = _rect(*gen.normal(0, 0.4, 2), 10 + gen.normal(0, 0.5), 4 + gen.normal(0, 0.5), 40)
        for rule, gm in maps.items():  # ego = world here: the pose is the identity
            merge_crossing(gm, 7, view, view, RANGE_60x30, frame, rule)
    averaged, union = maps["average"].get(7)[1], maps["union"].get(7)[1]
    assert maps["average"].info(7)["observations"] == 21
    assert _area(averaged) == pytest.approx(40.0, rel=0.1)
    assert _ring_distance(averaged, truth) < 0.5
    assert _area(union) > 1.5 * 40.0  # every noisy view widened it


def test_a_view_cut_by_the_range_edge_extends_by_union() -> None:
    """A crossing first seen cut at the range edge grows to its full extent by union once the
    rest comes into view; complete views after that average."""
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    cut = _rect(25.0, 0, 8, 4)  # x 21..29: the part in range of a crossing reaching x = 33
    gm.insert_with_id(1, 0, cut, frame=0)
    ego_full = _rect(20.0, 0, 12, 4)  # seen whole after driving on: x 14..26 in the ego frame
    world_full = ego_full + [7.0, 0.0]  # x 21..33 in the world
    edge_ego = _rect(25.0, 0, 12, 4)  # the same crossing cut at the edge (x 19..31)
    merge_crossing(gm, 1, world_full, edge_ego, RANGE_60x30, 1, "average")  # cut: union
    assert _area(gm.get(1)[1]) == pytest.approx(48.0, rel=0.05)
    merge_crossing(gm, 1, world_full, ego_full, RANGE_60x30, 2, "average")  # complete: mean
    stored = gm.get(1)[1]
    assert _ring_distance(stored, _rect(27.0, 0, 12, 4, 60)) < 0.3
    with pytest.raises(ValueError, match="crossing merge must be"):
        merge_crossing(gm, 1, world_full, ego_full, RANGE_60x30, 3, "mean")
    with pytest.raises(KeyError):
        merge_crossing(gm, 99, world_full, ego_full, RANGE_60x30, 3, "average")


def test_mapper_config_names_the_crossing_rule() -> None:
    assert MapperConfig().crossing_merge == "average"
    assert MapperConfig.from_dict({"crossing_merge": "union"}).crossing_merge == "union"
    with pytest.raises(ValueError, match="crossing_merge"):
        MapperConfig(crossing_merge="mean")
