"""A six-camera rig laid out like nuScenes' (positions, heights, yaws and fields of view close to
the real calibration), with pinhole intrinsics scaled to any image size. No I/O."""

from __future__ import annotations

import numpy as np

from icmapper.data.types import CameraRig

#: name, (x, y, z) mount in the ego frame (m), yaw (deg, left positive), horizontal FOV (deg)
NUSCENES_LAYOUT: tuple[tuple[str, tuple[float, float, float], float, float], ...] = (
    ("CAM_FRONT", (1.70, 0.00, 1.51), 0.0, 70.0),
    ("CAM_FRONT_RIGHT", (1.55, -0.49, 1.49), -55.0, 70.0),
    ("CAM_FRONT_LEFT", (1.52, 0.49, 1.51), 55.0, 70.0),
    ("CAM_BACK", (0.03, 0.00, 1.56), 180.0, 110.0),
    ("CAM_BACK_LEFT", (1.04, 0.48, 1.56), 110.0, 70.0),
    ("CAM_BACK_RIGHT", (1.04, -0.48, 1.56), -110.0, 70.0),
)

#: Principal point row as a fraction of the image height: the horizon of a level camera sits a
#: little above the middle, so more of the road is in view (like nuScenes' cropped images).
HORIZON_ROW = 0.42


def camera_to_ego(position: tuple[float, float, float], yaw: float) -> np.ndarray:
    """(4, 4) cam->ego of a level camera at `position` looking along `yaw` (radians).
    Camera axes: x right, y down, z forward."""
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.eye(4)
    m[:3, 0] = [s, -c, 0.0]  # camera x (right) in the ego frame
    m[:3, 1] = [0.0, 0.0, -1.0]  # camera y (down)
    m[:3, 2] = [c, s, 0.0]  # camera z (forward)
    m[:3, 3] = position
    return m


def nuscenes_rig(image_size: tuple[int, int] = (128, 352)) -> CameraRig:
    """The six nuScenes cameras (front, front-right, front-left, back, back-left, back-right).

    image_size: (H, W) of every camera. Intrinsics (C, 3, 3): square pixels, fx = W / 2 /
    tan(hfov / 2), principal point (W / 2, HORIZON_ROW * H). cam_to_ego (C, 4, 4).
    """
    h, w = (int(v) for v in image_size)
    if h < 2 or w < 2:
        raise ValueError(f"image_size must be (H, W) with both >= 2, got {image_size}")
    names, ks, exts = [], [], []
    for name, pos, yaw_deg, hfov in NUSCENES_LAYOUT:
        f = 0.5 * w / np.tan(np.deg2rad(hfov) / 2)
        ks.append(np.array([[f, 0.0, 0.5 * w], [0.0, f, HORIZON_ROW * h], [0.0, 0.0, 1.0]]))
        exts.append(camera_to_ego(pos, np.deg2rad(yaw_deg)))
        names.append(name)
    return CameraRig(tuple(names), np.stack(ks), np.stack(exts), (h, w))


def project_ego_points(rig: CameraRig, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projects ego-frame 3-D points (n, 3) into every camera.

    Returns uv (C, n, 2) float64 pixel coordinates (column, row) and in_front (C, n) bool
    (depth > 0.1 m and inside the image).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    ego_to_cam = np.linalg.inv(rig.cam_to_ego)  # (C, 4, 4)
    cam = (
        np.einsum("cij,nj->cni", ego_to_cam[:, :3, :3], pts) + ego_to_cam[:, None, :3, 3]
    )  # (C, n, 3)
    z = cam[..., 2]  # (C, n)
    pix = np.einsum("cij,cnj->cni", rig.intrinsics, cam)  # (C, n, 3)
    uv = pix[..., :2] / np.where(np.abs(z) < 1e-9, 1e-9, z)[..., None]  # (C, n, 2)
    h, w = rig.image_size
    ok = (z > 0.1) & (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0) & (uv[..., 1] < h)
    return uv, ok
