"""Argoverse 2 reader: the real mini logs (../shared/data/av2-mini) and small written logs for
the extraction rules and the error paths."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.feather as feather
import pytest
from icmapper.data import av2, extract
from icmapper.data.errors import DataError
from icmapper.data.types import MapClass

CALIBRATED_LOG = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


@pytest.fixture(scope="module")
def logs(shared_data: Path) -> list[Path]:
    root = shared_data / "av2-mini"
    assert root.is_dir(), f"the shared data lacks {root}"
    return av2.find_av2_logs(root)


def _pts(*xy: tuple[float, float]) -> list[dict]:
    return [{"x": x, "y": y, "z": 0.0} for x, y in xy]


def _lane(i: int, y0: float, y1: float, lm: str, rm: str, succ: list[int]) -> dict:
    # Lane along +x between y = y0 (right) and y = y1 (left), x in [0, 50].
    return {
        "id": i,
        "is_intersection": False,
        "lane_type": "VEHICLE",
        "left_lane_boundary": _pts((0, y1), (25, y1), (50, y1)),
        "left_lane_mark_type": lm,
        "right_lane_boundary": _pts((0, y0), (50, y0)),
        "right_lane_mark_type": rm,
        "successors": succ,
        "predecessors": [],
        "right_neighbor_id": None,
        "left_neighbor_id": None,
    }


def write_log(root: Path, poses_ns: np.ndarray | None = None) -> Path:
    """A 2-lane road x in [0, 50], y in [-3.5, 3.5]: a dashed divider at y = 0 listed by both
    lanes, solid white marks on the road edges (they lie on the boundary), one crossing."""
    log = root / "log0"
    (log / "map").mkdir(parents=True)
    archive = {
        "lane_segments": {
            "1": _lane(1, -3.5, 0.0, "DASHED_WHITE", "SOLID_WHITE", []),
            "2": _lane(2, 0.0, 3.5, "NONE", "DASHED_WHITE", []),
        },
        "pedestrian_crossings": {
            "7": {
                "id": 7,
                "edge1": _pts((20, -3.5), (20, 3.5)),
                "edge2": _pts((23, -3.5), (23, 3.5)),
            }
        },
        "drivable_areas": {
            "9": {"id": 9, "area_boundary": _pts((0, -3.5), (50, -3.5), (50, 3.5), (0, 3.5))}
        },
    }
    (log / "map" / "log_map_archive_log0____PIT_city_1.json").write_text(json.dumps(archive))
    ts = np.arange(0, 5_000_000_000, 100_000_000) if poses_ns is None else poses_ns
    n = len(ts)
    table = pa.table(
        {
            "timestamp_ns": pa.array(ts, pa.int64()),
            "qw": np.ones(n),
            "qx": np.zeros(n),
            "qy": np.zeros(n),
            "qz": np.zeros(n),
            "tx_m": np.linspace(0, 40, n),
            "ty_m": np.full(n, -1.75),
            "tz_m": np.zeros(n),
        }
    )
    feather.write_feather(table, log / av2.POSE_FILE)
    return log


def test_real_worlds(logs: list[Path]) -> None:
    assert len(logs) == 3
    for log in logs:
        world = av2.load_av2_world(log)
        classes = {int(i.cls) for i in world.instances}
        assert classes == {0, 1, 2}, log.name
        ids = [i.id for i in world.instances]
        assert len(ids) == len(set(ids))
        for inst in world.instances:
            assert inst.points.ndim == 2 and inst.points.shape[1] == 2
            assert np.all(np.isfinite(inst.points))
            assert inst.closed == (inst.cls == MapClass.PED_CROSSING)
            if inst.cls == MapClass.DIVIDER:
                assert inst.style and inst.style not in ("none", "unknown")
        dividers = [i.points for i in world.instances if i.cls == MapClass.DIVIDER]
        for a in range(len(dividers)):  # de-duplicated: no two dividers overlap
            for b in range(a + 1, len(dividers)):
                assert not extract.overlaps(dividers[a], dividers[b])
        assert world.lanes and all(lane.width > 1.0 for lane in world.lanes.values())
        for lane in world.lanes.values():
            assert all(s in world.lanes for s in lane.successors)


def test_real_poses_2hz(logs: list[Path]) -> None:
    t, poses = av2.load_av2_poses(logs[0])
    assert poses.shape == (len(t), 4, 4) and len(t) > 20
    assert np.allclose(np.diff(t), 0.5, atol=0.02)
    r = poses[:, :3, :3]
    assert np.allclose(r @ r.transpose(0, 2, 1), np.eye(3), atol=1e-9)


def test_real_rig(logs: list[Path]) -> None:
    by_name = {log.name: log for log in logs}
    rig = av2.load_av2_rig(by_name[CALIBRATED_LOG], image_size=(32, 88))
    assert rig is not None and rig.names == av2.AV2_RING_CAMERAS and rig.image_size == (32, 88)
    assert np.allclose(rig.cam_to_ego[0][:3, 2], [1, 0, 0], atol=0.01)  # front looks forward
    assert np.allclose(rig.intrinsics[0, 0, 2], 777.990573 * 88 / 1550)
    assert np.allclose(rig.intrinsics[0, 1, 2], 1013.524325 * 32 / 2048)
    others = [log for log in logs if log.name != CALIBRATED_LOG]
    assert av2.load_av2_rig(others[0]) is None


def test_extraction_rules(tmp_path: Path) -> None:
    world = av2.load_av2_world(write_log(tmp_path))
    div = [i for i in world.instances if i.cls == MapClass.DIVIDER]
    # y = 0 is listed by both lanes -> one divider; the edge marks lie on the boundary -> dropped.
    assert len(div) == 1 and np.allclose(div[0].points[:, 1], 0.0)
    assert div[0].style == "dashed_white"
    (cross,) = [i for i in world.instances if i.cls == MapClass.PED_CROSSING]
    assert cross.id == 7 and cross.style == "zebra"
    assert np.allclose(cross.points, [[20, -3.5], [20, 3.5], [23, 3.5], [23, -3.5]])
    (bound,) = [i for i in world.instances if i.cls == MapClass.BOUNDARY]
    assert np.allclose(bound.points[0], bound.points[-1]) and len(bound.points) >= 5
    assert set(world.lanes) == {1, 2}
    assert np.allclose(world.lanes[1].centerline[:, 1], -1.75)
    assert world.lanes[1].width == pytest.approx(3.5)


def test_sequence_without_images(tmp_path: Path) -> None:
    seq = av2.load_av2_sequence(write_log(tmp_path), image_size=(32, 88), render=False)
    assert seq.source == "av2" and seq.render is None and len(seq) == 10
    assert np.allclose(seq.poses[:, 2, 3], 0.0)


def test_sequence_renders(logs: list[Path]) -> None:
    seq = av2.load_av2_sequence(logs[0], image_size=(32, 88))
    img = seq.frame(0).images
    assert img is not None and img.dtype == np.uint8 and img.shape == (6, 3, 32, 88)
    by_name = {log.name: log for log in logs}
    seq7 = av2.load_av2_sequence(by_name[CALIBRATED_LOG], image_size=(32, 88), rig="av2")
    assert seq7.rig.num_cameras == 7 and seq7.render is not None
    with pytest.raises(DataError, match="calibration"):
        av2.load_av2_sequence(logs[0] if logs[0].name != CALIBRATED_LOG else logs[1], rig="av2")


def test_av2_drives(logs: list[Path]) -> None:
    drives = av2.av2_drives(logs[0], 2, seed=3, image_size=(32, 88), render=False)
    again = av2.av2_drives(logs[0], 2, seed=3, image_size=(32, 88), render=False)
    assert [d.name for d in drives] == [f"{logs[0].name}-drive{k}" for k in range(2)]
    assert all(len(d) > 1 for d in drives)
    assert np.array_equal(drives[0].poses, again[0].poses)
    assert not np.array_equal(drives[0].poses[:2], drives[1].poses[:2])


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="not found"):
        av2.load_av2_world(tmp_path / "nope")
    log = write_log(tmp_path)
    (log / av2.POSE_FILE).unlink()
    with pytest.raises(DataError, match=av2.POSE_FILE):
        av2.load_av2_poses(log)
    for f in (log / "map").iterdir():
        f.unlink()
    with pytest.raises(DataError, match="log_map_archive"):
        av2.load_av2_world(log)


def test_malformed_archive(tmp_path: Path) -> None:
    log = write_log(tmp_path)
    (path,) = (log / "map").iterdir()
    path.write_text("{not json")
    with pytest.raises(DataError, match="malformed"):
        av2.load_av2_world(log)
    path.write_text(json.dumps({"lane_segments": {}, "pedestrian_crossings": {}}))
    with pytest.raises(DataError, match="drivable_areas"):
        av2.load_av2_world(log)


def test_bad_poses(tmp_path: Path) -> None:
    dup = write_log(tmp_path / "a", np.array([0, 100, 100, 200]))
    with pytest.raises(DataError, match="duplicated"):
        av2.load_av2_poses(dup)
    gap = write_log(tmp_path / "b", np.array([0, 100_000_000, 1_500_000_000]))
    with pytest.raises(DataError, match="gap"):
        av2.load_av2_poses(gap)
