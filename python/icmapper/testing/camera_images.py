"""JPEG camera images of a world rendered through exact 3-D camera geometry, for the real-image
fixture writers (``nuscenes_fixture``, ``av2_fixture``).

Each image is rendered by ``sim.Renderer`` for one camera whose camera->world transform is given
as a full SE(3) matrix (the camera's own ego pose at its timestamp times its mount), over the
flat ground z = 0 of the world frame: the renderer's "ego" is the world frame itself (identity
pose), so the camera geometry is used exactly as given, roll, pitch and height included. The world
raster is painted once and shared by every camera (``Renderer.with_rig``); vehicles are left out
so that painted markings are never occluded.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from icmapper.data.types import CameraRig, WorldMap


@dataclass
class CameraShot:
    """One image to render: output path, camera->world (4, 4) (camera x right, y down,
    z forward), native pixel intrinsics (3, 3) and native size (h, w)."""

    path: Path
    cam_to_world: NDArray[np.float64]
    intrinsics: NDArray[np.float64]
    size: tuple[int, int]


def render_jpegs(
    world: WorldMap, shots: list[CameraShot], seed: int = 0, quality: int = 90
) -> None:
    """Renders and writes every shot as a JPEG (folders created)."""
    from PIL import Image

    from icmapper.data.sim import Renderer

    base: Renderer | None = None
    for k, shot in enumerate(shots):
        rig = CameraRig(
            ("cam",),
            np.asarray(shot.intrinsics, np.float64)[None],  # (1, 3, 3)
            np.asarray(shot.cam_to_world, np.float64)[None],  # (1, 4, 4)
            (int(shot.size[0]), int(shot.size[1])),
        )
        if base is None:
            base = Renderer(world, rig, seed, vehicles=False)
            r = base
        else:
            r = base.with_rig(rig)
        img = r.render(np.eye(4), frame_seed=k)[0]  # (3, h, w) uint8
        shot.path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(np.ascontiguousarray(img.transpose(1, 2, 0))).save(
            shot.path, quality=quality
        )


def look_rotation(yaw: float, pitch: float = 0.0, roll: float = 0.0) -> NDArray[np.float64]:
    """(3, 3) camera->ego rotation of a camera looking along `yaw` (radians, left positive),
    tilted down by `pitch` and rolled by `roll` about its optical axis."""
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # cam -> ego at yaw 0
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cp, sp = np.cos(pitch), np.sin(pitch)
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])  # nose down for pitch > 0
    cr, sr = np.cos(roll), np.sin(roll)
    rc = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])  # about the camera z axis
    return rz @ ry @ base @ rc


def matrix_to_quat(r: NDArray[np.float64]) -> list[float]:
    """(3, 3) rotation -> unit quaternion [w, x, y, z] (w >= 0)."""
    m = np.asarray(r, np.float64)
    t = float(np.trace(m))
    if t > 0:
        s = 2.0 * np.sqrt(t + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        v = [0.0, 0.0, 0.0]
        v[i] = 0.25 * s
        v[j] = (m[j, i] + m[i, j]) / s
        v[k] = (m[k, i] + m[i, k]) / s
        q = [(m[k, j] - m[j, k]) / s, *v]
    q = np.asarray(q) / np.linalg.norm(q)
    return [float(x) for x in (q if q[0] >= 0 else -q)]


def euler_pose(
    x: float, y: float, z: float, yaw: float, pitch: float = 0.0, roll: float = 0.0
) -> NDArray[np.float64]:
    """(4, 4) ego->world from position and yaw / pitch / roll (Z-Y-X, radians)."""
    c, s = np.cos(yaw), np.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cp, sp = np.cos(pitch), np.sin(pitch)
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    cr, sr = np.cos(roll), np.sin(roll)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    m[:3, 3] = [x, y, z]
    return m
