"""The ego standing still merges nothing (``MapperConfig.min_travel``): a stopped car's repeated
view does not pile into the map, its detections are still tracked and reported, a turn or a move
merges again, and a run saved during a stop resumes as it was. Frames faster than the keyframes
warn, and ``Sequence.keyframes`` takes a faster sequence back to them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from icmapper.data.sim.rig import nuscenes_rig
from icmapper.data.types import STILL_TURN, Frame, xy_yaw_to_pose
from icmapper.mapping.config import MapperConfig
from icmapper.mapping.mapper import Mapper
from icmapper.mapping.types import Detections

RIG = nuscenes_rig((32, 88))


class _Scripted:
    """A detection source replaying given Detections, one per frame."""

    def __init__(self, frames: list[Detections]) -> None:
        self.frames = frames

    def reset(self) -> None:
        pass

    def detect(self, frame: Frame) -> Detections:
        return self.frames[frame.index]


def _divider(y: float) -> Detections:
    """One lane line 20 m long along x at ``y`` (ego metres), score 0.9."""
    pts = np.stack([np.linspace(-10, 10, 20), np.full(20, y)], -1).astype(np.float32)  # (20, 2)
    return Detections(np.ones(1, np.int64), np.full(1, 0.9, np.float32), pts[None])


def _snapshot(m: Mapper) -> dict[int, bytes]:
    return {int(i): np.asarray(m.global_map.get(int(i))[1]).tobytes() for i in m.global_map.ids()}


def _run(poses: list[tuple[float, float, float]], ys: list[float], **cfg: float) -> tuple:
    """Steps a mapper (positional association, no fusion) through ``poses`` (x, y, yaw) with one
    divider per frame at ego ``ys``; returns the mapper, the step results and the map after each
    step."""
    config = MapperConfig(min_hits=1, detect_threshold=0.0, track_threshold=0.0, **cfg)
    m = Mapper(_Scripted([_divider(y) for y in ys]), config=config)
    results, maps = [], []
    for i, p in enumerate(poses):
        results.append(m.step(Frame(i, 0.5 * i, xy_yaw_to_pose(*p), RIG)))
        maps.append(_snapshot(m))
    return m, results, maps


# a car drives 3 m, stops for three frames (creeping 0.2 m in all; its view wanders 0.2 m
# sideways), then drives on
POSES = [(0.0, 0.0, 0.0), (3.0, 0.0, 0.0), (3.1, 0.0, 0.0), (3.2, 0.0, 0.0), (3.2, 0.0, 0.0),
         (6.0, 0.0, 0.0)]  # fmt: skip
YS = [2.0, 2.0, 2.2, 1.8, 2.2, 2.0]


def test_stop_merges_nothing() -> None:
    m, results, maps = _run(POSES, YS)
    assert m.stats.still == 3
    assert maps[2] == maps[1] and maps[3] == maps[1] and maps[4] == maps[1]
    for r in results[2:5]:
        assert r.inserted == [] and r.merged == []
        # still tracked and reported: the track the map knows
        assert len(r.detections.scores) == 1 and int(r.track_ids[0]) == int(results[1].track_ids[0])
    assert results[5].merged  # driving on merges again
    assert m.merge_pose == pytest.approx((6.0, 0.0, 0.0))


def test_every_frame_merges_without_the_rule() -> None:
    m, results, maps = _run(POSES, YS, min_travel=0.0)
    assert m.stats.still == 0
    assert all(r.merged for r in results[1:])
    assert maps[2] != maps[1]  # the wandering view went in


def test_turning_in_place_merges() -> None:
    turn = np.radians(STILL_TURN + 1.0)
    poses = [(0.0, 0.0, 0.0), (0.0, 0.0, turn), (0.0, 0.0, turn + np.radians(1.0))]
    m, results, _ = _run(poses, [2.0, 2.0, 2.0])
    assert results[1].merged and not results[2].merged
    assert m.stats.still == 1


def test_still_counted_from_the_last_merge() -> None:
    # creeping 0.3 m per frame: every second frame has moved 0.6 m since the last merge
    poses = [(0.3 * i, 0.0, 0.0) for i in range(6)]
    m, results, _ = _run(poses, [2.0] * 6)
    assert [bool(r.merged) for r in results[1:]] == [False, True, False, True, False]
    assert m.stats.still == 3


@pytest.mark.parametrize("bad", [-0.1, float("nan"), float("inf")])
def test_bad_min_travel_refused(bad: float) -> None:
    with pytest.raises(ValueError, match="min_travel"):
        MapperConfig(min_travel=bad)


def test_resume_during_a_stop(tmp_path: Path) -> None:
    full, ref, _ = _run(POSES, YS)
    config = MapperConfig(min_hits=1, detect_threshold=0.0, track_threshold=0.0)
    first = Mapper(_Scripted([_divider(y) for y in YS]), config=config)
    for i in range(3):  # up to the first still frame
        first.step(Frame(i, 0.5 * i, xy_yaw_to_pose(*POSES[i]), RIG))
    path = tmp_path / "stop.icmap"
    first.save_state(path)
    resumed = Mapper(_Scripted([_divider(y) for y in YS]), config=config)
    resumed.resume(path)
    assert resumed.merge_pose == pytest.approx((3.0, 0.0, 0.0))
    got = [resumed.step(Frame(i, 0.5 * i, xy_yaw_to_pose(*POSES[i]), RIG)) for i in range(3, 6)]
    assert [r.merged for r in got] == [r.merged for r in ref[3:]]
    assert resumed.stats.still == full.stats.still == 3
    assert _snapshot(resumed) == _snapshot(full)


def test_frames_faster_than_keyframes_warn_once() -> None:
    """Frames 0.1 s apart (10 Hz) get one warning per sequence naming the keyframe rate; frames
    0.5 s apart (the keyframes) none."""
    import warnings

    config = MapperConfig(min_hits=1, detect_threshold=0.0, track_threshold=0.0)
    m = Mapper(_Scripted([_divider(2.0)] * 6), config=config)
    with pytest.warns(UserWarning, match=r"0\.100 s apart.*2 Hz") as record:
        for i in range(6):
            m.step(Frame(i, 0.1 * i, xy_yaw_to_pose(1.5 * i, 0.0, 0.0), RIG))
    assert len([w for w in record if "apart" in str(w.message)]) == 1
    m.reset()  # a new sequence warns again
    with pytest.warns(UserWarning, match="apart"):
        for i in range(2):
            m.step(Frame(i, 0.1 * i, xy_yaw_to_pose(1.5 * i, 0.0, 0.0), RIG))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m.reset()
        for i in range(6):
            m.step(Frame(i, 0.5 * i, xy_yaw_to_pose(1.5 * i, 0.0, 0.0), RIG))


def test_keyframes_of_a_faster_sequence() -> None:
    """``Sequence.keyframes`` takes a sequence at 10 Hz back to the 2 Hz keyframes: the same
    poses, rigs and images as the drive sampled at 2 Hz; ``select`` refuses indices out of range."""
    from icmapper.data.sources import open_source

    base = open_source("sim:val:1", image_size=(32, 88))[0]
    n = len(base)
    idx = np.repeat(np.arange(n), 5)  # (5n,): every frame held five times
    fast = base.select(idx, "fast")
    fast.timestamps = np.arange(5 * n) * 0.1  # as if at 10 Hz
    keys = fast.keyframes()
    assert keys.name == "fast" and len(keys) == n
    np.testing.assert_array_equal(keys.poses, base.poses)
    np.testing.assert_allclose(np.diff(keys.timestamps), 0.5)
    np.testing.assert_array_equal(keys.frame(3).images, base.frame(3).images)
    assert len(base.keyframes()) == n  # already keyframes: whole
    with pytest.raises(ValueError, match="frame indices"):
        base.select(np.array([0, n]))
