"""Training the decoder on cached BEV features of a frozen encoder (``stage1.freeze_encoder``).

A full stage-1 step runs the backbone and the view transformer on every camera of every frame;
once they are trained, the decoder, the query propagation and the association head can go on
learning from the BEVs those parts produce, which cost nothing to re-read. ``encode_sequences``
runs the frozen encoder (backbone, view transformer, BEV neck, temporal memory) over each whole
sequence, exactly as inference streams it, and keeps every frame's fused BEV (float16) in a cache
folder keyed by the encoder's parameter digest; ``BevClipDataset`` serves clips of those BEVs with
the clips' poses and ground truth, in the layout of ``ClipDataset`` with ``bev`` (T, C, X, Y) in
place of the images. Cache files are written atomically and read with ``weights_only=True``; a
stale or corrupt file is recomputed. Data-parallel ranks each encode their share of the
sequences, then read the others' after a barrier; the encoder runs on its own device and the cache
is kept on the CPU.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from icmapper.atomic import atomic_open
from icmapper.data.datasets import ClipDataset, SequenceDataset, collate_clips
from icmapper.data.sources import Sequence
from icmapper.data.types import PerceptionRange
from icmapper.models.detector import MapDetector

#: The detector's sub-modules that make the BEV (frozen with ``stage1.freeze_encoder``).
ENCODER_PARTS = ("backbone", "view", "neck", "memory", "seg")


def encoder_digest(detector: MapDetector, image_size: tuple[int, int]) -> str:
    """A short hash of the encoder's parameters and buffers and the image size."""
    h = hashlib.sha256(repr(tuple(image_size)).encode())
    for part in ENCODER_PARTS[:-1]:  # the segmentation head does not change the BEV
        for name, t in getattr(detector, part).state_dict().items():
            h.update(name.encode())
            h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def _load(path: Path, frames: int) -> torch.Tensor | None:
    """The cached BEVs (T, C, X, Y) float16 of ``path``, or None when missing, corrupt or of
    another length."""
    if not path.is_file():
        return None
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
        bev = blob["bev"]
    except Exception:  # corrupt or foreign: recompute
        return None
    if not isinstance(bev, torch.Tensor) or bev.dim() != 4 or bev.shape[0] != frames:
        return None
    return bev


def stream_bev(detector: MapDetector, item: dict) -> Iterator[torch.Tensor]:
    """The fused BEV (1, C, X, Y) of each frame of one sequence item (``SequenceDataset``),
    streamed as at inference: the encoder only (``MapDetector.encode_stream``), the memory carried
    from frame to frame. Call it under ``torch.no_grad()`` unless gradients are wanted."""
    from icmapper.training.objectives import prev_to_cur

    dev = next(detector.parameters()).device  # the item's tensors go where the encoder is
    poses = item["poses"][None].to(dev)  # (1, T, 4, 4)
    state = None
    for t in range(item["images"].shape[0]):
        motion = prev_to_cur(poses, t) if t > 0 else None
        bev, state = detector.encode_stream(
            item["images"][None, t].to(dev),
            item["intrinsics"][None, t].to(dev),
            item["cam_to_ego"][None, t].to(dev),
            state,
            motion,
        )  # fmt: skip  (1, C, X, Y)
        yield bev


@torch.no_grad()
def encode_sequence(detector: MapDetector, item: dict) -> torch.Tensor:
    """The fused BEV of every frame of one sequence item (``stream_bev``) -> (T, C, X, Y)
    float16 on the CPU."""
    return torch.stack([bev[0].half().cpu() for bev in stream_bev(detector, item)])


