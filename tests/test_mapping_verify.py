"""The finished map checked against the drive's own detections (``MapperConfig.verify``,
``mapping.verify``), for every method: hand-made drives whose right map is known."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from icmapper import GlobalMap
from icmapper.data.sources import open_source
from icmapper.data.types import Frame, RANGE_60x30, Sequence
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.methods import method
from icmapper.mapping.run import map_sequence
from icmapper.mapping.types import Detections
from icmapper.mapping.verify import MIN_TRIM, check

#: The car drives along y = 0 from x = 0, 3 m per frame, 8 frames.
STEP, FRAMES = 3.0, 8


def line(x0: float, x1: float, y: float, n: int = 20) -> np.ndarray:
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], -1)  # (n, 2) float64


def pose(i: int) -> np.ndarray:
    p = np.eye(4)
    p[0, 3] = STEP * i
    return p  # (4, 4) ego -> world


#: World lines (class, points) and the frames that detect them. The road's lane line is
#: detected in every frame; a stray piece 6 m beside it only in frame 0, though it stays in view
#: until the end; a true piece at the range's far edge only in the last frame, the one frame it
#: is in view.
LANE = (1, line(-60.0, 80.0, 0.0, 141))
STRAY = (1, line(20.0, 26.0, 6.0))
EDGE = (2, line(48.0, 52.0, -10.0))
SEEN = {0: [LANE, STRAY], **{i: [LANE] for i in range(1, FRAMES - 1)}, FRAMES - 1: [LANE, EDGE]}


def detections(i: int) -> Detections:
    """Frame ``i``'s detections of ``SEEN`` in the ego frame, resampled to 20 points."""
    from icmapper.eval.globalmap import dense_sample

    items = SEEN.get(i, [])
    pts = []
    for _, w in items:
        ego = w - pose(i)[:2, 3]  # (n, 2): the ego frame is the world shifted (no rotation)
        inside = (np.abs(ego[:, 0]) <= 30.0) & (np.abs(ego[:, 1]) <= 15.0)
        pts.append(dense_sample(ego[inside], False, 0.1)[np.linspace(0, -1, 20).astype(int)])
    return Detections(
        classes=np.array([c for c, _ in items], np.int64),
        scores=np.full(len(items), 0.9, np.float32),
        points=np.stack(pts).astype(np.float32) if pts else np.zeros((0, 20, 2), np.float32),
    )


class WorldScripted:
    """``detections`` of each frame, whatever the frame's images."""

    def reset(self) -> None:
        pass

    def detect(self, frame: Frame) -> Detections:
        return detections(frame.index)


@pytest.fixture(scope="module")
def drive() -> Sequence:
    """``FRAMES`` frames along the x axis (a synthetic drive's other fields; no images)."""
    seq = open_source("sim:val:1", image_size=(32, 88), render=False)[0]
    return replace(
        seq,
        timestamps=np.arange(FRAMES) * 0.5,
        poses=np.stack([pose(i) for i in range(FRAMES)]),
    )


def _frames() -> list[tuple[np.ndarray, Detections]]:
    return [(pose(i), detections(i)) for i in range(FRAMES)]


def _map() -> tuple[GlobalMap, dict[str, int]]:
    gm = GlobalMap()
    ids = {name: gm.insert(c, pts) for name, (c, pts) in
           {"lane": LANE, "stray": STRAY, "edge": EDGE}.items()}  # fmt: skip
    return gm, ids


def removed(frames: list, cfg: MapperConfig, keep: set[int] | frozenset = frozenset()) -> list:
    gm, _ = _map()
    return check(gm, frames, cfg, RANGE_60x30, keep).removed


def test_an_instance_the_drive_does_not_back_is_removed() -> None:
    gm, ids = _map()
    cfg = MapperConfig()
    assert removed(_frames(), cfg) == [ids["stray"]]
    # the stray was in view in all 8 frames and detected in 1: with verify_share 0.9 (7 of 8
    # frames missed is 0.875) or verify_frames 8 (it was missed in 7) it stays
    assert removed(_frames(), replace(cfg, verify_share=0.9)) == []
    assert removed(_frames(), replace(cfg, verify_frames=8)) == []
    # a continued map's earlier instances are left alone
    assert removed(_frames(), cfg, keep={ids["stray"]}) == []
    # detections below track_threshold back nothing: the lane line goes too, the edge piece,
    # in view in one frame, stays
    weak = [(p, replace(d, scores=np.full(len(d.scores), 0.3, np.float32))) for p, d in _frames()]
    assert removed(weak, cfg) == sorted([ids["lane"], ids["stray"]])
    verdict = check(gm, _frames(), cfg, RANGE_60x30).apply(gm)
    assert verdict.removed == [ids["stray"]] and verdict.trimmed == {}
    assert sorted(int(i) for i in gm.ids()) == sorted([ids["lane"], ids["edge"]])


