"""GlobalMap.merge_many: the same map as sequential merge calls (parallel merges of different
instances), per-item errors like merge's, argument errors before anything changes, and safety
while other threads read the map."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from icmapper import GlobalMap


def city(seed: int) -> tuple[GlobalMap, list[int]]:
    """12 polylines and 4 crossings."""
    rng = np.random.default_rng(seed)
    m = GlobalMap(smoothing=0.5, spacing=1.0)
    ids = []
    for k in range(12):
        t = np.linspace(0.0, 40.0, 41)
        pts = np.stack([t, 8.0 * k + 0.3 * np.sin(t / 7.0 + k)], axis=1)
        ids.append(m.insert(1 + k % 2, pts, frame=0))
    for k in range(4):
        c = np.array([60.0 + 10.0 * k, 5.0])
        box = np.array([[-2.0, -7.0], [2.0, -7.0], [2.0, 7.0], [-2.0, 7.0]])
        ids.append(m.insert(0, box + c + rng.normal(0, 0.05, (4, 2)), frame=0))
    return m, ids


def detections(m: GlobalMap, ids: list[int], seed: int) -> list[tuple[int, np.ndarray]]:
    """Noisy partial copies, several per instance for some."""
    rng = np.random.default_rng(seed)
    out = []
    for i in list(ids) + list(ids[:5]) + list(ids[-2:]):
        cls, pts = m.get(i)
        if cls == 0:
            det = pts[:: max(1, len(pts) // 12)] + rng.normal(
                0, 0.1, (len(pts[:: max(1, len(pts) // 12)]), 2)
            )
        else:
            a = int(rng.integers(0, len(pts) // 2))
            det = pts[a : a + 20] + rng.normal(0, 0.1, (len(pts[a : a + 20]), 2)) + [3.0, 0.0]
        out.append((i, det))
    order = rng.permutation(len(out))
    return [out[j] for j in order]


def snapshot(m: GlobalMap) -> dict[int, tuple[int, bytes, dict]]:
    return {int(i): (m.get(int(i))[0], m.get(int(i))[1].tobytes(), m.info(int(i))) for i in m.ids()}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_map_as_sequential_merges(seed: int) -> None:
    a, ids = city(seed)
    b, _ = city(seed)
    dets = detections(a, ids, seed + 10)
    for i, d in dets:
        a.merge(i, d, frame=3)
    errors = b.merge_many([i for i, _ in dets], [d for _, d in dets], frame=3)
    assert errors == [None] * len(dets)
    assert snapshot(a) == snapshot(b)
    # The index follows: the same query answers.
    for pose in [(20.0, 40.0, 0.3), (70.0, 5.0, 1.0), (0.0, 0.0, 0.0)]:
        assert a.query(pose, (30.0, 15.0)).tolist() == b.query(pose, (30.0, 15.0)).tolist()


def test_per_item_errors_match_merge() -> None:
    a, ids = city(0)
    b, _ = city(0)
    good = np.stack([np.linspace(5, 25, 20), np.full(20, 0.2)], axis=1)
    items: list[tuple[int, np.ndarray]] = [
        (ids[0], good),
        (999, good),  # unknown id
        (-3, good),  # not an instance id
        (ids[1], np.array([[0.0, np.nan], [1.0, 2.0]])),  # NaN
        (ids[2], np.array([[1.0, 2.0]])),  # one point
        (ids[0], good + [10.0, 0.1]),  # a second merge into the same instance
        (ids[-1], np.array([[60.0, 0.0], [61.0, 0.0]])),  # a crossing ring of two points
    ]
    expected: list[type[BaseException] | None] = []
    for i, d in items:
        try:
            a.merge(i, d, frame=5)
            expected.append(None)
        except (KeyError, ValueError) as exc:
            expected.append(type(exc))
    got = b.merge_many(np.array([i for i, _ in items]), [d for _, d in items], frame=5)
    assert [None if e is None else type(e) for e in got] == expected
    assert expected == [None, KeyError, KeyError, ValueError, ValueError, None, ValueError]
    assert "non-finite" in str(got[3]) and "999" in str(got[1])
    assert snapshot(a) == snapshot(b)
    assert b.info(ids[0])["observations"] == 3


def test_argument_errors_change_nothing() -> None:
    m, ids = city(1)
    before = snapshot(m)
    line = np.zeros((5, 2))
    with pytest.raises(ValueError, match="same length"):
        m.merge_many(ids[:2], [line])
    with pytest.raises(ValueError, match=r"points\[1\]"):
        m.merge_many(ids[:2], [line, np.zeros((5, 3))])
    with pytest.raises(TypeError):
        m.merge_many(5, [line])  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        m.merge_many(["a"], [line])  # type: ignore[list-item]
    assert snapshot(m) == before
    assert m.merge_many([], []) == []


def test_stacked_array_and_float32() -> None:
    a, ids = city(2)
    b, _ = city(2)
    dets = np.stack(
        [np.stack([np.linspace(2, 30, 20), 8.0 * k + np.full(20, 0.1)], axis=1) for k in range(6)]
    ).astype(np.float32)  # (6, 20, 2)
    for k in range(6):
        a.merge(ids[k], dets[k], frame=1)
    assert b.merge_many(ids[:6], dets, frame=1) == [None] * 6
    assert snapshot(a) == snapshot(b)


def test_concurrent_readers() -> None:
    m, ids = city(3)
    dets = detections(m, ids, 4)
    stop = threading.Event()
    seen: list[int] = []

    def read() -> None:
        while not stop.is_set():
            seen.append(len(m.query((40.0, 40.0, 0.0), (80.0, 80.0))))

    threads = [threading.Thread(target=read) for _ in range(2)]
    for t in threads:
        t.start()
    try:
        for _ in range(5):
            assert m.merge_many([i for i, _ in dets], [d for _, d in dets]) == [None] * len(dets)
    finally:
        stop.set()
        for t in threads:
            t.join()
    assert seen and all(n == len(ids) for n in seen)
