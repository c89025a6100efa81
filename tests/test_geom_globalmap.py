"""icmapper.GlobalMap: bookkeeping, query vs brute force (shapely), sample_patch frames and shapes,
persistence (round trip, corrupt/missing files, atomic save), GeoJSON export, thread safety."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
import shapely
from icmapper import GlobalMap, geom
from icmapper.testing.geom_reference import patch_polygon, to_world
from shapely.geometry import LineString, Polygon

# ---------------------------------------------------------------------------------------------
# helpers


def seg_dist(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of points p (k, 2) to the polyline `line` (m, 2): (k,)."""
    a, b = line[:-1], line[1:]  # (m - 1, 2)
    ab = b - a
    t = np.clip(
        np.einsum("kmd,md->km", p[:, None] - a[None], ab) / np.maximum((ab**2).sum(1), 1e-18),
        0,
        1,
    )  # (k, m')
    proj = a[None] + t[..., None] * ab[None]  # (k, m', 2)
    return np.linalg.norm(proj - p[:, None], axis=2).min(axis=1)


def random_instance(rng: np.random.Generator) -> tuple[int, np.ndarray]:
    """A random class and world geometry: a crossing quad or a 20-60 m wiggly polyline."""
    c = rng.uniform(-150, 150, 2)
    if rng.random() < 0.25:
        w, h, a = rng.uniform(3, 10), rng.uniform(2, 5), rng.uniform(0, math.pi)
        box = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2  # (4, 2)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        return 0, box @ rot.T + c
    n = int(rng.integers(3, 8))
    a = rng.uniform(0, 2 * math.pi)
    steps = rng.uniform(5, 10, n - 1)[:, None] * np.stack(
        [np.cos(a + rng.normal(0, 0.2, n - 1)), np.sin(a + rng.normal(0, 0.2, n - 1))], axis=1
    )  # (n - 1, 2)
    return int(rng.integers(1, 3)), c + np.vstack([[0, 0], np.cumsum(steps, axis=0)])


def random_map(seed: int, n: int) -> tuple[GlobalMap, dict[int, tuple[int, np.ndarray]]]:
    rng = np.random.default_rng(seed)
    m = GlobalMap(smoothing=0.5, spacing=1.0)
    inst = {}
    for f in range(n):
        cls, pts = random_instance(rng)
        inst[m.insert(cls, pts, frame=f)] = (cls, pts)
    return m, inst


def assert_same_map(a: GlobalMap, b: GlobalMap) -> None:
    np.testing.assert_array_equal(a.ids(), b.ids())
    assert (a.smoothing, a.spacing) == (b.smoothing, b.spacing)
    for i in a.ids():
        ca, pa = a.get(i)
        cb, pb = b.get(i)
        assert ca == cb
        np.testing.assert_array_equal(pa, pb)
        assert a.info(i) == b.info(i)


# ---------------------------------------------------------------------------------------------
# bookkeeping


def test_insert_get_info_remove() -> None:
    m = GlobalMap()
    assert len(m) == 0 and m.ids().dtype == np.uint64 and m.ids().shape == (0,)
    line = np.stack([np.linspace(0, 10, 4), np.zeros(4)], axis=1)  # (4, 2)
    i0 = m.insert(1, line, frame=3)
    i1 = m.insert(2, line + [0, 5], frame=4)
    assert (i0, i1) == (0, 1) and len(m) == 2 and 0 in m and 1 in m and 2 not in m
    cls, pts = m.get(i0)
    assert cls == 1 and pts.dtype == np.float64
    np.testing.assert_allclose(pts, geom.resample_spacing(line, m.spacing), atol=1e-9)
    info = m.info(i0)
    assert info == {
        "id": 0,
        "cls": 1,
        "closed": False,
        "first_frame": 3,
        "last_frame": 3,
        "observations": 1,
        "n_points": pts.shape[0],
        "drives": [],
    }
    m.remove(i0)
    assert i0 not in m and len(m) == 1
    with pytest.raises(KeyError):
        m.get(i0)
    assert m.insert(0, np.array([[0, 0], [4, 0], [4, 3], [0, 3]]), frame=5) == 2  # never reused
    assert m.info(2)["closed"] is True
    m.insert_with_id(100, 1, line)
    assert m.insert(1, line) == 101
    with pytest.raises(ValueError, match="100"):
        m.insert_with_id(100, 1, line)
    assert "GlobalMap(" in repr(m) and "len=4" in repr(m)
    assert (m.smoothing, m.spacing) == (0.5, 1.0)
    assert "x" not in m and -1 not in m