def encode_sequences(
    detector: MapDetector,
    sequences: list[Sequence],
    rng: PerceptionRange,
    cache_dir: str | Path,
    image_size: tuple[int, int],
    image_cache: str | Path | None = None,
    log: Callable[[str], None] | None = None,
    shard: tuple[int, int] = (0, 1),
    wait: Callable[[], None] | None = None,
) -> list[torch.Tensor]:
    """Per sequence its BEVs (T, C, X, Y) float16, read from ``cache_dir/bev-<digest>/`` or
    computed there (the detector's encoder in eval mode, no gradients).

    With ``shard = (rank, world_size)`` (data-parallel training) this process encodes only the
    missing sequences i with i % world_size == rank, calls ``wait`` (a barrier: every rank has
    written its share), then reads the others' from the cache; a sequence still missing then
    (another rank failed to write it) is encoded here."""
    rank, world = shard
    if not 0 <= rank < world:
        raise ValueError(f"encode_sequences: bad shard {shard}; expected (rank, world_size)")
    was_training = detector.training
    detector.eval()
    root = Path(cache_dir) / f"bev-{encoder_digest(detector, image_size)}"
    root.mkdir(parents=True, exist_ok=True)
    ds = SequenceDataset(sequences, rng, cache_dir=image_cache)
    paths = [
        root / f"{hashlib.sha256(seq.name.encode()).hexdigest()[:12]}-{i:05d}.pt"
        for i, seq in enumerate(sequences)
    ]
    mine: dict[int, torch.Tensor] = {}

    def encode(i: int) -> torch.Tensor:
        bev = encode_sequence(detector, ds[i])
        with atomic_open(paths[i], "wb") as fh:
            torch.save({"bev": bev, "name": sequences[i].name}, fh)
        return bev

    try:
        for i in range(rank, len(sequences), world):  # this rank's share
            bev = _load(paths[i], len(sequences[i]))
            mine[i] = bev if bev is not None else encode(i)
            if log is not None and (i + 1) % 8 == 0:
                log(f"BEV cache: {i + 1}/{len(sequences)} sequences in {root}")
        if wait is not None:
            wait()
        bevs = []
        for i, seq in enumerate(sequences):
            bev = mine.get(i)
            if bev is None:
                bev = _load(paths[i], len(seq))
            bevs.append(bev if bev is not None else encode(i))
    finally:
        detector.train(was_training)
    return bevs


class BevClipDataset(Dataset):
    """Clips of cached BEVs: item i is ``ClipDataset``'s item i (poses, ground truth, cameras)
    without images and with ``bev`` (T, C, X, Y) float16. Collate with ``collate_bev_clips``."""

    def __init__(
        self,
        sequences: list[Sequence],
        bevs: list[torch.Tensor],
        clip_len: int,
        rng: PerceptionRange,
        seed: int = 0,
    ) -> None:
        if len(bevs) != len(sequences):
            raise ValueError(f"{len(bevs)} BEV tensors for {len(sequences)} sequences")
        for seq, bev in zip(sequences, bevs, strict=True):
            if bev.shape[0] != len(seq):
                raise ValueError(f"sequence {seq.name}: {bev.shape[0]} BEVs for {len(seq)} frames")
        self.clips = ClipDataset(sequences, clip_len, rng, seed=seed, images=False)
        self.bevs = bevs

    def set_epoch(self, epoch: int) -> None:
        self.clips.set_epoch(epoch)

    def __len__(self) -> int:
        return len(self.clips)

    def __getitem__(self, index: int) -> dict:
        s, start = self.clips.clip(int(index))
        item = self.clips[int(index)]
        item["bev"] = self.bevs[s][start : start + self.clips.clip_len]  # (T, C, X, Y)
        return item


def collate_bev_clips(items: list[dict]) -> dict:
    """``collate_clips`` plus ``bev`` (B, T, C, X, Y) float32."""
    out = collate_clips(items)
    out["bev"] = torch.stack([it["bev"] for it in items]).float()
    return out


def frames_of(bevs: list[torch.Tensor]) -> int:
    """Total frames held by ``bevs``."""
    return int(np.sum([b.shape[0] for b in bevs]))
