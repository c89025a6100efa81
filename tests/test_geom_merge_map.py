"""GlobalMap.merge_map (city maps from drive maps), provenance (tag_drive, info["drives"]), the
native bytes (to_bytes / from_bytes, exact and compact) and region loading (load(path, bbox)).

Oracles: shapely for the overlap test, unions and distances; a format-1 file written here from
its documented layout (old files still load); the format-2 checksum re-implemented here to forge
headers with absurd counts."""

from __future__ import annotations

import itertools
import struct
import threading
from pathlib import Path

import numpy as np
import pytest
import shapely
from icmapper import GlobalMap
from shapely.geometry import LineString, MultiLineString, Point, Polygon

GATE = 1.5
MIN_OVERLAP = 0.5

# ---------------------------------------------------------------------------------------------
# helpers


def wave(x0: float, x1: float, y: float, amp: float = 2.0, period: float = 40.0) -> np.ndarray:
    """A gently curved polyline along x at height y, points 0.5 m apart: (n, 2)."""
    x = np.arange(x0, x1 + 1e-9, 0.5)  # (n,)
    return np.stack([x, y + amp * np.sin(x / period)], axis=1)


def rect(cx: float, cy: float, hx: float, hy: float) -> np.ndarray:
    """A crossing ring: (4, 2)."""
    return np.array(
        [[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]]
    )


def shape(cls: int, pts: np.ndarray) -> LineString | Polygon:
    return Polygon(pts) if cls == 0 else LineString(pts)


def share_oracle(cls: int, a: np.ndarray, b: np.ndarray, gate: float) -> float:
    """max(share of a's points within gate of b, share of b's within gate of a), by shapely
    (a point inside a crossing is at distance 0)."""
    ga, gb = shape(cls, a), shape(cls, b)
    sa = np.mean([gb.distance(Point(p)) <= gate for p in a])
    sb = np.mean([ga.distance(Point(p)) <= gate for p in b])
    return float(max(sa, sb))


def instances(m: GlobalMap) -> dict[int, tuple[int, np.ndarray]]:
    return {int(i): m.get(int(i)) for i in m.ids()}


def map_chamfer(a: GlobalMap, b: GlobalMap, cls: int) -> float:
    """Chamfer distance between the class-`cls` parts of two maps: (mean distance of a's points to
    b's geometry + the same from b to a) / 2, by shapely (ring boundaries for crossings)."""

    def geometry(m: GlobalMap) -> tuple[np.ndarray, MultiLineString | None]:
        parts = [p for c, p in instances(m).values() if c == cls]
        if not parts:
            return np.zeros((0, 2)), None
        lines = [np.vstack([p, p[:1]]) if cls == 0 else p for p in parts]
        return np.vstack(parts), MultiLineString([LineString(x) for x in lines])

    pa, ga = geometry(a)
    pb, gb = geometry(b)
    if ga is None and gb is None:
        return 0.0
    if ga is None or gb is None:
        return float("inf")
    da = shapely.distance(shapely.points(pa), gb).mean()
    db = shapely.distance(shapely.points(pb), ga).mean()
    return float(da + db) / 2


def assert_same_map(a: GlobalMap, b: GlobalMap) -> None:
    np.testing.assert_array_equal(a.ids(), b.ids())
    assert (a.smoothing, a.spacing) == (b.smoothing, b.spacing)
    for i in a.ids():
        ca, pa = a.get(int(i))
        cb, pb = b.get(int(i))
        assert ca == cb
        np.testing.assert_array_equal(pa, pb)
        assert a.info(int(i)) == b.info(int(i))