def test_merge_updates_geometry_and_bookkeeping() -> None:
    m = GlobalMap(smoothing=0.5, spacing=1.0)
    line = np.stack([np.linspace(0, 30, 31), np.zeros(31)], axis=1)  # (31, 2)
    i = m.insert(1, line, frame=0)
    det = np.stack([np.linspace(20, 50, 31), np.full(31, 0.05)], axis=1)  # (31, 2)
    m.merge(i, det, frame=7)
    _, pts = m.get(i)
    assert pts[0, 0] == pytest.approx(0, abs=0.3) and pts[-1, 0] == pytest.approx(50, abs=0.3)
    info = m.info(i)
    assert (info["first_frame"], info["last_frame"], info["observations"]) == (0, 7, 2)
    # the index follows the merged geometry
    assert i in m.query((45, 0, 0), (1, 1)).tolist()
    # crossings merge by union
    c = m.insert(0, np.array([[0, 10], [4, 10], [4, 13], [0, 13]]), frame=1)
    m.merge(c, np.array([[2, 10], [6, 10], [6, 13], [2, 13]]), frame=2)
    _, ring = m.get(c)
    assert ring[:, 0].min() == pytest.approx(0, abs=1e-6)
    assert ring[:, 0].max() == pytest.approx(6, abs=1e-6)
    # a failed merge leaves the instance unchanged
    before = m.get(i)[1]
    with pytest.raises(ValueError):
        m.merge(i, np.array([[0.0, np.nan], [1.0, 1.0]]))
    np.testing.assert_array_equal(m.get(i)[1], before)
    assert m.info(i)["observations"] == 2
    with pytest.raises(KeyError):
        m.merge(999, det)


@pytest.mark.parametrize("seed", range(4))
def test_query_matches_brute_force(seed: int) -> None:
    m, _ = random_map(seed, 300)
    rng = np.random.default_rng(1000 + seed)
    geoms = {}
    for i in m.ids():
        cls, pts = m.get(i)
        geoms[int(i)] = Polygon(pts) if cls == 0 else LineString(pts)
    for _ in range(20):
        pose = (*rng.uniform(-150, 150, 2), float(rng.uniform(-4, 4)))
        he, margin = rng.uniform(5, 40, 2), float(rng.uniform(0, 10))
        got = m.query(pose, he, margin=margin)
        assert got.dtype == np.uint64
        poly = patch_polygon(pose, he[0] + margin, he[1] + margin)
        want = sorted(i for i, g in geoms.items() if g.intersects(poly))
        assert got.tolist() == want


@pytest.mark.parametrize("seed", range(3))
def test_sample_patch_shapes_and_frames(seed: int) -> None:
    m, _ = random_map(10 + seed, 300)
    rng = np.random.default_rng(seed)
    for _ in range(10):
        pose = (*rng.uniform(-120, 120, 2), float(rng.uniform(-4, 4)))
        he, margin, n = (30.0, 15.0), 20.0, 20
        ids, cls, pts, mask = m.sample_patch(pose, he, margin=margin, n_points=n)
        k = ids.shape[0]
        assert ids.dtype == np.uint64 and cls.dtype == np.int64
        assert pts.dtype == np.float32 and mask.dtype == np.bool_
        assert cls.shape == (k,) and pts.shape == (k, n, 2) and mask.shape == (k, n)
        assert ids.tolist() == m.query(pose, he, margin=margin).tolist()
        patch = patch_polygon(pose, he[0] + margin, he[1] + margin)
        # ego frame, inside the expanded patch
        assert np.all(np.abs(pts[..., 0]) <= he[0] + margin + 1e-3)
        assert np.all(np.abs(pts[..., 1]) <= he[1] + margin + 1e-3)
        for j in range(k):
            c, world = m.get(ids[j])
            assert cls[j] == c
            back = to_world(pts[j].astype(np.float64), pose)  # (n, 2)
            if c == 0:  # on the boundary of the crossing clipped to the patch
                clipped = Polygon(world).intersection(patch)
                d = [clipped.boundary.distance(shapely.Point(q)) for q in back]
                assert max(d) < 1e-3
            else:  # on the stored polyline, never connecting past its last point
                assert seg_dist(back, world).max() < 1e-3
                assert not mask[j, -1]


