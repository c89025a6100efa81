"""torch Datasets over Sequences: random consecutive clips (stage-1 training) and whole sequences
(stage 2 / evaluation), with images rendered on the fly or read from disk (real-image sources:
JPEG decode + resize in the DataLoader workers, ``icmapper.data.images``) and an optional on-disk
image cache.

Item (a dict; docs/data.md):
    images        uint8   (T, C, 3, H, W)   (absent/None with images=False)
    intrinsics    float32 (T, C, 3, 3)      pixels of the (H, W) images, per keyframe
    cam_to_ego    float32 (T, C, 4, 4)      camera frame x right, y down, z forward, per keyframe
    poses         float64 (T, 4, 4)         ego->world
    gt            list of T dicts {ids int64 (k,), classes int64 (k,), points float32 (k, 20, 2)}
                  ego frame metres; ids stable over the whole sequence
    seq_name      str
    frame_indices int64   (T,)

Determinism: item `index` of ClipDataset draws from numpy's Generator seeded with
(seed, epoch, index), so items do not depend on worker count or order. Cache layout:
`<cache_dir>/<seq name>/<frame:05d>.npy` ((C, 3, H, W) uint8, written to a temp file and
renamed, so an interrupted run leaves no partial file); a cached file of another shape or dtype is
re-rendered. Use one cache_dir per image size / rig / renderer seed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
from numpy.typing import NDArray
from torch.utils.data import Dataset

from icmapper.atomic import atomic_open
from icmapper.data.gt import sequence_gt
from icmapper.data.types import FrameGT, PerceptionRange, RANGE_60x30, Sequence


def _safe_name(name: str) -> str:
    bad = set('/\\:*?"<>|') | {"\0"}
    out = "".join("_" if ch in bad else ch for ch in name)
    if out in ("", ".", ".."):
        raise ValueError(f"sequence name {name!r} cannot name a cache folder")
    return out


class ImageCache:
    """Rendered images of sequences on disk: `<root>/<seq name>/<frame:05d>.npy`."""

    def __init__(self, root: str | Path):
        self.root = Path(root)

    def path(self, seq: Sequence, i: int) -> Path:
        return self.root / _safe_name(seq.name) / f"{i:05d}.npy"

    def get(self, seq: Sequence, i: int) -> NDArray[np.uint8]:
        """Images (C, 3, H, W) uint8 of frame i: read from the cache or rendered and stored."""
        h, w = seq.rig.image_size
        shape = (seq.rig.num_cameras, 3, h, w)
        path = self.path(seq, i)
        if path.is_file():
            try:
                arr = np.load(path, allow_pickle=False)
                if arr.shape == shape and arr.dtype == np.uint8:
                    return arr
            except (OSError, ValueError):
                pass  # corrupt entry: re-render below and overwrite it
        arr = _render(seq, i)
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_open(path, "wb") as f:
            np.save(f, arr, allow_pickle=False)
        return arr

    def fill(
        self, sequences: list[Sequence], shard: int = 0, num_shards: int = 1, log: Any = None
    ) -> int:
        """Renders every frame of ``sequences`` that is not cached yet (frame j of the flat list
        when j % num_shards == shard, so that processes can share the work); interruptible:
        a later call goes on where it stopped. Returns the number of frames rendered."""
        if not 0 <= shard < num_shards:
            raise ValueError(f"shard must be in [0, {num_shards}), got {shard}")
        todo = [(seq, i) for seq in sequences for i in range(len(seq))]
        todo = [t for j, t in enumerate(todo) if j % num_shards == shard]
        done = 0
        for j, (seq, i) in enumerate(todo):
            if not self.path(seq, i).is_file():
                self.get(seq, i)
                done += 1
            if log is not None and (j + 1) % 500 == 0:
                log(f"cache {self.root}: {j + 1}/{len(todo)} frames checked, {done} rendered")
        return done


def _render(seq: Sequence, i: int) -> NDArray[np.uint8]:
    if seq.render is None:
        raise ValueError(f"sequence {seq.name!r} has no images (no renderer); use images=False")
    arr = np.asarray(seq.render(i))
    h, w = seq.rig.image_size
    shape = (seq.rig.num_cameras, 3, h, w)
    if arr.shape != shape or arr.dtype != np.uint8:
        raise ValueError(
            f"renderer of {seq.name!r} gave {arr.dtype} {arr.shape}, expected uint8 {shape}"
        )
    return arr


def _gt_dict(g: FrameGT) -> dict[str, torch.Tensor]:
    return {
        "ids": torch.from_numpy(np.ascontiguousarray(g.ids, dtype=np.int64)),  # (k,)
        "classes": torch.from_numpy(np.ascontiguousarray(g.classes, dtype=np.int64)),  # (k,)
        "points": torch.from_numpy(np.ascontiguousarray(g.points, dtype=np.float32)),  # (k, 20, 2)
    }


class _SequenceItems:
    """Shared machinery: lazily computed sequence GT and item assembly."""

    def __init__(
        self,
        sequences: list[Sequence],
        rng: PerceptionRange,
        cache_dir: str | Path | None,
        images: bool,
    ):
        if not sequences:
            raise ValueError("no sequences given")
        self.sequences = list(sequences)
        self.rng = rng
        self.cache = ImageCache(cache_dir) if cache_dir is not None else None
        self.images = images
        self._gt: dict[int, list[FrameGT]] = {}

    def gt(self, s: int) -> list[FrameGT]:
        if s not in self._gt:
            self._gt[s] = sequence_gt(self.sequences[s], self.rng)
        return self._gt[s]

    def item(self, s: int, frames: NDArray[np.int64]) -> dict:
        seq = self.sequences[s]
        rigs = [seq.rig_of(int(i)) for i in frames]  # each keyframe's own camera parameters
        out: dict = {
            "intrinsics": torch.from_numpy(
                np.stack([r.intrinsics for r in rigs]).astype(np.float32)
            ),  # (T, C, 3, 3)
            "cam_to_ego": torch.from_numpy(
                np.stack([r.cam_to_ego for r in rigs]).astype(np.float32)
            ),  # (T, C, 4, 4)
            "poses": torch.from_numpy(seq.poses[frames].astype(np.float64)),  # (T, 4, 4)
            "gt": [_gt_dict(self.gt(s)[int(i)]) for i in frames],
            "seq_name": seq.name,
            "frame_indices": torch.from_numpy(frames.astype(np.int64)),  # (T,)
        }
        if self.images:
            imgs = [
                self.cache.get(seq, int(i)) if self.cache else _render(seq, int(i)) for i in frames
            ]
            out["images"] = torch.from_numpy(np.stack(imgs))  # (T, C, 3, H, W)
        else:
            out["images"] = None
        return out


class ClipDataset(Dataset):
    """Consecutive clips of `clip_len` frames (stage-1 training).

    samples_per_epoch=None: item i is the i-th clip of all sequences in order (every start
    frame); an int: item i is a random clip drawn with numpy's Generator seeded by
    (seed, epoch, i) (sequences weighted by their number of clips). `set_epoch` changes the draw.
    """

    def __init__(
        self,
        sequences: list[Sequence],
        clip_len: int = 3,
        rng: PerceptionRange = RANGE_60x30,
        seed: int = 0,
        samples_per_epoch: int | None = None,
        cache_dir: str | Path | None = None,
        images: bool = True,
    ):
        if clip_len < 1:
            raise ValueError(f"clip_len must be >= 1, got {clip_len}")
        if samples_per_epoch is not None and samples_per_epoch < 1:
            raise ValueError(f"samples_per_epoch must be >= 1, got {samples_per_epoch}")
        self._items = _SequenceItems(sequences, rng, cache_dir, images)
        self.clip_len = clip_len
        self.seed = int(seed)
        self.epoch = 0
        self.samples_per_epoch = samples_per_epoch
        counts = np.array([max(0, len(s) - clip_len + 1) for s in self._items.sequences])
        if counts.sum() == 0:
            raise ValueError(f"no sequence has {clip_len} frames")
        self._counts = counts  # (S,) clips per sequence
        self._offsets = np.concatenate([[0], np.cumsum(counts)])  # (S + 1,)

    @property
    def sequences(self) -> list[Sequence]:
        return self._items.sequences

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        if self.samples_per_epoch is not None:
            return self.samples_per_epoch
        return int(self._offsets[-1])

    def clip(self, index: int) -> tuple[int, int]:
        """(sequence index, start frame) of item `index`."""
        if not 0 <= index < len(self):
            raise IndexError(f"clip {index} out of range for {len(self)} items")
        if self.samples_per_epoch is None:
            s = int(np.searchsorted(self._offsets, index, side="right") - 1)
            return s, int(index - self._offsets[s])
        g = np.random.default_rng([self.seed, self.epoch, index])
        k = int(g.integers(self._offsets[-1]))
        s = int(np.searchsorted(self._offsets, k, side="right") - 1)
        return s, int(k - self._offsets[s])

    def __getitem__(self, index: int) -> dict:
        s, start = self.clip(int(index))
        return self._items.item(s, np.arange(start, start + self.clip_len, dtype=np.int64))


class SequenceDataset(Dataset):
    """Whole sequences (stage 2 / evaluation): item i is sequence i, all its frames."""

    def __init__(
        self,
        sequences: list[Sequence],
        rng: PerceptionRange = RANGE_60x30,
        cache_dir: str | Path | None = None,
        images: bool = True,
    ):
        self._items = _SequenceItems(sequences, rng, cache_dir, images)

    @property
    def sequences(self) -> list[Sequence]:
        return self._items.sequences

    def __len__(self) -> int:
        return len(self._items.sequences)

    def __getitem__(self, index: int) -> dict:
        if not 0 <= index < len(self):
            raise IndexError(f"sequence {index} out of range for {len(self)} sequences")
        n = len(self._items.sequences[index])
        return self._items.item(int(index), np.arange(n, dtype=np.int64))


def collate_clips(items: list[dict]) -> dict:
    """Stacks items of equal length and rig: tensors get a leading batch dim (B, T, ...);
    `gt` becomes a list (B) of lists (T) of dicts; `seq_name` a list of B names."""
    if not items:
        raise ValueError("collate_clips: empty batch")
    shapes = {tuple(it["poses"].shape) for it in items}
    rigs = {tuple(it["intrinsics"].shape) for it in items}
    if len(shapes) != 1 or len(rigs) != 1:
        raise ValueError(f"collate_clips: items differ in length or rig: {shapes} {rigs}")
    out = {
        key: torch.stack([it[key] for it in items])
        for key in ("intrinsics", "cam_to_ego", "poses", "frame_indices")
    }  # (B, T, ...)
    has = [it.get("images") is not None for it in items]
    if all(has):
        out["images"] = torch.stack([it["images"] for it in items])  # (B, T, C, 3, H, W)
    elif any(has):
        raise ValueError("collate_clips: some items have images and some do not")
    else:
        out["images"] = None
    out["gt"] = [it["gt"] for it in items]
    out["seq_name"] = [it["seq_name"] for it in items]
    return out