def fnv1a64(data: bytes) -> int:
    h = 0xCBF29CE484222325
    for byte in data:
        h = ((h ^ byte) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def hash64(data: bytes) -> int:
    """The format-2 checksum (persist_v2.rs `hash64`), re-implemented."""
    mask = 0xFFFFFFFFFFFFFFFF
    p = 0x100000001B3

    def step(h: int, w: int) -> int:
        h = ((h ^ w) * p) & mask
        return h ^ (h >> 29)

    lanes = [0xCBF29CE484222325, 0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB]
    padded = data + b"\0" * (-len(data) % 8)
    words = struct.unpack(f"<{len(padded) // 8}Q", padded)
    for k, w in enumerate(words):
        lanes[k % 4] = step(lanes[k % 4], w)
    h = step(0x2545F4914F6CDD1D, len(data))
    for k, lane in enumerate(lanes):
        v = step(lane, k)
        r = (16 * k) % 64
        h ^= ((v << r) | (v >> (64 - r))) & mask if r else v
    return step(h, 0)


def v1_bytes(
    items: list[tuple[int, int, np.ndarray, int, int, int]], next_id: int, smoothing: float = 0.5
) -> bytes:
    """A format-1 map file from its documented layout: items = (id, cls, points, first, last,
    observations), ascending id."""
    out = bytearray(b"ICMAPGM\0")
    out += struct.pack("<Iddqq", 1, smoothing, 1.0, next_id, len(items))
    for i, cls, pts, first, last, obs in items:
        out += struct.pack("<QBBqqIQ", i, cls, int(cls == 0), first, last, obs, len(pts))
        out += np.ascontiguousarray(pts, dtype="<f8").tobytes()
    out += struct.pack("<Q", fnv1a64(bytes(out)))
    return bytes(out)


def city_world(rng: np.random.Generator) -> list[tuple[int, np.ndarray]]:
    """A few well-separated world instances: wavy polylines 12 m apart, crossings below them."""
    world = []
    for k in range(int(rng.integers(2, 5))):
        amp, period = rng.uniform(-3, 3), rng.uniform(20, 80)
        world.append((int(rng.integers(1, 3)), wave(0, 100, 12.0 * k, amp, period)))
    for k in range(int(rng.integers(0, 3))):
        world.append((0, rect(20 + 30 * k, -20, rng.uniform(1, 3), rng.uniform(1.5, 4))))
    return world


def drive_map(
    world: list[tuple[int, np.ndarray]], rng: np.random.Generator, drive: int
) -> GlobalMap:
    """One drive's map: each world instance seen with probability 0.8, a polyline only in a part
    (50-100 % of it), everything offset by up to 0.14 m and jittered by up to 0.06 m."""
    m = GlobalMap()
    for cls, pts in world:
        if rng.random() > 0.8:
            continue
        off = rng.uniform(-0.1, 0.1, 2)  # (2,)
        if cls == 0:
            m.insert(cls, pts + off, frame=drive)
            continue
        n = len(pts)
        i0 = int(rng.uniform(0, 0.5) * n)
        i1 = min(n, i0 + max(2, int(rng.uniform(0.5, 1.0) * n)))
        piece = pts[i0:i1] + off + rng.uniform(-0.03, 0.03, (i1 - i0, 2))  # (k, 2)
        m.insert(cls, piece, frame=drive)
    m.tag_drive(drive)
    return m


def merged_in_order(maps: list[GlobalMap], order: tuple[int, ...]) -> GlobalMap:
    city = GlobalMap.from_bytes(maps[order[0]].to_bytes())
    for k in order[1:]:
        city.merge_map(maps[k])
    return city


# ---------------------------------------------------------------------------------------------
# merge_map


def test_disjoint_maps_give_the_union_of_their_instances() -> None:
    a = GlobalMap()
    a.insert(1, wave(0, 50, 0), frame=3)
    a.insert(0, rect(10, 20, 2, 4), frame=4)
    a.tag_drive(1)
    b = GlobalMap()
    b.insert_with_id(7, 2, wave(0, 50, 30), frame=1)
    b.insert_with_id(9, 2, wave(0, 50, 0), frame=2)  # where a's divider is, but a boundary
    b.tag_drive(4)
    before_b = instances(b)
    before_a = instances(a)
    stats = a.merge_map(b)
    assert stats == {"merged": 0, "inserted": 2, "absorbed": 0}
    got = instances(a)
    assert len(got) == 4
    for i, (cls, pts) in before_a.items():  # a's instances untouched
        assert got[i][0] == cls
        np.testing.assert_array_equal(got[i][1], pts)
    new = sorted(set(got) - set(before_a))
    assert new == [2, 3]  # fresh ids of a, in b's id order
    for i, j in zip(new, (7, 9), strict=True):
        assert got[i][0] == before_b[j][0]
        np.testing.assert_array_equal(got[i][1], before_b[j][1])
        assert a.info(i)["drives"] == [4]
        info = a.info(i)
        assert (info["first_frame"], info["observations"]) == (b.info(j)["first_frame"], 1)
    for j, (_, pts) in before_b.items():  # other unchanged
        np.testing.assert_array_equal(b.get(j)[1], pts)


def test_identical_maps_keep_their_instances() -> None:
    a = GlobalMap()
    for k in range(4):
        a.insert(1 + k % 2, wave(0, 60, 10.0 * k), frame=k)
    a.insert(0, rect(5, -20, 2, 4))
    a.tag_drive(0)
    b = GlobalMap.from_bytes(a.to_bytes())
    b.tag_drive(9)
    original = GlobalMap.from_bytes(a.to_bytes())
    stats = a.merge_map(b)
    assert stats == {"merged": 5, "inserted": 0, "absorbed": 0}
    np.testing.assert_array_equal(a.ids(), original.ids())
    for cls in range(3):
        assert map_chamfer(a, original, cls) < 0.02
    for i in a.ids():
        info = a.info(int(i))
        assert info["drives"] == [0, 9] and info["observations"] == 2


def test_overlap_decision_matches_the_shapely_oracle() -> None:
    """Random pairs of one class, shifted and cut: merged exactly when the shapely share is at
    least min_overlap (pairs within one point of the threshold are skipped)."""
    rng = np.random.default_rng(3)
    checked = merged = 0
    for _ in range(60):
        cls = int(rng.integers(0, 3))
        if cls == 0:
            a = rect(0, 0, rng.uniform(1, 3), rng.uniform(2, 4))
            b = a + rng.uniform(-3, 3, 2)
        else:
            a = wave(0, rng.uniform(20, 60), 0)
            start, length = rng.uniform(-10, 40), rng.uniform(8, 50)
            b = wave(start, start + length, rng.uniform(-2.5, 2.5))
        m, o = GlobalMap(), GlobalMap()
        m.insert(cls, a)
        o.insert(cls, b)
        ma, ob = m.get(0)[1], o.get(0)[1]  # as stored (resampled at 1 m)
        share = share_oracle(cls, ma, ob, GATE)
        if abs(share - MIN_OVERLAP) < 1.0 / min(len(ma), len(ob)):
            continue
        stats = m.merge_map(o, gate=GATE, min_overlap=MIN_OVERLAP)
        expect = share >= MIN_OVERLAP
        assert stats["merged"] == int(expect), (cls, share)
        assert stats["inserted"] == int(not expect)
        assert len(m) == (1 if expect else 2)
        checked += 1
        merged += expect
    assert checked > 40 and 5 < merged < checked - 5  # both outcomes exercised


def test_crossings_merge_by_union_and_pieces_join() -> None:
    a = GlobalMap()
    c = a.insert(0, rect(0, 50, 2, 4), frame=0)
    p1 = a.insert(1, wave(0, 40, 0), frame=5)
    p2 = a.insert(1, wave(60, 100, 0), frame=2)
    a.tag_drive(1)
    b = GlobalMap()
    b.insert(0, rect(1, 51, 2, 4), frame=3)
    b.insert(1, wave(-5, 105, 0.1), frame=9)  # spans both pieces: all three join
    b.tag_drive(7)
    stats = a.merge_map(b)
    assert stats == {"merged": 2, "inserted": 0, "absorbed": 1}
    assert sorted(int(i) for i in a.ids()) == [c, p1] and p2 not in a  # p2 absorbed into p1
    union = shapely.union(Polygon(rect(0, 50, 2, 4)), Polygon(rect(1, 51, 2, 4)))
    ring = Polygon(a.get(c)[1])
    assert ring.symmetric_difference(union).area < 0.05 * union.area
    assert ring.hausdorff_distance(union) < 1.0
    info = a.info(p1)
    assert (info["first_frame"], info["last_frame"], info["observations"]) == (2, 9, 3)
    assert info["drives"] == [1, 7]
    line = LineString(a.get(p1)[1])
    truth = LineString(wave(-5, 105, 0.05))
    assert line.hausdorff_distance(truth) < 0.5


def test_merge_order_changes_the_city_map_little() -> None:
    """Every order of 4 drive maps (and a tree reduction) gives the same city map within the
    documented tolerance (map Chamfer per class <= 0.25 m), with every drive and observation."""
    rng = np.random.default_rng(11)
    world = city_world(rng)
    maps = [drive_map(world, rng, d) for d in range(4)]
    ref = merged_in_order(maps, (0, 1, 2, 3))
    total_obs = sum(len(m) for m in maps)
    orders = list(itertools.permutations(range(4)))[::5]
    worst = 0.0
    for order in orders:
        city = merged_in_order(maps, order)
        for cls in range(3):
            worst = max(worst, map_chamfer(ref, city, cls))
        assert sum(city.info(int(i))["observations"] for i in city.ids()) == total_obs
        drives = {d for i in city.ids() for d in city.info(int(i))["drives"]}
        assert drives == {d for d, m in enumerate(maps) if len(m)}
    left = GlobalMap.from_bytes(maps[3].to_bytes())
    left.merge_map(maps[1])
    right = GlobalMap.from_bytes(maps[2].to_bytes())
    right.merge_map(maps[0])
    left.merge_map(right)
    for cls in range(3):
        worst = max(worst, map_chamfer(ref, left, cls))
    assert worst <= 0.25, worst
    # The city map is near the world: every world instance some drive saw is covered.
    for cls, pts in world:
        parts = [p for c, p in instances(ref).values() if c == cls]
        lines = MultiLineString([LineString(p) for p in parts])
        d = shapely.distance(shapely.points(pts[::10]), lines)  # (k,)
        assert np.median(d) < 0.3 or cls == 0


def test_merge_map_is_deterministic_and_leaves_other_unchanged() -> None:
    rng = np.random.default_rng(5)
    world = city_world(rng)
    base, other = drive_map(world, rng, 0), drive_map(world, rng, 1)
    other_bytes = other.to_bytes()
    results = []
    for _ in range(2):
        m = GlobalMap.from_bytes(base.to_bytes())
        stats = m.merge_map(other)
        results.append((stats, m.to_bytes()))
    assert results[0] == results[1]
    assert other.to_bytes() == other_bytes


def test_merge_map_with_itself_and_bad_arguments() -> None:
    m = GlobalMap()
    m.insert(1, wave(0, 30, 0))
    m.insert(2, wave(0, 30, 20))
    assert m.merge_map(m) == {"merged": 2, "inserted": 0, "absorbed": 0}
    assert len(m) == 2 and m.info(0)["observations"] == 2
    other = GlobalMap()
    bad_kwargs = (
        {"gate": -1.0},
        {"gate": float("nan")},
        {"min_overlap": 0.0},
        {"min_overlap": 1.5},
        {"tolerance": 0.0},
        {"tolerance": float("inf")},
    )
    for kwargs in bad_kwargs:
        with pytest.raises(ValueError, match="gate|min_overlap|tolerance"):
            m.merge_map(other, **kwargs)
    with pytest.raises(TypeError):
        m.merge_map("not a map")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        m.merge_map(None)  # type: ignore[arg-type]


def test_concurrent_merges_in_both_directions_do_not_deadlock() -> None:
    a, b = GlobalMap(), GlobalMap()
    for k in range(40):
        a.insert(1, wave(0, 30, 5.0 * k))
        b.insert(1, wave(10, 40, 5.0 * k + 0.2))
    errors: list[BaseException] = []

    def run(x: GlobalMap, y: GlobalMap) -> None:
        try:
            for _ in range(20):
                x.merge_map(y)
        except BaseException as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=run, args=p) for p in ((a, b), (b, a))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads), "deadlock"
    assert not errors


