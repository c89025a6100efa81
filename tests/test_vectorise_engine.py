"""The engine's vectoriser (``icmapper._icmap.vectorise``, Rust ``icmap_geom::vectorise``) against
the former Python one (``icmapper.testing.vectorise_reference``): the same instances on recorded
masks of the shipped checkpoint (``tests/data/vectorise_masks.npz``, recorded by
``scripts/record_vectorise_masks.py``: 64 frames of sim:val:12, among them every frame of that
source whose crossing outlines start at a vertex GEOS picks from its buffer graph), for the
shipped settings and for variants that exercise the other branches; the binding's contract."""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from icmapper import _icmap
from icmapper.models import vectorise as vec
from icmapper.models.vectorise import VectoriseParams, vectorise
from icmapper.testing.vectorise_reference import vectorise_reference

DATA = Path(__file__).resolve().parent / "data" / "vectorise_masks.npz"


def _frames() -> tuple[list[np.ndarray], float, float]:
    d = np.load(DATA)
    hx, hy = (float(v) for v in d["_half"])
    return [d[k] for k in d.files if k != "_half"], hx, hy


def _assert_same(prob: np.ndarray, hx: float, hy: float, p: VectoriseParams) -> int:
    ref = vectorise_reference(prob, hx, hy, p)
    got = vectorise(prob, hx, hy, p)
    np.testing.assert_array_equal(got.classes, ref.classes)  # counts and order per class
    assert got.points.shape == ref.points.shape and got.points.dtype == np.float32
    if len(ref):
        assert float(np.abs(got.points - ref.points).max()) <= 1e-3
        np.testing.assert_allclose(got.scores, ref.scores, atol=1e-6)
    return len(ref)


def test_same_instances_as_the_reference_on_recorded_masks() -> None:
    """The shipped settings: every instance of every recorded frame, counts equal and points
    within 1e-3 m (they agree to the bit in float32 on these and on all 1934 frames of the
    caches they were taken from)."""
    frames, hx, hy = _frames()
    assert len(frames) >= 60 and frames[0].shape == (3, 50, 25)
    per_class = np.zeros(3, int)
    for prob in frames:
        _assert_same(prob, hx, hy, VectoriseParams())
        per_class += np.bincount(vectorise(prob, hx, hy).classes, minlength=3)
    assert (per_class > 50).all(), per_class  # crossings, dividers and boundaries all tested


@pytest.mark.parametrize(
    "change",
    [
        {"through": 0.0, "spur": 0.0},  # lines cut at every junction
        {"ridge_classes": ()},  # dividers by the plain threshold
        {"ridge_classes": (1, 2), "through": 30.0, "spur": 2.0},
        {"rectangularity": 0.0},  # touching crossings not split
        {"edge_margin": 0.0},  # ridge lines along the front and back edges kept
        {"edge_margin": 3.0, "edge_span": 1.0},
        {"bend": 0.0},  # ridge lines not cut where they bend
        {"bend": 20.0, "min_length": 1.0},
        {"band": 0.0},  # kerb bands kept as their skeletons
        {"band": 1.1},
        {"hull_simplify": 0.0},  # minimum rotated rectangles
        {"shrink": 0.0},
        {"upsample": 3, "num_points": 7},
        {"upsample": 1},
    ],
    ids=lambda c: ",".join(f"{k}={v}" for k, v in c.items()),
)
def test_same_instances_with_other_settings(change: dict[str, object]) -> None:
    frames, hx, hy = _frames()
    p = replace(VectoriseParams(), **change)
    assert sum(_assert_same(prob, hx, hy, p) for prob in frames[::4]) > 20


def test_parallel_classes_and_concurrent_calls_give_the_same_result() -> None:
    frames, hx, hy = _frames()
    kw = {"ridge_classes": [1]}
    serial = [_icmap.vectorise(f, hx, hy, parallel=False, **kw) for f in frames[:12]]
    par = [_icmap.vectorise(f, hx, hy, parallel=True, **kw) for f in frames[:12]]
    threaded: list[object] = [None] * 12

    def work(k: int) -> None:
        for i in range(k, 12, 3):
            threaded[i] = _icmap.vectorise(frames[i], hx, hy, parallel=False, **kw)

    workers = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    for a, b, c in zip(serial, par, threaded, strict=True):
        for x, y, z in zip(a, b, c, strict=True):  # type: ignore[call-overload]
            np.testing.assert_array_equal(x, y)
            np.testing.assert_array_equal(x, z)


