"""Absorption in the online mapper (``MapperConfig.absorb``), the confirmation of new tracks
(``min_hits``, ``confirm_score``) and the map NMS offered to every
method (``MapperConfig.map_nms``): hand-made detections whose right map is known."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.sources import open_source
from icmapper.data.types import Frame, RANGE_60x30, Sequence
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.map_nms import map_nms
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.methods import method
from icmapper.mapping.run import map_sequence
from icmapper.mapping.types import Detections


def line(x0: float, x1: float, y: float, n: int = 20) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], -1).astype(np.float32)


class Scripted:
    """Fixed ego-frame detections per frame index (the same for every pose)."""

    def __init__(self, frames: dict[int, list[tuple[int, np.ndarray]]]) -> None:
        self.frames = frames
        self.score = 0.9

    def reset(self) -> None:
        pass

    def detect(self, frame: Frame) -> Detections:
        items = self.frames.get(frame.index, [])
        if not items:
            return Detections.empty()
        return Detections(
            classes=np.array([c for c, _ in items], np.int64),
            scores=np.full(len(items), self.score, np.float32),
            points=np.stack([p for _, p in items]).astype(np.float32),
        )


@pytest.fixture(scope="module")
def still() -> Sequence:
    """A drive whose first frames serve as poses (the detections are scripted)."""
    return open_source("sim:val:1", image_size=(32, 88), render=False)[0]


#: Frame 0: a long divider. Frame 1: the divider and a piece of it 0.3 m off, 12 m long, which
#: the tracker takes for another instance (one-to-one) and re-identification may not rename.
SCRIPT = {
    0: [(1, line(-25, 25, 2.0))],
    1: [(1, line(-25, 25, 2.0)), (1, line(-5, 7, 2.3))],
    2: [(1, line(-25, 25, 2.0)), (1, line(-5, 7, 2.3))],
}


def _run(still: Sequence, cfg: MapperConfig) -> Mapper:
    m = Mapper(Scripted(SCRIPT), config=cfg)
    m.reset()
    for i in range(3):
        m.step(still.frame(i, with_images=False))
    return m


def test_a_piece_on_an_instance_is_absorbed_and_its_track_maps_into_it(still: Sequence) -> None:
    # re-identification off, one hit enough: the piece enters the map as its own instance;
    # the assignment by scores alone (the script's lines stay put in the ego frame, so they
    # slide 5 m along themselves from frame to frame, and weighed by what they share the
    # piece's second view opens a third track: the tracker's business, not absorption's)
    base = MapperConfig(reid_distance=0.0, min_hits=1, assign_cover=0.0)
    apart = _run(still, replace(base, absorb=False))
    assert len(apart.global_map) == 2
    joined = _run(still, base)
    assert len(joined.global_map) == 1
    assert joined.stats.absorbed == 1
    (kept,) = [int(i) for i in joined.global_map.ids()]
    # the piece's track maps into the kept instance, which took its observation (frames 1, 2)
    piece_track = max(int(t.id) for t in joined.tracker.tracks)
    assert joined.alias == {piece_track: kept}
    assert joined.global_map.info(kept)["observations"] == 5
    # the kept divider is the long one as the map without absorption has it (the piece adds
    # nothing beyond it), moved by at most the piece's 0.3 m offset
    _, pts = joined.global_map.get(kept)
    long_id = min(int(i) for i in apart.global_map.ids())
    _, ref = apart.global_map.get(long_id)
    d = np.linalg.norm(pts[:, None] - ref[None], axis=-1).min(1)  # (n,) to the nearest vertex
    assert d.max() <= 0.3 + 0.5  # + half the 1 m spacing of the stored vertices
    assert len(pts) >= len(ref) - 1


def test_absorption_survives_save_and_resume(still: Sequence, tmp_path: Path) -> None:
    cfg = MapperConfig(reid_distance=0.0, min_hits=1)
    m = Mapper(Scripted(SCRIPT), config=cfg)
    m.reset()
    for i in range(2):
        m.step(still.frame(i, with_images=False))
    path = tmp_path / "run.icmap"
    m.global_map.save(str(path))
    m.save_state(path)
    resumed = Mapper(Scripted(SCRIPT), config=cfg)
    resumed.resume(path)
    assert resumed.stats.absorbed == m.stats.absorbed == 1
    assert resumed.alias == m.alias
    m.step(still.frame(2, with_images=False))
    resumed.step(still.frame(2, with_images=False))
    assert len(resumed.global_map) == len(m.global_map) == 1


def test_map_nms_cleans_any_method_and_only_when_asked(still: Sequence) -> None:
    cfg = MapperConfig(baseline_threshold=0.3, map_nms=False)
    counts = {}
    for nms in (False, True):
        post = method("post-track").build(Scripted(SCRIPT), replace(cfg, map_nms=nms), RANGE_60x30)
        frames, gmap = map_sequence(post, _three(still), with_images=False)
        counts[nms] = len(gmap)
        assert len(frames) == 3  # per-frame output is the same either way
    assert counts == {False: 2, True: 1}


def test_map_nms_on_a_hand_made_map() -> None:
    from icmapper import GlobalMap

    gm = GlobalMap()
    long_ = gm.insert(2, line(0, 60, 0).astype(np.float64))
    gm.insert(2, line(10, 30, 0.4).astype(np.float64))  # a copy of a stretch of the kerb
    lane = gm.insert(2, line(0, 60, 3.5).astype(np.float64))  # the next kerb: stays
    assert map_nms(gm, MapperConfig()) == 1
    assert sorted(int(i) for i in gm.ids()) == [long_, lane]
    assert map_nms(gm, MapperConfig()) == 0  # nothing left to absorb


def test_boundaries_absorb_with_their_own_wider_gate() -> None:
    """A kerb seen twice 1.3 m apart is one kerb (``absorb_boundary_gate`` 1.5 m); two dividers
    1.3 m apart stay two (``absorb_gate`` 1 m); with the boundary gate at 1 m both stay."""
    from icmapper import GlobalMap
    from icmapper.mapping.absorb import absorb_pairs

    def two(cls: int) -> tuple[GlobalMap, list[int]]:
        gm = GlobalMap()
        ids = [gm.insert(cls, line(0, 40, 0).astype(np.float64)),
               gm.insert(cls, line(5, 25, 1.3).astype(np.float64))]  # fmt: skip
        return gm, ids

    gm, (kerb, view) = two(2)
    assert absorb_pairs(gm, [view], MapperConfig()) == [(view, kerb)]
    assert [int(i) for i in gm.ids()] == [kerb]
    gm, (a, b) = two(1)
    assert absorb_pairs(gm, [b], MapperConfig()) == []
    gm, (kerb, view) = two(2)
    assert absorb_pairs(gm, [view], MapperConfig(absorb_boundary_gate=1.0)) == []
    assert len(gm) == 2
    with pytest.raises(ValueError, match="absorb_boundary_gate"):
        MapperConfig(absorb_boundary_gate=0.0)


def _three(seq: Sequence) -> Sequence:
    """The first three frames of ``seq``."""
    return replace(seq, timestamps=seq.timestamps[:3], poses=seq.poses[:3])


def test_map_nms_removes_stubs_across_lanes_only() -> None:
    from icmapper import GlobalMap
    from icmapper.mapping.map_nms import stubs_across

    gm = GlobalMap()
    lane = gm.insert(1, line(0, 60, 0).astype(np.float64))
    across = gm.insert(1, np.array([[20.0, -2.0], [20.0, 2.0]]))  # 4 m, at 90 degrees: a stub
    slant = gm.insert(1, np.array([[30.0, -3.0], [37.15, 3.0]]))  # 9.3 m at 40 degrees: kept
    long_ = gm.insert(1, np.array([[45.0, -8.0], [45.0, 8.0]]))  # 16 m across: kept
    kerb = gm.insert(2, np.array([[10.0, -2.0], [10.0, 2.0]]))  # another class: kept
    apart = gm.insert(1, np.array([[70.0, -2.0], [70.0, 2.0]]))  # crosses nothing: kept
    assert stubs_across(gm, 10.0, 45.0) == [across]
    assert stubs_across(gm, 15.0, 45.0) == [across]  # the default length
    assert stubs_across(gm, 20.0, 45.0) == [across, long_]
    assert stubs_across(gm, 0.0, 45.0) == []  # off
    assert map_nms(gm, MapperConfig()) == 1
    assert sorted(int(i) for i in gm.ids()) == sorted([lane, slant, long_, kerb, apart])


def test_is_stub_and_drop_stubs_on_a_hand_made_map() -> None:
    """IC-Mapper's online rule (``drop_stubs``): a short divider across a longer stored one is a
    stub; ``drop_stubs`` removes the stubs among the touched dividers and their neighbours, the
    stub itself or the line it crosses being touched."""
    from icmapper import GlobalMap
    from icmapper.mapping.map_nms import drop_stubs, is_stub

    gm = GlobalMap()
    lane = gm.insert(1, line(0, 60, 0).astype(np.float64))
    across = np.array([[20.0, -2.0], [20.0, 2.0]])  # 4 m at 90 degrees
    assert is_stub(gm, across, 15.0, 45.0)
    assert not is_stub(gm, across, 0.0, 45.0)  # off
    assert not is_stub(gm, across + [0.0, 3.0], 15.0, 45.0)  # ends before the line
    assert not is_stub(gm, np.array([[30.0, -3.0], [37.15, 3.0]]), 15.0, 45.0)  # 40 degrees
    assert not is_stub(gm, np.array([[45.0, -8.0], [45.0, 8.0]]), 15.0, 45.0)  # 16 m
    kerb = gm.insert(2, across)  # another class: never a stub
    stub = gm.insert(1, across + [10.0, 0.0])
    # its own id is skipped: a stored stub is tested against the others
    assert is_stub(gm, gm.get(stub)[1], 15.0, 45.0, skip=stub)
    assert drop_stubs(gm, [kerb], 15.0, 45.0) == []  # nothing touched among the dividers
    assert drop_stubs(gm, [lane], 0.0, 45.0) == []  # off
    assert drop_stubs(gm, [lane], 15.0, 45.0) == [stub]  # the line it crosses was touched
    later = gm.insert(1, across + [35.0, 0.0])
    assert drop_stubs(gm, [later, 999], 15.0, 45.0) == [later]  # the stub itself; unknown ids
    assert sorted(int(i) for i in gm.ids()) == sorted([lane, kerb])


#: Frames 0-2: a long lane line; frame 1 also a 5 m stub across it (0.9 scores: confirmed at
#: once).
CROSSED = {i: [(1, line(-25, 25, 2.0))] for i in range(3)}
CROSSED[1] = CROSSED[1] + [(1, np.stack([np.full(20, 3.0), np.linspace(-0.5, 4.5, 20)], -1))]


@pytest.mark.parametrize("drop", [True, False])
def test_the_mapper_keeps_stubs_across_lanes_out(still: Sequence, drop: bool) -> None:
    """With ``drop_stubs`` (the default) a stub seen across a stored lane line never enters the
    map; without it, it does (and ``stats.stubs`` counts nothing)."""
    m = Mapper(Scripted(CROSSED), config=MapperConfig(drop_stubs=drop))
    map_sequence(m, _three(still), with_images=False)
    assert len(m.global_map) == (1 if drop else 2)
    assert m.stats.stubs == 0  # kept out at insertion, not removed later


def test_a_removed_stub_takes_its_aliases_along() -> None:
    """A track aliased into a stub that ``drop_stubs`` removes maps into its own id again."""
    m = Mapper(Scripted({}), config=MapperConfig())
    m.reset()
    gm = m.global_map
    lane = gm.insert(1, line(0, 60, 0).astype(np.float64))
    stub = gm.insert(1, np.array([[20.0, -4.0], [20.0, 4.0]]))  # 8 m across: not absorbed
    m._alias.update({77: stub, 78: lane})
    m._absorb([lane])
    assert stub not in gm and m.stats.stubs == 1
    assert m._alias == {78: lane}


def test_a_confident_first_sighting_enters_the_map_at_once(still: Sequence) -> None:
    """``confirm_score``: with ``min_hits`` 2 a divider seen in one frame only enters the map when
    its score reaches ``confirm_score``; a weaker one stays tentative (kept out)."""
    once = {1: [(1, line(-25, 25, 2.0))]}

    def mapped(score: float, confirm: float) -> int:
        src = Scripted(once)
        src.score = score
        m = Mapper(src, config=MapperConfig(min_hits=2, confirm_score=confirm))
        m.reset()
        for i in range(3):
            m.step(still.frame(i, with_images=False))
        return len(m.global_map)

    assert mapped(0.9, 0.7) == 1
    assert mapped(0.6, 0.7) == 0
    assert mapped(0.9, 1.0) == 0  # the former rule: min_hits frames for everyone
    with pytest.raises(ValueError, match="confirm_score"):
        MapperConfig(confirm_score=1.5)
