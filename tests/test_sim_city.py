"""Synthetic cities: determinism, splits, instance validity, lane graph."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data import MapClass
from icmapper.data.sim import CITY_SEEDS, generate_city
from shapely.geometry import Polygon


def _signature(world) -> list[tuple[int, int, str, bytes]]:
    return [(m.id, int(m.cls), m.style, m.points.tobytes()) for m in world.instances]


def test_same_seed_same_city_and_different_seeds_differ() -> None:
    a, b, c = generate_city(10_001), generate_city(10_001), generate_city(10_002)
    assert _signature(a) == _signature(b)
    assert sorted(a.lanes) == sorted(b.lanes)
    assert _signature(a) != _signature(c)


def test_split_ranges_disjoint() -> None:
    sets = {k: set(v) for k, v in CITY_SEEDS.items()}
    assert set(sets) == {"train", "val", "test"}
    assert (
        not sets["train"] & sets["val"]
        and not sets["train"] & sets["test"]
        and not sets["val"] & sets["test"]
    )


@pytest.mark.parametrize("seed", [0, 17, 10_050])
def test_instances_valid(seed: int) -> None:
    world = generate_city(seed)
    ids = [m.id for m in world.instances]
    assert len(ids) == len(set(ids))
    classes = {m.cls for m in world.instances}
    assert classes == {MapClass.PED_CROSSING, MapClass.DIVIDER, MapClass.BOUNDARY}
    for m in world.instances:
        assert isinstance(m.cls, MapClass)
        assert m.points.ndim == 2 and m.points.shape[1] == 2 and m.points.shape[0] >= 2
        assert np.all(np.isfinite(m.points))
        assert m.style
        assert m.closed == (m.cls == MapClass.PED_CROSSING)
        if m.closed:
            assert m.points.shape[0] >= 4
            assert not np.allclose(m.points[0], m.points[-1])  # ring without a repeated point
            poly = Polygon(m.points)
            assert poly.is_valid and poly.area > 5.0
    # Markings span a few hundred metres, dividers come in several styles.
    styles = {m.style for m in world.instances if m.cls == MapClass.DIVIDER}
    assert len(styles) >= 2
    ext = np.ptp(np.concatenate([m.points for m in world.instances]), axis=0)
    assert np.all(ext > 250) and np.all(ext < 700)


@pytest.mark.parametrize("seed", [3, 10_100])
def test_lane_graph_connected_and_inside_drivable(seed: int) -> None:
    world = generate_city(seed)
    assert world.lanes and world.drivable
    area = Polygon(world.drivable[0]).buffer(0)
    for p in world.drivable[1:]:
        area = area.union(Polygon(p).buffer(0))
    for lane in world.lanes.values():
        assert lane.successors, f"lane {lane.id} has no successor"
        assert all(s in world.lanes for s in lane.successors)
        # a successor starts where its predecessor ends
        for s in lane.successors:
            assert np.linalg.norm(world.lanes[s].centerline[0] - lane.centerline[-1]) < 1e-6
        mid = lane.centerline[len(lane.centerline) // 2]
        assert area.buffer(0.5).contains(Polygon([mid, mid + 0.01, mid + [0, 0.01]]))


def test_bad_seed() -> None:
    with pytest.raises(ValueError, match="seed"):
        generate_city(-1)
    with pytest.raises(TypeError, match="seed"):
        generate_city("3")  # type: ignore[arg-type]


def _digest(seed: int, varied: bool = False, junctions: bool = False) -> str:
    import hashlib

    h = hashlib.sha256()
    w = generate_city(seed, varied, junctions)
    for m in w.instances:
        h.update(np.asarray(m.points, np.float64).tobytes())
        h.update(f"{m.id} {int(m.cls)} {m.style}".encode())
    return h.hexdigest()[:16]


def test_varied_cities(monkeypatch: pytest.MonkeyPatch) -> None:
    """The real-road variety (domain randomisation) draws from its own stream, so the plain
    cities (the benchmark's) stay as they were; it gives wider roads with fewer dividers
    (shoulders and unmarked lanes), deterministically."""
    from icmapper.data.sim import city

    assert _digest(6037, varied=True) == _digest(6037, varied=True) != _digest(6037)
    with monkeypatch.context() as m:  # without the variety itself, the same city comes out
        m.setattr(city, "_vary_street", lambda st, rng: st)
        assert _digest(6037, varied=True) == _digest(6037)
    plain, varied = generate_city(6037), generate_city(6037, varied=True)
    assert varied.name == "sim-varied-city-6037" and plain.name == "sim-city-6037"

    def count(w, cls):  # noqa: ANN001, ANN202
        return sum(int(m.cls) == cls for m in w.instances)

    assert count(varied, MapClass.DIVIDER) < count(plain, MapClass.DIVIDER)
    area = lambda w: sum(Polygon(p).area for p in w.drivable)  # noqa: E731
    assert area(varied) > 1.05 * area(plain)
    for m in varied.instances:  # still valid geometry
        assert np.all(np.isfinite(m.points)) and len(m.points) >= 2


def test_junction_cities() -> None:
    """``junctions``: the varied city (its kerbs, the same drives) with the crossings of each
    junction moved to the junction's edge (closer to the node than the plain rule puts them), some
    skewed; the varied and plain cities stay as they were; deterministic."""
    from icmapper.data.sim.sequences import sim_sequences

    assert _digest(6037, junctions=True) == _digest(6037, junctions=True)
    assert _digest(6037, junctions=True) != _digest(6037, varied=True)
    varied, junc = generate_city(6037, varied=True), generate_city(6037, junctions=True)
    assert junc.name == "sim-junction-city-6037"

    def of(w, cls):  # noqa: ANN001, ANN202
        return [np.asarray(m.points) for m in w.instances if int(m.cls) == cls]

    # the same lanes, and the same number of crossings, in other places
    assert varied.lanes.keys() == junc.lanes.keys()
    for k, lane in varied.lanes.items():
        np.testing.assert_array_equal(lane.centerline, junc.lanes[k].centerline)
    cv, cj = of(varied, MapClass.PED_CROSSING), of(junc, MapClass.PED_CROSSING)

    def kept(a: np.ndarray, others: list[np.ndarray]) -> bool:
        return any(a.shape == b.shape and np.allclose(a, b) for b in others)

    # junction crossings move; crossings at corners stay (mid-block ones may be added: the blocks
    # between junction crossings grow)
    assert 0 < sum(kept(c, cv) for c in cj) < len(cj) and len(cj) >= len(cv)
    assert sum(not kept(c, cj) for c in cv) >= 5
    sides = [np.linalg.norm(np.diff(np.vstack([c, c[:1]]), axis=0), axis=1) for c in cj]
    skewed = [abs(float(np.dot(*np.diff(c[:3], axis=0)))) > 1e-6 for c in cj]  # corner 1 not 90°
    assert any(skewed) and all(np.all(s > 0.5) for s in sides)
    # the same drives, named for the variety
    (dv,), (dj,) = sim_sequences("train", 1, varied=True), sim_sequences("train", 1, junctions=True)
    assert dj.name == dv.name.replace("sim-varied-", "sim-junction-")
    np.testing.assert_array_equal(dj.poses, dv.poses)