def test_the_runtime_does_not_import_the_reference() -> None:
    import inspect

    assert "vectorise_reference" not in inspect.getsource(vec.vectorise)
    assert "_icmap.vectorise" in inspect.getsource(vec.vectorise)


def test_binding_contract() -> None:
    prob = np.zeros((3, 10, 5), np.float32)
    classes, scores, points = _icmap.vectorise(prob, 30.0, 15.0)
    assert classes.dtype == np.int64 and scores.dtype == np.float32
    assert points.shape == (0, 20, 2) and points.dtype == np.float32
    with pytest.raises(TypeError):
        _icmap.vectorise(prob.astype(np.float64), 30.0, 15.0)  # float32 only
    with pytest.raises(TypeError):
        _icmap.vectorise(prob[0], 30.0, 15.0)  # (K, X, Y) only
    bad = prob.copy()
    bad[1, 2, 2] = np.inf
    with pytest.raises(ValueError, match="non-finite"):
        _icmap.vectorise(bad, 30.0, 15.0)
    with pytest.raises(ValueError, match="threshold"):
        _icmap.vectorise(prob, 30.0, 15.0, threshold=1.0)
    with pytest.raises(ValueError, match="ridge_classes"):
        _icmap.vectorise(prob, 30.0, 15.0, ridge_classes=[0])
    with pytest.raises(ValueError, match="ridge_classes"):
        _icmap.vectorise(prob, 30.0, 15.0, ridge_classes=[-1])
    with pytest.raises(ValueError, match="half_x"):
        _icmap.vectorise(prob, float("nan"), 15.0)
    with pytest.raises(ValueError, match="upsampled grid"):
        _icmap.vectorise(np.zeros((1, 200, 200), np.float32), 30.0, 15.0, upsample=64)
    with pytest.raises(ValueError, match=r"\(K, X, Y\)"):
        _icmap.vectorise(np.zeros((3, 0, 5), np.float32), 30.0, 15.0)
    # a non-contiguous view is read as it is
    wide = np.zeros((3, 10, 10), np.float32)
    wide[0, 2:8, 1:9:2] = 0.95
    a = _icmap.vectorise(wide[:, :, ::2], 30.0, 15.0)
    b = _icmap.vectorise(np.ascontiguousarray(wide[:, :, ::2]), 30.0, 15.0)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_ridge_lines_along_the_front_and_back_edges_are_dropped() -> None:
    """The edge rule fires on the recorded masks, on dividers only, and only on lines lying along
    the front or back edge of the grid (what it drops is there with ``edge_margin = 0``)."""
    frames, hx, hy = _frames()
    dropped = 0
    for prob in frames:
        keep = vectorise(prob, hx, hy)
        every = vectorise(prob, hx, hy, VectoriseParams(edge_margin=0.0))
        for c in (0, 2):  # crossings and boundaries untouched
            np.testing.assert_array_equal(keep.points[keep.classes == c],
                                          every.points[every.classes == c])  # fmt: skip
        kept = {p.tobytes() for p in keep.points[keep.classes == 1]}
        for p in every.points[every.classes == 1]:
            if p.tobytes() in kept:
                continue
            dropped += 1
            assert (np.abs(p[:, 0]) > hx - 1.5).mean() > 0.8 and np.ptp(p[:, 1]) > 3.0
    assert dropped > 0


def test_the_edge_rule_on_a_hand_made_mask() -> None:
    """A divider ridge across the grid at its front edge goes; the same line a metre inside stays
    (50x25 cells over 60x30 m)."""
    prob = np.zeros((3, 50, 25), np.float32)
    prob[1, 49, 4:20] = 0.95  # the last row of cells: x in [28.8, 30]
    assert len(vectorise(prob, 30.0, 15.0, VectoriseParams(edge_margin=0.0))) == 1
    assert len(vectorise(prob, 30.0, 15.0)) == 0
    prob = np.roll(prob, -3, axis=1)  # 3.6 m inside
    assert len(vectorise(prob, 30.0, 15.0)) == 1
