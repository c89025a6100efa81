"""Map instances drawn into camera images through the frame's real camera geometry.

An instance is a polyline (or a closed ring) of ego-frame points on the ground plane (z = 0, the
plane the renderer and the datasets' ego frames put the road on). Each point goes through the
rig's ``cam_to_ego`` (inverted) into the camera frame (x right, y down, z forward), segments are
clipped at the near plane ``NEAR`` (so a line passing beside or behind the camera is cut, not
wrapped), and the rest is projected with the pinhole intrinsics. Drawing uses Pillow: class colour,
a track-id label on the visible part. No I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw

from icmapper.data.types import CameraRig
from icmapper.vis.style import CLASS_RGB, font

#: Near clipping plane (m in front of the camera).
NEAR = 0.5
#: Longest segment (m) before projection: vertices every metre keep labels on the visible part.
DENSIFY_STEP = 1.0


@dataclass
class Overlay:
    """One instance to draw: points (n, 2) ego frame metres, its class, closed ring or open
    polyline, an optional label (e.g. the track id) and the line width in pixels."""

    points: NDArray[np.floating]
    cls: int
    closed: bool = False
    label: str | None = None
    width: int = 2


def densify(points: NDArray[np.floating], closed: bool, step: float = DENSIFY_STEP) -> NDArray:
    """(n, 2) -> (m, 2) float64 with no segment longer than ``step`` (closed: the ring is closed
    explicitly, its first point repeated at the end)."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] == 0:
        raise ValueError(f"points must have shape (n, 2) with n >= 1, got {pts.shape}")
    if closed:
        pts = np.vstack([pts, pts[:1]])
    if pts.shape[0] == 1:
        return pts
    seg = np.diff(pts, axis=0)  # (n-1, 2)
    k = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / step)).astype(np.int64)  # (n-1,)
    frac = np.concatenate([np.arange(c) / c for c in k.tolist()])  # (sum k,)
    start = np.repeat(np.arange(seg.shape[0]), k)  # (sum k,)
    out = pts[start] + frac[:, None] * seg[start]  # (sum k, 2)
    return np.vstack([out, pts[-1:]])


def ground_to_camera(rig: CameraRig, points: NDArray[np.floating]) -> NDArray[np.float64]:
    """Ego-frame ground points (n, 2) (z = 0) -> camera-frame points (C, n, 3) of every camera."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got {pts.shape}")
    ego = np.concatenate([pts, np.zeros((pts.shape[0], 1))], axis=1)  # (n, 3)
    ego_to_cam = np.linalg.inv(np.asarray(rig.cam_to_ego, dtype=np.float64))  # (C, 4, 4)
    return np.einsum("cij,nj->cni", ego_to_cam[:, :3, :3], ego) + ego_to_cam[:, None, :3, 3]


def project_ground_points(
    rig: CameraRig, points: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Ego-frame ground points (n, 2) -> pixel coordinates uv (C, n, 2) (column, row) and
    visible (C, n) bool (at least ``NEAR`` in front of the camera and inside its image)."""
    cam = ground_to_camera(rig, points)  # (C, n, 3)
    z = cam[..., 2]  # (C, n)
    pix = np.einsum("cij,cnj->cni", np.asarray(rig.intrinsics, np.float64), cam)  # (C, n, 3)
    uv = pix[..., :2] / np.where(z > 1e-9, z, 1e-9)[..., None]  # (C, n, 2)
    h, w = rig.image_size
    visible = (z >= NEAR) & (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0)
    return uv, visible & (uv[..., 1] < h)


def project_polyline(
    rig: CameraRig, camera: int, points: NDArray[np.floating], closed: bool = False
) -> list[NDArray[np.float64]]:
    """An ego-frame ground polyline (n, 2) in camera ``camera``: the pieces in front of the near
    plane, each (m, 2) float64 pixel coordinates (column, row), m >= 2. Pieces may reach outside
    the image (the caller's drawing clips them)."""
    if not 0 <= camera < rig.num_cameras:
        raise ValueError(f"camera {camera} out of range for a rig of {rig.num_cameras}")
    dense = densify(points, closed)  # (m, 2)
    cam = ground_to_camera(rig, dense)[camera]  # (m, 3)
    k = np.asarray(rig.intrinsics[camera], dtype=np.float64)  # (3, 3)
    pieces: list[NDArray[np.float64]] = []
    current: list[NDArray[np.float64]] = []
    for a, b in zip(cam[:-1], cam[1:], strict=True):
        ina, inb = a[2] >= NEAR, b[2] >= NEAR
        if not (ina or inb):
            continue
        if ina and inb:
            if not current:
                current.append(a)
            current.append(b)
            continue
        cut = a + (NEAR - a[2]) / (b[2] - a[2]) * (b - a)  # on the near plane
        if ina:  # leaving the visible half-space: end the piece at the cut
            if not current:
                current.append(a)
            current.append(cut)
            pieces.append(np.array(current))
            current = []
        else:  # entering: start a piece at the cut
            current = [cut, b]
    if current:
        pieces.append(np.array(current))
    out = []
    for p in pieces:  # (m, 3) camera frame
        if p.shape[0] < 2:
            continue
        pix = p @ k.T  # (m, 3)
        out.append(pix[:, :2] / pix[:, 2:3])  # (m, 2)
    return out