# ---------------------------------------------------------------------------------------------
# provenance


def test_tag_drive_and_info_drives() -> None:
    m = GlobalMap()
    a = m.insert(1, wave(0, 10, 0))
    assert m.info(a)["drives"] == []
    m.tag_drive(7)
    m.tag_drive(2)
    m.tag_drive(7)
    m.tag_drive(2**32 - 1)
    b = m.insert(2, wave(0, 10, 5))
    assert m.info(a)["drives"] == [2, 7, 2**32 - 1]
    assert m.info(b)["drives"] == []  # tagging covers the instances present at the time
    m.tag_drive(np.uint32(3))
    assert m.info(b)["drives"] == [3]
    for bad in (-1, 2**32):
        with pytest.raises(ValueError, match="drive"):
            m.tag_drive(bad)
    for bad_type in (1.5, "1", None, True):
        with pytest.raises(TypeError, match="drive"):
            m.tag_drive(bad_type)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# native bytes and files


def dense_map(n: int, seed: int = 0) -> GlobalMap:
    rng = np.random.default_rng(seed)
    m = GlobalMap()
    for k in range(n):
        x, y = rng.uniform(0, 2000, 2)
        if k % 10 == 0:
            m.insert(0, rect(x, y, rng.uniform(1, 3), rng.uniform(2, 5)), frame=k)
        else:
            line = wave(x, x + rng.uniform(20, 60), y, 1.0, rng.uniform(20, 60))  # (n, 2)
            m.insert(1 + k % 2, line, frame=k)
    m.tag_drive(seed)
    return m


