"""Every camera pixel's ray of a rig cast onto the ego's ground plane, once per rig geometry.

The renderer moves these fixed ego-frame ground hits by each frame's pose instead of casting
rays per frame. The plane is z = 0 in the ego frame (roll, pitch and height of the pose are
ignored); rays above the horizon, or hitting beyond ``MAX_DEPTH``, see sky / haze. Casts are
cached per rig geometry (``rays_for``): every synthetic drive has the same rig. No I/O, no
painting or colour here.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import CameraRig

MAX_DEPTH = 250.0  # m; ground hits beyond are haze
_KEEP_RIGS = 4  # rigs whose rays are kept (least recently used dropped)


@dataclass(frozen=True)
class RigRays:
    """Every pixel's ray of a rig cast onto the ego's ground plane (shared by the renderers of
    the same rig: every synthetic drive has the same one)."""

    dir_planes: NDArray[np.float32]  # (C, 3, H, W) ray directions, ego frame
    origins: NDArray[np.float64]  # (C, 3) camera centres, ego frame
    depth: NDArray[np.float32]  # (C, H, W) ray parameter of the ground hit, inf off the ground
    hit_full: NDArray[np.float32]  # (C, H, W, 2) ground hit, ego frame
    ground_flat: NDArray[np.int64]  # (N,) pixels that see the ground, into C*H*W
    hit: NDArray[np.float32]  # (N, 2) their ground hits
    fog: NDArray[np.float32]  # (N, 1) haze weight with distance
    sky_weight: NDArray[np.float64]  # (C, H, W, 1) zenith share of the sky colour


#: The casts of the rigs seen last, by rig geometry (least recently used dropped).
rays_cache: OrderedDict[bytes, RigRays] = OrderedDict()


def rays_for(rig: CameraRig) -> RigRays:
    """The cast rays of ``rig``, from the cache when a rig of the same geometry was seen."""
    key = (
        np.asarray(rig.image_size, np.int64).tobytes()
        + np.asarray(rig.intrinsics, np.float64).tobytes()
        + np.asarray(rig.cam_to_ego, np.float64).tobytes()
    )
    rays = rays_cache.get(key)
    if rays is None:
        rays = cast_rays(rig)
        rays_cache[key] = rays
        while len(rays_cache) > _KEEP_RIGS:
            rays_cache.popitem(last=False)
    rays_cache.move_to_end(key)
    return rays


def cast_rays(rig: CameraRig) -> RigRays:
    """Casts every pixel's ray of ``rig`` (uncached); ValueError for a camera below the ground."""
    h, w = rig.image_size
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)  # (H, W) each
    pix = np.stack([u, v, np.ones_like(u)], axis=-1)  # (H, W, 3)
    k_inv = np.linalg.inv(rig.intrinsics)  # (C, 3, 3)
    d_cam = np.einsum("cij,hwj->chwi", k_inv, pix)  # (C, H, W, 3)
    d = np.einsum("cij,chwj->chwi", rig.cam_to_ego[:, :3, :3], d_cam)  # (C, H, W, 3) ego frame
    o = rig.cam_to_ego[:, :3, 3]  # (C, 3)
    if np.any(o[:, 2] <= 0):
        raise ValueError("every camera must be mounted above the ground (cam_to_ego z > 0)")
    dz = d[..., 2]  # (C, H, W)
    down = dz < -1e-6
    lam = np.where(down, -o[:, 2, None, None] / np.where(down, dz, -1.0), np.inf)  # (C, H, W)
    dist = lam * np.linalg.norm(d, axis=-1)  # (C, H, W)
    ground = dist < MAX_DEPTH
    hit = o[:, None, None, :2] + np.where(ground, lam, 0.0)[..., None] * d[..., :2]  # (C,H,W,2)
    ground_flat = np.flatnonzero(ground)  # (N,) into C*H*W
    fog = 1.0 - np.exp(-dist.reshape(-1)[ground_flat] / 160.0)  # (N,)
    elev = dz / np.linalg.norm(d, axis=-1)  # (C, H, W) sine of elevation
    return RigRays(
        dir_planes=np.ascontiguousarray(d.transpose(0, 3, 1, 2)).astype(np.float32),
        origins=o,
        depth=np.where(ground, lam, np.inf).astype(np.float32),
        hit_full=hit.astype(np.float32),
        ground_flat=ground_flat,
        hit=hit.reshape(-1, 2)[ground_flat].astype(np.float32),
        fog=fog.astype(np.float32)[:, None],
        sky_weight=np.clip(elev * 3.0, 0.0, 1.0)[..., None],
    )
