"""torch Datasets (clips, sequences, image cache, collate) and source specs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from icmapper.data.datasets import ClipDataset, ImageCache, SequenceDataset, collate_clips
from icmapper.data.sources import open_source
from icmapper.data.types import (
    CameraRig,
    MapClass,
    MapInstance,
    RANGE_60x30,
    Sequence,
    WorldMap,
    xy_yaw_to_pose,
)
from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

H, W, C = 4, 6, 2


class CountingRender:
    """A fake renderer: frame i is filled with i; counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, i: int) -> np.ndarray:
        self.calls += 1
        return np.full((C, 3, H, W), i, dtype=np.uint8)


def _seq(name: str, n: int) -> Sequence:
    xs = np.linspace(-200, 200, 41)
    world = WorldMap(name, [MapInstance(5, MapClass.DIVIDER, np.stack([xs, 0 * xs], 1), False)])
    rig = CameraRig(("A", "B"), np.stack([np.eye(3)] * C), np.stack([np.eye(4)] * C), (H, W))
    poses = np.stack([xy_yaw_to_pose(2.0 * i, 1.0, 0.0) for i in range(n)])
    return Sequence(name, "sim", world, np.arange(n) * 0.5, poses, rig, CountingRender())


def test_clip_items_enumerate_all_clips() -> None:
    ds = ClipDataset([_seq("a", 5), _seq("b", 3)], clip_len=3, rng=RANGE_60x30)
    assert len(ds) == 3 + 1
    item = ds[3]
    assert item["seq_name"] == "b" and item["frame_indices"].tolist() == [0, 1, 2]
    assert item["images"].shape == (3, C, 3, H, W) and item["images"].dtype == torch.uint8
    assert item["images"][2].max() == 2
    assert item["intrinsics"].shape == (3, C, 3, 3) and item["intrinsics"].dtype == torch.float32
    assert item["cam_to_ego"].shape == (3, C, 4, 4) and item["cam_to_ego"].dtype == torch.float32
    assert item["poses"].shape == (3, 4, 4) and item["poses"].dtype == torch.float64
    assert len(item["gt"]) == 3
    g = item["gt"][1]
    assert g["ids"].dtype == torch.int64 and g["classes"].dtype == torch.int64
    assert g["points"].shape == (1, 20, 2) and g["points"].dtype == torch.float32
    assert g["ids"].tolist() == [5000] and torch.allclose(g["points"][0, :, 1], torch.tensor(-1.0))
    with pytest.raises(IndexError):
        ds[4]


def test_random_clips_are_deterministic() -> None:
    seqs = [_seq("a", 8), _seq("b", 6)]
    a = ClipDataset(seqs, clip_len=2, seed=7, samples_per_epoch=10)
    b = ClipDataset(seqs, clip_len=2, seed=7, samples_per_epoch=10)
    assert len(a) == 10
    clips = [a.clip(i) for i in range(10)]
    assert clips == [b.clip(i) for i in reversed(range(10))][::-1]  # order-independent
    assert all(0 <= start <= len(seqs[s]) - 2 for s, start in clips)
    a.set_epoch(1)
    assert [a.clip(i) for i in range(10)] != clips
    assert ClipDataset(seqs, clip_len=2, seed=8, samples_per_epoch=10).clip(0) is not None


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="clip_len"):
        ClipDataset([_seq("a", 3)], clip_len=0)
    with pytest.raises(ValueError, match="frames"):
        ClipDataset([_seq("a", 3)], clip_len=4)
    with pytest.raises(ValueError, match="no sequences"):
        SequenceDataset([])


def test_sequence_dataset_and_no_images() -> None:
    ds = SequenceDataset([_seq("a", 4)], images=False)
    item = ds[0]
    assert item["images"] is None and item["frame_indices"].tolist() == [0, 1, 2, 3]
    seq = _seq("b", 2)
    seq.render = None
    with pytest.raises(ValueError, match="no images"):
        SequenceDataset([seq])[0]