def test_bytes_round_trip_exact_and_compact(tmp_path: Path) -> None:
    m = dense_map(300)
    m.merge(5, m.get(5)[1] + 0.2, frame=999)
    m.remove(7)
    data = m.to_bytes()
    back = GlobalMap.from_bytes(data)
    assert_same_map(m, back)
    assert back.to_bytes() == data
    assert_same_map(m, GlobalMap.from_bytes(bytearray(data)))
    compact = m.to_bytes(compact=True)
    assert len(compact) * 3 < len(data)
    cback = GlobalMap.from_bytes(compact)
    np.testing.assert_array_equal(cback.ids(), m.ids())
    for i in m.ids():
        assert cback.info(int(i)) == m.info(int(i))
        got, want = cback.get(int(i))[1], m.get(int(i))[1]  # (n, 2) each
        np.testing.assert_allclose(got, want, rtol=0, atol=0.5e-4 + 1e-9)
    assert cback.to_bytes(compact=True) == compact
    # save / load agree with the bytes.
    p = tmp_path / "m.icmap"
    m.save(p, compact=True)
    assert p.read_bytes() == compact
    m.save(p)
    assert p.read_bytes() == data
    assert_same_map(m, GlobalMap.load(p))
    assert [q.name for q in tmp_path.iterdir()] == ["m.icmap"]