def test_sample_patch_fully_inside_and_empty() -> None:
    m = GlobalMap()
    line = np.array([[100.0, 50.0], [110.0, 50.0], [110.0, 60.0]])
    i = m.insert(2, line)
    pose = (105.0, 55.0, 0.3)
    ids, cls, pts, mask = m.sample_patch(pose, (30, 15), margin=20, n_points=20)
    assert ids.tolist() == [i] and cls.tolist() == [2]
    want = geom.resample(m.get(i)[1], 20)  # (20, 2) world
    np.testing.assert_allclose(to_world(pts[0].astype(np.float64), pose), want, atol=1e-4)
    assert mask[0].tolist() == [True] * 19 + [False]
    ids, cls, pts, mask = m.sample_patch((-500.0, 0.0, 0.0), (30, 15), n_points=20)
    assert ids.shape == (0,) and cls.shape == (0,)
    assert pts.shape == (0, 20, 2) and pts.dtype == np.float32
    assert mask.shape == (0, 20) and mask.dtype == np.bool_


# ---------------------------------------------------------------------------------------------
# persistence


def test_save_load_round_trip(tmp_path: Path) -> None:
    m, _ = random_map(5, 50)
    m.merge(3, m.get(3)[1] + 0.1, frame=99)
    m.remove(7)
    p = tmp_path / "m.icmap"
    m.save(p)  # os.PathLike
    m2 = GlobalMap.load(str(p))  # str
    assert_same_map(m, m2)
    assert m2.insert(1, [[0, 0], [1, 1]]) == m.insert(1, [[0, 0], [1, 1]])  # next id continues
    assert not [q for q in tmp_path.iterdir() if q.name != "m.icmap"]  # no temp files left


def _saved(tmp_path: Path, n: int = 20) -> tuple[GlobalMap, Path, bytes]:
    m, _ = random_map(6, n)
    p = tmp_path / "bad.icmap"
    m.save(p)
    return m, p, p.read_bytes()


