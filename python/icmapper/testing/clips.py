"""Tiny synthetic clips in the ``ClipDataset`` item format, for tests, benchmarks and the training
config's ``data.source = "synthetic:N"`` (smoke runs; no dataset needed).

Images are seeded noise, GT instances random straight/zig-zag polylines and crossings fixed in a
world frame, seen from an ego driving straight ahead. Not a simulator (see ``icmapper.data.sim``).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch.utils.data import Dataset

from icmapper.data.types import PerceptionRange, xy_yaw_to_pose


def default_rig(num_cameras: int, image_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A ring of ``num_cameras`` cameras 1.5 m high: intrinsics (C, 3, 3), cam_to_ego (C, 4, 4)."""
    h, w = image_size
    k = np.array([[0.6 * w, 0, w / 2], [0, 0.6 * w, h / 2], [0, 0, 1]], dtype=np.float32)
    base = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=np.float32)  # cam axes in ego
    exts = []
    for c in range(num_cameras):
        yaw = 2 * math.pi * c / num_cameras
        rz = np.array(
            [[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]],
            dtype=np.float32,
        )
        e = np.eye(4, dtype=np.float32)
        e[:3, :3] = rz @ base
        e[:3, 3] = [0.0, 0.0, 1.5]
        exts.append(e)
    return np.repeat(k[None], num_cameras, 0), np.stack(exts)


class SyntheticClips(Dataset):
    """``num`` clips of ``clip_len`` frames in the item format of ``data.datasets.ClipDataset``."""

    def __init__(
        self,
        num: int,
        clip_len: int,
        rng: PerceptionRange,
        image_size: tuple[int, int],
        num_cameras: int = 6,
        seed: int = 0,
        num_points: int = 20,
    ) -> None:
        if num <= 0 or clip_len <= 0:
            raise ValueError("synthetic clips need num > 0 and clip_len > 0")
        self.num, self.clip_len, self.rng = num, clip_len, rng
        self.image_size, self.num_cameras = image_size, num_cameras
        self.seed, self.num_points = seed, num_points

    def __len__(self) -> int:
        return self.num

    def __getitem__(self, i: int) -> dict:
        if not 0 <= i < self.num:
            raise IndexError(f"clip {i} out of range ({self.num})")
        g = np.random.default_rng([self.seed, i])
        t, c, (h, w), p = self.clip_len, self.num_cameras, self.image_size, self.num_points
        images = torch.from_numpy(g.integers(0, 256, (t, c, 3, h, w), dtype=np.uint8))
        k, e = default_rig(c, (h, w))
        speed = g.uniform(2.0, 6.0)
        poses = np.stack([xy_yaw_to_pose(speed * f, 0.0, 0.0) for f in range(t)])  # (T, 4, 4)
        # world instances: a few lines along x and one crossing
        lines = []
        for j, y in enumerate(g.uniform(-self.rng.half_y + 1, self.rng.half_y - 1, size=3)):
            x = np.linspace(-self.rng.half_x, self.rng.half_x + speed * t, p)
            lines.append((j + 1, 1 + j % 2, np.stack([x, np.full(p, y)], -1)))
        cx, cy = g.uniform(-10, 10), g.uniform(-5, 5)
        ang = np.linspace(0, 2 * np.pi, p, endpoint=False)
        ring = np.stack([cx + 3 * np.cos(ang), cy + 2 * np.sin(ang)], -1)
        lines.append((10, 0, ring))
        gts = []
        for f in range(t):
            ids, cls, pts = [], [], []
            for iid, cl, wpts in lines:
                ego = wpts - poses[f, :2, 3]  # yaw 0: world -> ego is a translation
                if cl != 0:  # open polylines clipped to the range, resampled to p points
                    ego = np.stack(
                        [np.linspace(-self.rng.half_x, self.rng.half_x, p), ego[:, 1]], -1
                    )
                elif np.abs(ego[:, 0]).max() > self.rng.half_x:
                    continue
                ids.append(iid)
                cls.append(cl)
                pts.append(ego)
            gts.append(
                {
                    "ids": torch.tensor(ids, dtype=torch.int64),
                    "classes": torch.tensor(cls, dtype=torch.int64),
                    "points": torch.tensor(np.array(pts), dtype=torch.float32).reshape(-1, p, 2),
                }
            )
        return {
            "images": images,
            "intrinsics": torch.from_numpy(k)[None].repeat(t, 1, 1, 1),
            "cam_to_ego": torch.from_numpy(e)[None].repeat(t, 1, 1, 1),
            "poses": torch.from_numpy(poses),
            "gt": gts,
        }


def collate_clips(items: list[dict]) -> dict:
    """Stacks clip items to (B, T, ...) and keeps gt as a list (B) of lists (T) (same as the data
    module's ``collate_clips``)."""
    out = {k: torch.stack([it[k] for it in items]) for k in items[0] if k != "gt"}
    out["gt"] = [it["gt"] for it in items]
    return out