def test_version_1_files_still_load(tmp_path: Path) -> None:
    items = [
        (0, 0, rect(0, 0, 1, 2), -3, 7, 4),
        (2, 2, np.array([[-1e6, 3.0], [1e6, 3.0]]), 0, 0, 1),
        (5, 1, wave(10, 20, -1), 2, 2, 1),
    ]
    data = v1_bytes(items, next_id=9, smoothing=0.25)
    p = tmp_path / "old.icmap"
    p.write_bytes(data)
    for m in (GlobalMap.load(p), GlobalMap.from_bytes(data)):
        assert [int(i) for i in m.ids()] == [0, 2, 5]
        assert m.smoothing == 0.25
        for i, cls, pts, first, last, obs in items:
            got_cls, got = m.get(i)
            assert got_cls == cls
            np.testing.assert_array_equal(got, pts)
            info = m.info(i)
            assert (info["first_frame"], info["last_frame"]) == (first, last)
            assert info["observations"] == obs
            assert info["drives"] == []
        assert m.insert(1, [[0, 0], [1, 1]]) == 9
    region = GlobalMap.load(p, bbox=(9, -5, 12, 2))  # instance 2 lies at y = 3
    assert [int(i) for i in region.ids()] == [5]
    with pytest.raises(ValueError, match="checksum"):
        GlobalMap.from_bytes(data[:-1] + bytes([data[-1] ^ 1]))


def test_region_loading_matches_the_box_oracle(tmp_path: Path) -> None:
    m = dense_map(2000, seed=4)
    boxes = {int(i): m.get(int(i))[1] for i in m.ids()}
    p = tmp_path / "city.icmap"
    rng = np.random.default_rng(8)
    for compact in (False, True):
        m.save(p, compact=compact)
        for _ in range(6):
            x0, y0 = rng.uniform(-100, 2000, 2)
            w, h = rng.uniform(0, 600, 2)
            bbox = (x0, y0, x0 + w, y0 + h)
            got = GlobalMap.load(p, bbox=bbox)
            expect = [
                i
                for i, pts in boxes.items()
                if pts[:, 0].min() <= bbox[2]
                and pts[:, 0].max() >= bbox[0]
                and pts[:, 1].min() <= bbox[3]
                and pts[:, 1].max() >= bbox[1]
            ]
            # (Compact coordinates move by 0.05 mm at most: no box sits that close to the edge.)
            assert sorted(int(i) for i in got.ids()) == expect
            for i in got.ids():
                assert got.info(int(i))["drives"] == [4]
        assert len(GlobalMap.load(p, bbox=np.array([-1e9, -1e9, 1e9, 1e9]))) == len(m)
        assert len(GlobalMap.load(p, bbox=(1e7, 1e7, 1e7 + 1, 1e7 + 1))) == 0
    for bad in ((float("nan"), 0, 1, 1), (0, 0, 1, float("nan")), (2, 0, 1, 1), (0, 2, 1, 1)):
        with pytest.raises(ValueError, match="bbox"):
            GlobalMap.load(p, bbox=bad)
    with pytest.raises(ValueError, match="4 values"):
        GlobalMap.load(p, bbox=(0, 0, 1))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="bbox"):
        GlobalMap.load(p, bbox="0 0 1 1")  # type: ignore[arg-type]