def test_a_line_drawn_past_what_is_there_loses_the_unbacked_end() -> None:
    """The lane line is stored 12 m longer at its start than any detection draws it (x -72 to
    -60): the car sees that end in its first frames, where nothing backs it, so it is cut off;
    the backed rest stays as stored, with its bookkeeping. An overshoot shorter than
    ``MIN_TRIM`` stays."""
    for extra, cut in ((12.0, True), (MIN_TRIM / 2, False)):
        gm = GlobalMap()
        lane = gm.insert(1, line(-60.0 - extra, 80.0, 0.0, int(141 + extra)))
        before = np.asarray(gm.get(lane)[1])
        obs = gm.info(lane)["observations"]
        frames = [(_at(-50.0 + STEP * i), _seen_from(-50.0 + STEP * i)) for i in range(FRAMES)]
        verdict = check(gm, frames, MapperConfig(), RANGE_60x30).apply(gm)
        after = np.asarray(gm.get(lane)[1])
        assert verdict.removed == []
        if cut:
            a, b = verdict.trimmed[lane]
            assert b == len(before) and np.array_equal(after, before[a:b])
            assert -61.0 <= after[0, 0] <= -58.0  # cut where the backed line begins
            assert gm.info(lane)["observations"] == obs
        else:
            assert verdict.trimmed == {} and np.array_equal(after, before)


def _at(x: float) -> np.ndarray:
    p = np.eye(4)
    p[0, 3] = x
    return p  # (4, 4) ego -> world


def _seen_from(x: float) -> Detections:
    """The lane line as detected from ego position ``x``: its part in range from x = -60 on."""
    ego = LANE[1] - np.array([x, 0.0])  # (n, 2)
    inside = ego[np.abs(ego[:, 0]) <= 30.0]
    pts = inside[np.linspace(0, len(inside) - 1, 20).astype(int)]
    return Detections(
        classes=np.array([1]),
        scores=np.array([0.9], np.float32),
        points=pts[None].astype(np.float32),
    )


def test_a_car_standing_still_is_one_view() -> None:
    """The same frame 8 times (a car at a light) is one frame of evidence: fewer than
    ``verify_frames``, so nothing is removed."""
    frames = [(pose(1), detections(1))] * FRAMES
    assert removed(frames, MapperConfig()) == []


@pytest.mark.parametrize("name", ["icmapper", "post-track", "polymerge"])
def test_every_method_verifies_its_map_and_only_when_asked(drive: Sequence, name: str) -> None:
    cfg = MapperConfig(min_hits=1, use_association=False, use_fusion=False)
    counts = {}
    for verify in (False, True):
        c = replace(cfg, verify=verify)
        if name == "icmapper":
            m = Mapper(WorldScripted(), config=c)
        else:
            m = method(name).build(WorldScripted(), c, RANGE_60x30)
        frames, gmap = map_sequence(m, drive, with_images=False)
        assert len(frames) == FRAMES  # per-frame output is the same either way
        near_stray = [
            int(i) for i in gmap.ids()
            if np.abs(np.asarray(gmap.get(int(i))[1])[:, 1] - 6.0).max() < 0.5
        ]  # fmt: skip
        counts[verify] = (len(gmap), len(near_stray))
    assert counts[False][1] == 1  # the stray piece is mapped
    assert counts[True] == (counts[False][0] - 1, 0)  # and only it goes


def test_a_drive_without_frames_or_detections_removes_nothing_it_never_saw() -> None:
    """No frames: nothing was in view, nothing goes. Frames without detections: the instances in
    view are missed (the lane line, the stray), the edge piece (in view in one frame) stays."""
    gm, ids = _map()
    assert check(gm, [], MapperConfig(), RANGE_60x30).removed == []
    empty = [(pose(i), Detections.empty()) for i in range(FRAMES)]
    assert removed(empty, MapperConfig()) == sorted([ids["lane"], ids["stray"]])
    assert (
        len(GlobalMap()) == 0
        and check(GlobalMap(), empty, MapperConfig(), RANGE_60x30).removed == []
    )


def test_bad_frames_are_refused_naming_the_frame() -> None:
    gm, _ = _map()
    bad_pose = _frames()
    bad_pose[2] = (np.full((4, 4), np.nan), bad_pose[2][1])
    with pytest.raises(ValueError, match="frame 2: the pose"):
        check(gm, bad_pose, MapperConfig(), RANGE_60x30)
    d = detections(1)
    nan = replace(d, points=np.where(np.isnan(d.points), 0, np.nan).astype(np.float32))
    with pytest.raises(ValueError, match="frame 1: detection points must be finite"):
        check(gm, [(pose(0), detections(0)), (pose(1), nan)], MapperConfig(), RANGE_60x30)
    flat = replace(d, points=d.points.reshape(len(d.classes), -1))
    with pytest.raises(ValueError, match="frame 0: detection points must be"):
        check(gm, [(pose(0), flat)], MapperConfig(), RANGE_60x30)
    assert len(gm) == 3  # nothing removed


def test_verify_settings_are_checked() -> None:
    with pytest.raises(ValueError, match="verify_share"):
        MapperConfig(verify_share=0.0)
    with pytest.raises(ValueError, match="verify_frames"):
        MapperConfig(verify_frames=0)
