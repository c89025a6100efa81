"""A lane-line view that runs beside its instance is another line (``MapperConfig.beside_gate``,
``mapping.passed.lies_beside``, the merge step in ``mapping.merge``): its track leaves the
instance and the view goes in as a new one, instead of being spliced into the instance so that
the map draws the two lines as one weaving between them."""

from __future__ import annotations

import numpy as np
import pytest
from icmapper import GlobalMap
from icmapper.data.types import MapClass, RANGE_60x30
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.crossings import CrossingMerger
from icmapper.mapping.merge import merge_frame
from icmapper.mapping.passed import lies_beside
from icmapper.mapping.tracker import Tracker
from numpy.typing import NDArray

XS = np.linspace(0.0, 40.0, 41)


def line(y: float, x0: float = 0.0, x1: float = 40.0, n: int = 20) -> NDArray[np.float64]:
    """A straight line along x at height y, n points (metres)."""
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], -1)


def test_lies_beside() -> None:
    """Beside: most of the view's points that project inside the stored line lie farther than
    the gate; on it, past its end or crossing it: not beside."""
    stored = line(0.0)
    assert lies_beside(line(3.0, 5.0, 35.0), stored, 2.0)  # the neighbouring lane's line
    assert not lies_beside(line(0.4, 5.0, 35.0), stored, 2.0)  # the same line, detector noise
    assert not lies_beside(line(3.0, 5.0, 35.0), stored, 3.5)  # within a wider gate
    assert not lies_beside(line(0.2, 30.0, 70.0), stored, 2.0)  # runs on past the end
    assert not lies_beside(line(3.0, 45.0, 70.0), stored, 2.0)  # wholly past the end: no say
    # a stub across the line projects onto one station: at most a few points lie inside
    assert not lies_beside(line(0.0, 0.0, 0.5, 2), stored, 2.0)
    assert not lies_beside(line(3.0), stored[:1], 2.0)  # a one-point instance has no inside


def frame(
    global_map: GlobalMap,
    tracker: Tracker,
    alias: dict[int, int],
    track_ids: NDArray[np.int64],
    views: NDArray[np.float32],
    gate: float,
) -> tuple[list[int], list[int], list[int]]:
    """One merge step of unfused divider views (m, P, 2), the ego at the world origin."""
    m = len(track_ids)
    return merge_frame(
        global_map,
        CrossingMerger("average", RANGE_60x30),
        tracker,
        alias,
        MapperConfig(beside_gate=gate, min_hits=1),
        classes=np.full(m, int(MapClass.DIVIDER), np.int64),
        scores=np.full(m, 0.9, np.float32),
        track_ids=track_ids,
        fused=views,
        was_fused=np.zeros(m, bool),
        detected=views,
        pose=np.eye(4),
        frame_index=1,
        on_failure=lambda *a: pytest.fail(f"merge failed: {a}"),
    )


def setup() -> tuple[GlobalMap, Tracker, dict[int, int]]:
    """A map with lane line 0 at y = 0 and a buffer with track 0 (the line's own track) and
    track 1, aliased into instance 0 (e.g. a stub the instance absorbed) but following the
    neighbouring lane's line at y = 3."""
    gm = GlobalMap(smoothing=0.5, spacing=1.0)
    gm.insert_with_id(0, int(MapClass.DIVIDER), line(0.0, n=41), frame=0)
    tracker = Tracker()
    views = np.stack([line(0.0), line(3.0)]).astype(np.float32)
    ids = tracker.assign(np.zeros((2, 0)), np.full(2, 1), views, np.eye(4))
    assert ids.tolist() == [0, 1]
    return gm, tracker, {1: 0}


@pytest.mark.parametrize("gate", [0.0, 2.0])
def test_an_aliased_track_beside_its_instance_becomes_its_own(gate: float) -> None:
    """The aliased track's view 3 m beside the instance: with the rule it leaves the alias and
    goes in as instance 1, and instance 0 stays on its line; without it (gate 0) it is merged
    into instance 0, which leaves its line."""
    gm, tracker, alias = setup()
    views = np.stack([line(0.1, 5.0, 35.0), line(3.0, 5.0, 35.0)]).astype(np.float32)
    ids = np.array([0, 1], np.int64)
    inserted, merged, split = frame(gm, tracker, alias, ids, views, gate)
    far = np.abs(np.asarray(gm.get(0)[1])[:, 1]).max()
    if gate > 0:
        assert split == [1] and inserted == [1] and alias == {}
        assert far < 0.5
        np.testing.assert_allclose(np.asarray(gm.get(1)[1])[:, 1], 3.0, atol=1e-6)
    else:
        assert split == [] and inserted == [] and alias == {1: 0}
        assert far > 2.0  # the instance now weaves out to the other line
        assert 1 not in gm


def test_an_own_track_beside_its_instance_gets_a_fresh_id() -> None:
    """A track whose view runs beside its own instance (the association took the neighbouring
    line) gets a fresh id, its view a new instance; the instance keeps its line."""
    gm, tracker, alias = setup()
    alias.clear()
    before = np.asarray(gm.get(0)[1]).copy()
    ids = np.array([0], np.int64)
    inserted, merged, split = frame(
        gm, tracker, alias, ids, line(3.0, 5.0, 35.0)[None].astype(np.float32), 2.0
    )
    new = int(ids[0])
    assert new == 2 and split == [2] and inserted == [2] and merged == []
    assert tracker.track(2).points[0, 1] == pytest.approx(3.0)
    np.testing.assert_array_equal(np.asarray(gm.get(0)[1]), before)
    with pytest.raises(KeyError):
        tracker.track(0)


def test_beside_gate_is_validated() -> None:
    with pytest.raises(ValueError, match="beside_gate"):
        MapperConfig(beside_gate=-1.0)