def test_image_cache(tmp_path: Path) -> None:
    seq = _seq("x/y", 3)
    ds = SequenceDataset([seq], cache_dir=tmp_path)
    first = ds[0]["images"]
    assert seq.render.calls == 3
    path = ImageCache(tmp_path).path(seq, 2)
    assert path == tmp_path / "x_y" / "00002.npy" and path.is_file()
    assert not list(tmp_path.rglob(".tmp-*"))
    assert torch.equal(ds[0]["images"], first) and seq.render.calls == 3  # served from disk
    path.write_bytes(b"corrupt")  # an interrupted or broken entry is re-rendered
    assert torch.equal(ds[0]["images"], first) and seq.render.calls == 4


def test_image_cache_fill_in_shards(tmp_path: Path) -> None:
    seqs = [_seq("a", 3), _seq("b", 4)]
    cache = ImageCache(tmp_path)
    assert cache.fill(seqs, 1, 2) == 3  # frames 1, 3, 5 of the flat list of 7
    assert cache.fill(seqs, 0, 2) == 4
    assert cache.fill(seqs, 0, 1) == 0  # nothing left: an interrupted fill goes on from here
    assert sum(s.render.calls for s in seqs) == 7
    assert len(list(tmp_path.rglob("*.npy"))) == 7
    with pytest.raises(ValueError, match="shard"):
        cache.fill(seqs, 2, 2)


def test_collate() -> None:
    ds = ClipDataset([_seq("a", 4)], clip_len=2)
    batch = collate_clips([ds[0], ds[1]])
    assert batch["images"].shape == (2, 2, C, 3, H, W)
    assert batch["poses"].shape == (2, 2, 4, 4) and batch["frame_indices"].tolist() == [
        [0, 1],
        [1, 2],
    ]
    assert len(batch["gt"]) == 2 and len(batch["gt"][0]) == 2
    assert batch["seq_name"] == ["a", "a"]
    with pytest.raises(ValueError, match="differ"):
        collate_clips([ds[0], ClipDataset([_seq("b", 4)], clip_len=3)[0]])
    with pytest.raises(ValueError, match="empty"):
        collate_clips([])


def test_dataloader_workers_match_serial() -> None:
    ds = ClipDataset([_seq("a", 6)], clip_len=2, seed=3, samples_per_epoch=4)
    serial = [ds[i]["frame_indices"].tolist() for i in range(4)]
    loader = torch.utils.data.DataLoader(ds, batch_size=1, num_workers=2, collate_fn=collate_clips)
    assert [b["frame_indices"][0].tolist() for b in loader] == serial


def test_source_specs_errors() -> None:
    for bad in ("sim", "sim:dev", "sim:val:x", "sim:val:0", "foo:bar", "av2:", "av2-drives:3"):
        with pytest.raises(ValueError):
            open_source(bad)
    with pytest.raises(ValueError):
        open_source("av2:/nonexistent/path")


def test_source_nuscenes(tmp_path: Path) -> None:
    root = write_nuscenes_fixture(tmp_path / "nus", "v1.0-mini")
    seqs = open_source(f"nuscenes:{root}", image_size=(32, 88), render=False)
    assert len(seqs) == 3
    with pytest.raises(ValueError, match="split file"):
        open_source(f"nuscenes:{root}:val", render=False)
    (root / "splits.json").write_text('{"train": ["scene-0001"], "val": ["scene-0002"]}')
    (val,) = open_source(f"nuscenes:{root}:val", render=False)
    assert val.name == "scene-0002"


def test_source_av2(shared_data: Path) -> None:
    root = shared_data / "av2-mini"
    seqs = open_source(f"av2:{root}", image_size=(32, 88), render=False)
    assert len(seqs) == 3 and all(s.source == "av2" for s in seqs)


def test_sim_clip_dataset_end_to_end() -> None:
    seqs = open_source("sim:val:1", image_size=(32, 88))
    ds = ClipDataset(seqs, clip_len=2, samples_per_epoch=2, seed=0)
    batch = collate_clips([ds[0], ds[1]])
    c = seqs[0].rig.num_cameras
    assert batch["images"].shape == (2, 2, c, 3, 32, 88)
    assert batch["images"].float().std() > 0  # really rendered
    ids = [set(g["ids"].tolist()) for g in batch["gt"][0]]
    assert ids[0] & ids[1]  # consecutive frames share GT ids