def test_corrupt_bytes_and_absurd_headers_raise_value_error() -> None:
    m = dense_map(20)
    data = m.to_bytes()
    for bad in (b"", b"ICMAP", data[:100], data[: len(data) // 2], data + b"\0", b"x" * 200):
        with pytest.raises(ValueError, match="not a valid icmapper map file"):
            GlobalMap.from_bytes(bad)
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0x10
    with pytest.raises(ValueError, match="checksum"):
        GlobalMap.from_bytes(bytes(flipped))
    n_blocks = struct.unpack_from("<Q", data, 52)[0]
    head_end = 12 + 64 + 64 * n_blocks

    def forged(offset: int, value: int) -> bytes:
        """A header field rewritten and the head checksum made valid again."""
        b = bytearray(data)
        struct.pack_into("<Q", b, offset, value)
        end = 12 + 64 + 64 * struct.unpack_from("<Q", b, 52)[0]
        if end + 8 <= len(b):
            struct.pack_into("<Q", b, end, hash64(bytes(b[:end])))
        return bytes(b)

    assert forged(36, struct.unpack_from("<Q", data, 36)[0]) == data  # the checksum oracle agrees
    assert struct.unpack_from("<Q", data, head_end)[0] == hash64(data[:head_end])
    for offset, value, what in (
        (36, 2**63, "instances"),  # instance count
        (52, 2**62, "blocks"),  # block count
        (60, 2**63, "truncated"),  # body length
        (12 + 64 + 48, 2**63, "instances"),  # count of block 0
        (12 + 64 + 40, 2**62, "out of place"),  # length of block 0
    ):
        with pytest.raises(ValueError, match=what):
            GlobalMap.from_bytes(forged(offset, value))
    with pytest.raises(TypeError):
        GlobalMap.from_bytes("text")  # type: ignore[arg-type]


def _dense(corners: list[tuple[float, float]]) -> np.ndarray:
    """Points every 0.5 m along the polyline through ``corners``: (n, 2)."""
    out = [np.asarray(corners[:1], dtype=np.float64)]
    for a, b in itertools.pairwise(np.asarray(corners, dtype=np.float64)):
        n = int(np.ceil(np.linalg.norm(b - a) / 0.5))
        out.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(out)


@pytest.mark.parametrize(
    ("first", "second"),
    [
        # Two drives saw three sides of a 40 x 20 m block each, the ring closes across them.
        ([(0, 20), (0, 0), (40, 0), (40, 20)], [(40, 0), (40, 20), (0, 20), (0, 0)]),
        # A piece along the middle of a long boundary that then turns away.
        ([(0, 0), (100, 0)], [(10, 0.2), (60, 0.2), (60, 20), (80, 20)]),
    ],
)
def test_merge_map_loses_and_invents_no_polyline(
    first: list[tuple[float, float]], second: list[tuple[float, float]]
) -> None:
    """Regression (issue 16, AV2 city map): the curve-fit merge of two long boundaries that
    overlap only in part dropped whole sides (CD_bound 0.72 m on 6 AV2 drives). Every input
    vertex lies within the tolerance of the merged map and every merged vertex within it of the
    inputs (shapely distances); an unchecked merge (a tolerance and a gate too large to refuse:
    the gate bounds what a merge may leave farther than it) does not."""
    a, b = _dense(first), _dense(second)

    def gaps(tolerance: float, gate: float = 1.5) -> tuple[float, float]:
        m, o = GlobalMap(), GlobalMap()
        m.insert(2, a)
        o.insert(2, b)
        m.merge_map(o, gate=gate, tolerance=tolerance)
        out = MultiLineString([m.get(int(i))[1] for i in m.ids()])
        inputs = MultiLineString([a, b])
        lost = max(out.distance(Point(q)) for q in np.concatenate([a, b]))
        invented = max(inputs.distance(Point(q)) for i in m.ids() for q in m.get(int(i))[1])
        return lost, invented

    lost, invented = gaps(3.0)
    assert lost <= 3.0 and invented <= 3.0, (lost, invented)
    assert max(gaps(1e9, 1e9)) > 6.0