def label_candidates(
    piece_list: list[NDArray[np.float64]], size: tuple[int, int], margin: int = 8, k: int = 7
) -> list[tuple[float, float]]:
    """Up to ``k`` places for a label on the part of the pieces inside the image (less a
    margin), the middle first, then alternately farther out."""
    h, w = size
    inside = [
        p[
            (p[:, 0] >= margin)
            & (p[:, 0] < w - margin)
            & (p[:, 1] >= margin)
            & (p[:, 1] < h - margin)
        ]
        for p in piece_list
    ]
    pts = np.concatenate(inside) if inside else np.zeros((0, 2))  # (m, 2)
    return middle_out(pts, k)


def middle_out(pts: NDArray[np.floating], k: int = 7) -> list[tuple[float, float]]:
    """Up to ``k`` of the points (m, 2): the middle one, then alternately towards both ends."""
    m = int(pts.shape[0])
    if m == 0:
        return []
    mid = m // 2
    step = max(1, m // (k + 1))
    order = [mid]
    for j in range(1, k):
        off = (j + 1) // 2 * step * (1 if j % 2 else -1)
        if 0 <= mid + off < m:
            order.append(mid + off)
    return [(float(pts[i, 0]), float(pts[i, 1])) for i in order]


def draw_label(
    draw: ImageDraw.ImageDraw,
    xy: tuple[float, float],
    text: str,
    rgb: tuple[int, int, int],
    size: int,
) -> tuple[float, float, float, float]:
    """A label centred on ``xy``: white box, class-coloured text. Returns its box."""
    f = font(size)
    x0, y0, x1, y1 = draw.textbbox((0, 0), text, font=f)
    tw, th = x1 - x0, y1 - y0
    box = (xy[0] - tw / 2 - 2, xy[1] - th / 2 - 2, xy[0] + tw / 2 + 2, xy[1] + th / 2 + 2)
    draw.rectangle(box, fill=(255, 255, 255), outline=rgb)
    draw.text((box[0] + 2 - x0, box[1] + 2 - y0), text, fill=rgb, font=f)
    return box


def _overlaps(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def place_labels(
    draw: ImageDraw.ImageDraw,
    labels: list[tuple[list[tuple[float, float]], str, tuple[int, int, int]]],
    size: int,
) -> None:
    """Draws each label (candidate places, text, colour) at its first place that does not
    overlap a label already drawn (the first place when all overlap)."""
    f = font(size)
    boxes: list[tuple[float, float, float, float]] = []
    for places, text, rgb in labels:
        if not places:
            continue
        x0, y0, x1, y1 = draw.textbbox((0, 0), text, font=f)
        hw, hh = (x1 - x0) / 2 + 2, (y1 - y0) / 2 + 2
        pick = places[0]
        for x, y in places:
            box = (x - hw, y - hh, x + hw, y + hh)
            if not any(_overlaps(box, b) for b in boxes):
                pick = (x, y)
                break
        boxes.append(draw_label(draw, pick, text, rgb, size))


def draw_camera_overlays(
    images: NDArray[np.uint8], rig: CameraRig, overlays: list[Overlay], label_size: int = 11
) -> list[Image.Image]:
    """The camera images (C, 3, H, W) uint8 with ``overlays`` drawn in every camera that sees
    them; returns C RGB Pillow images of the rig's image size."""
    imgs = np.asarray(images)
    c, h, w = rig.num_cameras, *rig.image_size
    if imgs.shape != (c, 3, h, w):
        raise ValueError(
            f"images must have shape ({c}, 3, {h}, {w}) for this rig, got {imgs.shape}"
        )
    out = []
    for cam in range(c):
        im = Image.fromarray(np.ascontiguousarray(imgs[cam].transpose(1, 2, 0)))  # (H, W, 3)
        draw = ImageDraw.Draw(im)
        labels = []
        for ov in overlays:
            pieces = project_polyline(rig, cam, ov.points, ov.closed)
            rgb = CLASS_RGB[int(ov.cls)]
            for p in pieces:
                draw.line([tuple(q) for q in p.tolist()], fill=rgb, width=ov.width, joint="curve")
            if ov.label is not None:
                labels.append((label_candidates(pieces, (h, w)), ov.label, rgb))
        place_labels(draw, labels, label_size)  # above every line
        out.append(im)
    return out