def test_corrupt_files_raise_value_error_naming_the_file(tmp_path: Path) -> None:
    _, p, data = _saved(tmp_path)
    cases = {
        "truncated": data[: len(data) // 2],
        "truncated_header": data[:3],
        "empty": b"",
        "wrong_magic": b"XXXX" + data[4:],
        "flipped_byte": data[: len(data) // 2]
        + bytes([data[len(data) // 2] ^ 0x10])
        + data[len(data) // 2 + 1 :],
        "flipped_last_byte": data[:-1] + bytes([data[-1] ^ 0x01]),
        "trailing_garbage": data + b"\x00garbage",
    }
    for name, bad in cases.items():
        q = tmp_path / f"{name}.icmap"
        q.write_bytes(bad)
        with pytest.raises(ValueError, match=name) as exc:
            GlobalMap.load(q)
        assert str(q) in str(exc.value) or q.name in str(exc.value), name


def test_missing_file_and_bad_directory(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        GlobalMap.load(tmp_path / "nope.icmap")
    m = GlobalMap()
    with pytest.raises(OSError):
        m.save(tmp_path / "no_such_dir" / "m.icmap")
    assert not (tmp_path / "no_such_dir").exists()
    with pytest.raises(OSError):
        m.to_geojson(tmp_path / "no_such_dir" / "m.geojson")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir" / "keep").write_text("x")
    with pytest.raises(OSError):
        m.save(tmp_path / "adir")  # the target is a non-empty directory
    assert (tmp_path / "adir" / "keep").read_text() == "x"
    assert sorted(q.name for q in tmp_path.iterdir()) == ["adir"]  # no temp file left behind


_FAILING_SAVE = """
import resource, signal, sys
import numpy as np
from icmapper import GlobalMap
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
m = GlobalMap()
for k in range(200):
    m.insert(1, np.array([[0.0, k], [300.0, k]]))
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
try:
    m.save(sys.argv[1])
except OSError as e:
    print("OSError", e)
    sys.exit(0)
print("saved")
sys.exit(1)
"""


@pytest.mark.skipif(sys.platform != "linux", reason="uses RLIMIT_FSIZE to make a write fail")
def test_failed_save_leaves_previous_file_intact(tmp_path: Path) -> None:
    """A save whose write fails (file-size limit) raises OSError and keeps the old file."""
    m, p, data = _saved(tmp_path, n=3)
    assert len(data) < 4096
    r = subprocess.run(
        [sys.executable, "-c", _FAILING_SAVE, str(p)], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert p.read_bytes() == data
    assert_same_map(m, GlobalMap.load(p))
    assert sorted(q.name for q in tmp_path.iterdir()) == ["bad.icmap"]


def test_geojson_export(tmp_path: Path) -> None:
    m, inst = random_map(8, 30)
    p = tmp_path / "m.geojson"
    m.to_geojson(p)
    doc = json.loads(p.read_text())
    assert doc["type"] == "FeatureCollection" and len(doc["features"]) == len(m)
    for f in doc["features"]:
        i = f["properties"]["id"]
        cls, pts = m.get(i)
        assert f["properties"]["class"] == cls
        kind = f["geometry"]["type"]
        assert kind == ("Polygon" if cls == 0 else "LineString")
        coords = np.asarray(f["geometry"]["coordinates"][0 if cls == 0 else slice(None)])
        if cls == 0:
            assert np.allclose(coords[0], coords[-1])  # GeoJSON rings are closed
            coords = coords[:-1]
        np.testing.assert_allclose(coords, pts, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# threads


def test_one_map_from_many_threads() -> None:
    m = GlobalMap()
    n_threads, per_thread = 6, 60
    inserted: list[list[int]] = [[] for _ in range(n_threads)]
    errors: list[BaseException] = []
    barrier = threading.Barrier(n_threads)

    def work(t: int) -> None:
        try:
            rng = np.random.default_rng(t)
            barrier.wait()
            for k in range(per_thread):
                cls, pts = random_instance(rng)
                i = m.insert(cls, pts, frame=k)
                inserted[t].append(i)
                m.merge(i, pts + rng.normal(0, 0.05, pts.shape), frame=k + 1)
                pose = (*rng.uniform(-150, 150, 2), 0.0)
                ids, _, p, _ = m.sample_patch(pose, (30, 15), margin=20)
                assert p.shape[0] == ids.shape[0]
                m.query(pose, (30, 15))
                if k % 5 == 0:
                    m.remove(i)
                    inserted[t].pop()
                len(m)
        except BaseException as e:  # noqa: BLE001 - re-raised in the main thread
            errors.append(e)

    threads = [threading.Thread(target=work, args=(t,)) for t in range(n_threads)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert not errors, errors
    all_ids = sorted(i for ids in inserted for i in ids)
    assert len(set(all_ids)) == len(all_ids)
    assert m.ids().tolist() == all_ids
    for i in all_ids:
        assert m.info(i)["observations"] == 2


def test_replace_keeps_bookkeeping_and_errors_leave_instance_unchanged() -> None:
    m = GlobalMap()
    i = m.insert(1, np.array([[0.0, 0.0], [10.0, 0.0]]), frame=2)
    m.replace(i, np.array([[0.0, 1.0], [20.0, 1.0]], dtype=np.float32), frame=5)
    info = m.info(i)
    assert (info["first_frame"], info["last_frame"], info["observations"]) == (2, 5, 2)
    cls, pts = m.get(i)
    assert cls == 1 and np.allclose(pts[[0, -1]], [[0.0, 1.0], [20.0, 1.0]])
    assert list(m.query((10.0, 1.0, 0.0), (1.0, 1.0))) == [i]
    with pytest.raises(ValueError, match="NaN"):
        m.replace(i, np.array([[0.0, np.nan], [1.0, 1.0]]), frame=6)
    with pytest.raises(KeyError):
        m.replace(999, np.array([[0.0, 0.0], [1.0, 1.0]]))
    assert m.info(i)["last_frame"] == 5 and np.array_equal(m.get(i)[1], pts)


@pytest.mark.parametrize("length", [40.0, 700.0])
def test_merge_same_result_with_gil_held_or_released(length: float) -> None:
    """A merge of at most 512 points in all runs with the GIL held, a larger one releases it:
    both store exactly what ``geom.merge_polyline`` returns for the same inputs."""
    m = GlobalMap(smoothing=0.5, spacing=1.0)
    x = np.linspace(0.0, length, int(length / 5.0) + 1)  # (n,)
    i = m.insert(2, np.stack([x, 0.2 * np.sin(x / 9.0)], axis=1))
    _, stored = m.get(i)
    assert (len(stored) + 20 <= 512) == (length < 100.0)
    det = np.stack([np.linspace(10.0, 30.0, 20), np.full(20, 0.1)], axis=1)  # (20, 2)
    m.merge(i, det, frame=1)
    _, merged = m.get(i)
    np.testing.assert_array_equal(merged, geom.merge_polyline(stored, det, s=0.5, spacing=1.0))
