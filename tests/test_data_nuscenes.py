"""nuScenes reader on a tiny written fixture: tables, poses, rig, map extraction, splits, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.data import gt, nuscenes
from icmapper.data.errors import DataError
from icmapper.data.types import MapClass, RANGE_60x30
from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

VERSION = "v1.0-mini"


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    return write_nuscenes_fixture(tmp_path / "nus", VERSION)


def test_reads_scenes_poses_and_rig(root: Path) -> None:
    seqs = nuscenes.load_nuscenes(root, VERSION, image_size=(32, 88), render=False)
    assert [s.name for s in seqs] == ["scene-0001", "scene-0002", "scene-0003"]
    s = seqs[1]
    assert len(s) == 5 and s.source == "nuscenes"
    assert np.allclose(np.diff(s.timestamps), 0.5)
    assert np.allclose(s.poses[:, 0, 3], 80.0 + 5.0 * np.arange(5))
    assert np.allclose(s.poses[:, 1, 3], -1.75)
    assert s.rig.names == nuscenes.NUSCENES_CAMERAS and s.rig.image_size == (32, 88)
    k = s.rig.intrinsics[0]
    assert np.isclose(k[0, 0], 1266.4 * 88 / 1600) and np.isclose(k[1, 2], 491.5 * 32 / 900)
    front = s.rig.cam_to_ego[0]
    assert np.allclose(front[:3, 2], [1, 0, 0], atol=1e-9)  # optical axis forward
    assert np.allclose(front[:3, :3] @ front[:3, :3].T, np.eye(3), atol=1e-9)


def test_map_extraction(root: Path) -> None:
    seqs = nuscenes.load_nuscenes(root, VERSION, render=False)
    world = seqs[2].world  # x in [140, 155]: both crossings within the 100 m margin
    by_cls = {c: [i for i in world.instances if i.cls == c] for c in MapClass}
    assert len(by_cls[MapClass.DIVIDER]) == 3  # two lane dividers + the road divider
    # The two touching halves of the crossing at x = 100 are unioned: 2 crossings, not 3.
    assert len(by_cls[MapClass.PED_CROSSING]) == 2
    big = max(by_cls[MapClass.PED_CROSSING], key=lambda i: np.ptp(i.points[:, 1]))
    assert np.ptp(big.points[:, 1]) == pytest.approx(14.0)
    # One boundary: the contour of the whole road (road segments and lanes unioned).
    (b,) = by_cls[MapClass.BOUNDARY]
    assert np.allclose(b.points[0], b.points[-1])
    assert np.allclose(b.points.min(axis=0), [0, -7]) and np.allclose(
        b.points.max(axis=0), [400, 7]
    )
    ids = [i.id for i in world.instances]
    assert len(ids) == len(set(ids))


def test_gt_ids_are_derived_and_stable(root: Path) -> None:
    (s,) = [
        q for q in nuscenes.load_nuscenes(root, VERSION, render=False) if q.name == "scene-0002"
    ]
    frames = gt.sequence_gt(s, RANGE_60x30)
    assert all(len(f) > 0 for f in frames)
    div_ids = [set(f.ids[f.classes == MapClass.DIVIDER].tolist()) for f in frames]
    assert all(d == div_ids[0] for d in div_ids) and len(div_ids[0]) == 3


def test_split_file(root: Path, tmp_path: Path) -> None:
    split = tmp_path / "split.json"
    split.write_text(
        json.dumps(
            {
                "source": "x",
                "train": ["scene-0001", "scene-0003"],
                "val": ["scene-0002", "scene-9999"],
            }
        )
    )
    train = nuscenes.load_nuscenes(root, VERSION, split_file=split, split="train", render=False)
    assert [s.name for s in train] == ["scene-0001", "scene-0003"]
    val = nuscenes.load_nuscenes(root, VERSION, split_file=split, split="val", render=False)
    assert [s.name for s in val] == ["scene-0002"]
    with pytest.raises(DataError, match="unknown split 'test'"):
        nuscenes.load_nuscenes(root, VERSION, split_file=split, split="test", render=False)
    with pytest.raises(ValueError, match="both"):
        nuscenes.load_nuscenes(root, VERSION, split="val", render=False)


def test_shared_newsplit(shared_data: Path) -> None:
    path = shared_data / "splits" / "nuscenes_newsplit.json"
    assert path.is_file(), f"the shared data lacks {path}"
    train = nuscenes.read_split(path, "train")
    val = nuscenes.read_split(path, "val")
    assert len(train) == 698 and len(val) == 148 and not set(train) & set(val)
    with pytest.raises(DataError, match="available"):
        nuscenes.read_split(path, "source")  # not a list of scenes


def test_missing_table(root: Path) -> None:
    (root / VERSION / "ego_pose.json").unlink()
    with pytest.raises(DataError, match="ego_pose.json"):
        nuscenes.load_nuscenes(root, VERSION, render=False)


def test_malformed_table(root: Path) -> None:
    (root / VERSION / "sample.json").write_text("[{")
    with pytest.raises(DataError, match="sample.json"):
        nuscenes.load_nuscenes(root, VERSION, render=False)


def test_missing_map(root: Path) -> None:
    (root / "maps" / "expansion" / "test-town.json").unlink()
    with pytest.raises(DataError, match="test-town.json"):
        nuscenes.load_nuscenes(root, VERSION, render=False)


def test_map_missing_layer(root: Path) -> None:
    path = root / "maps" / "expansion" / "test-town.json"
    data = json.loads(path.read_text())
    del data["ped_crossing"]
    path.write_text(json.dumps(data))
    with pytest.raises(DataError, match="ped_crossing"):
        nuscenes.load_nuscenes(root, VERSION, render=False)


def test_scene_without_samples(tmp_path: Path) -> None:
    root = write_nuscenes_fixture(tmp_path / "nus", VERSION, scene_lengths=(3, 0))
    with pytest.raises(DataError, match="scene-0002 has no samples"):
        nuscenes.load_nuscenes(root, VERSION, render=False)


def test_missing_version_folder(root: Path) -> None:
    with pytest.raises(DataError, match="v1.0-trainval"):
        nuscenes.load_nuscenes(root, "v1.0-trainval", render=False)
