"""Bad input to icmapper.geom and GlobalMap raises a clear Python exception naming the problem:
ValueError for values and shapes, TypeError for types and dtypes, KeyError for unknown ids."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from icmapper import GlobalMap, geom
from icmapper.testing.geom_calls import POSE, point_entry_points

GOOD = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [0.0, 5.0]])  # (4, 2), usable as a ring


def _map() -> GlobalMap:
    m = GlobalMap()
    m.insert(1, GOOD)
    return m


# Every engine function that takes an (n, 2) point array, GOOD as the other line or ring.
POINT_FUNCS = point_entry_points(GOOD, GOOD)

NAN = GOOD.copy()
NAN[1, 0] = np.nan
INF = GOOD.copy()
INF[2, 1] = -np.inf

# (name, bad points, expected exception, regex the message must match)
BAD_POINTS: list[tuple[str, Any, type[Exception], str | None]] = [
    ("nan", NAN, ValueError, "non-finite|NaN"),
    ("inf", INF, ValueError, "non-finite|inf"),
    ("nan_f32", NAN.astype(np.float32), ValueError, "non-finite|NaN"),
    ("shape_n3", np.zeros((4, 3)), ValueError, r"shape \(n, 2\).*\(4, 3\)"),
    ("ndim1", np.zeros(8), ValueError, r"shape \(n, 2\).*\(8,\)"),
    ("ndim3", np.zeros((2, 4, 2)), ValueError, r"shape \(n, 2\).*\(2, 4, 2\)"),
    ("ragged_list", [[0.0, 0.0], [1.0]], ValueError, None),
    ("complex", GOOD.astype(np.complex128), TypeError, "dtype"),
    ("object", GOOD.astype(object), TypeError, "dtype"),
    ("str_array", GOOD.astype(str), TypeError, "dtype"),
    ("str", "0,0;1,1", TypeError, "str"),
    ("bool", GOOD > 1, TypeError, "dtype"),
    ("none", None, TypeError, None),
]

# Too few points: for open polylines fewer than 2; checked per function with its own minimum.
EMPTY = np.zeros((0, 2))
ONE = np.array([[1.0, 2.0]])


@pytest.mark.parametrize("func", sorted(POINT_FUNCS))
@pytest.mark.parametrize("case", BAD_POINTS, ids=[c[0] for c in BAD_POINTS])
def test_bad_points(func: str, case: tuple[str, Any, type[Exception], str | None]) -> None:
    _, bad, exc, pattern = case
    with pytest.raises(exc, match=pattern):
        POINT_FUNCS[func](bad)


@pytest.mark.parametrize("func", sorted(POINT_FUNCS))
@pytest.mark.parametrize("pts", [EMPTY, ONE], ids=["empty", "one_point"])
def test_too_few_points(func: str, pts: np.ndarray) -> None:
    if func.startswith("chamfer") and len(pts) == 1:
        # a single point is a valid Chamfer point set: (mean distance of GOOD's points to it +
        # its distance to the nearest of GOOD's points) / 2
        d = np.linalg.norm(GOOD - pts[0], axis=1)  # (4,)
        got = np.ravel(POINT_FUNCS[func](pts))
        np.testing.assert_allclose(got, [(d.mean() + d.min()) / 2], rtol=1e-12)
        return
    with pytest.raises(ValueError, match="point"):
        POINT_FUNCS[func](pts)


@pytest.mark.parametrize(
    "func",
    ["resample", "resample_spacing", "fit_curve", "insert_divider", "merge_polyline_detected"],
)
def test_degenerate_all_points_identical(func: str) -> None:
    with pytest.raises(ValueError):
        POINT_FUNCS[func](np.ones((5, 2)))


def test_argument_name_in_message() -> None:
    with pytest.raises(ValueError, match="detected_pts"):
        geom.merge_polyline(GOOD, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="global_pts"):
        geom.merge_polyline(np.zeros((3, 3)), GOOD)
    with pytest.raises(ValueError, match=r"b\[1\]"):
        geom.chamfer_matrix([GOOD], [GOOD, np.zeros((2, 3))])
    with pytest.raises(ValueError, match=r"\(A, n, 2\)"):
        geom.chamfer_matrix(np.zeros((3, 2)), [GOOD])


@pytest.mark.parametrize(
    "call",
    [
        lambda: geom.resample(GOOD, 1),
        lambda: geom.resample(GOOD, 0),
        lambda: geom.resample(GOOD, -3),
        lambda: geom.resample(GOOD, 2, closed=True),
        lambda: geom.resample_spacing(GOOD, 0.0),
        lambda: geom.resample_spacing(GOOD, -1.0),
        lambda: geom.resample_spacing(GOOD, float("nan")),
        lambda: geom.fit_curve(GOOD, s=-1.0),
        lambda: geom.fit_curve(GOOD, s=float("nan")),
        lambda: geom.fit_curve(GOOD, spacing=0.0),
        lambda: geom.merge_polyline(GOOD, GOOD, spacing=-1.0),
        lambda: GlobalMap(smoothing=-1.0),
        lambda: GlobalMap(spacing=0.0),
        lambda: GlobalMap(spacing=float("inf")),
    ],
)
def test_bad_parameters(call: Callable[[], Any]) -> None:
    with pytest.raises(ValueError):
        call()


PATCH_CALLS: dict[str, Callable[..., Any]] = {
    "query": lambda pose, he, margin: _map().query(pose, he, margin=margin),
    "sample_patch": lambda pose, he, margin: _map().sample_patch(pose, he, margin=margin),
    "clip_to_patch": lambda pose, he, margin: geom.clip_to_patch(GOOD, pose, he, margin=margin),
}


@pytest.mark.parametrize("func", sorted(PATCH_CALLS))
def test_bad_patch_arguments(func: str) -> None:
    call = PATCH_CALLS[func]
    with pytest.raises(ValueError, match="half_extents"):
        call(POSE, (-1.0, 5.0), 0.0)
    with pytest.raises(ValueError, match="margin"):
        call(POSE, (1.0, 5.0), -2.0)
    with pytest.raises(ValueError, match="pose"):
        call((0.0, float("nan"), 0.0), (1.0, 1.0), 0.0)
    with pytest.raises(ValueError, match="non-finite"):
        call(POSE, (float("inf"), 1.0), 0.0)
    with pytest.raises(ValueError, match="3 values"):
        call((0.0, 0.0), (1.0, 1.0), 0.0)
    with pytest.raises(ValueError, match="2 values"):
        call(POSE, (1.0, 1.0, 1.0), 0.0)
    with pytest.raises(TypeError, match="pose"):
        call("abc", (1.0, 1.0), 0.0)
    with pytest.raises(TypeError, match="pose"):
        call(3.0, (1.0, 1.0), 0.0)
    with pytest.raises(TypeError, match="half_extents"):
        call(POSE, ("a", "b"), 0.0)
    # numpy arrays and numpy scalars are fine
    call(np.array(POSE), np.array([1.0, 1.0], dtype=np.float32), np.float32(1.0))


@pytest.mark.parametrize("n_points", [-1, 0, 1])
def test_sample_patch_n_points_too_small(n_points: int) -> None:
    with pytest.raises(ValueError, match="n_points"):
        _map().sample_patch(POSE, (30, 15), n_points=n_points)


@pytest.mark.parametrize("cls", [3, -1, 100])
def test_unknown_class(cls: int) -> None:
    m = _map()
    with pytest.raises(ValueError, match="unknown map class"):
        m.insert(cls, GOOD)
    with pytest.raises(ValueError, match="unknown map class"):
        m.insert_with_id(50, cls, GOOD)
    assert len(m) == 1
    with pytest.raises(TypeError):
        m.insert("divider", GOOD)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad_id", [1, 99, 2**63, -1])
def test_unknown_id(bad_id: int) -> None:
    m = _map()
    for call in (m.get, m.info, m.remove, lambda i: m.merge(i, GOOD)):
        with pytest.raises(KeyError, match=str(bad_id)):
            call(bad_id)
    assert bad_id not in m
    with pytest.raises(TypeError):
        m.get("0")  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        m.get(0.0)  # type: ignore[arg-type]


def test_bad_paths(tmp_path: Any) -> None:
    m = _map()
    with pytest.raises(TypeError):
        m.save(3)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        GlobalMap.load(None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="id"):
        m.insert_with_id(-5, 1, GOOD)
