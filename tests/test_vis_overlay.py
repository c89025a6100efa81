"""Overlay geometry: ground-plane instances projected into camera images (icmapper.vis.overlay).

The oracle is the renderer itself: it casts every pixel's ray onto the ground and paints what it
hits, an inverse of the overlay's projection written independently. A ground-truth marking
projected by the overlay code must land on the marking's paint in the rendered image, and a copy
shifted sideways by half a metre must not.
"""

from __future__ import annotations

import numpy as np
import pytest
from icmapper.data.gt import frame_gt
from icmapper.data.sim.renderer import Renderer
from icmapper.data.sim.rig import nuscenes_rig, project_ego_points
from icmapper.data.types import MapClass, MapInstance, RANGE_60x30, WorldMap, xy_yaw_to_pose
from icmapper.vis.overlay import (
    NEAR,
    Overlay,
    densify,
    draw_camera_overlays,
    project_ground_points,
    project_polyline,
)

SIZE = (256, 704)
DIVIDER_Y = 1.8  # m, left of the ego


@pytest.fixture(scope="module")
def scene() -> tuple[WorldMap, np.ndarray, np.ndarray]:
    """A straight road with one solid white divider (synthetic frame), the ego pose and the
    rendered images (C, 3, H, W)."""
    xs = np.linspace(-120.0, 120.0, 49)
    road = np.array([[-120.0, -7.0], [120.0, -7.0], [120.0, 7.0], [-120.0, 7.0]])
    instances = [
        MapInstance(1, MapClass.DIVIDER, np.stack([xs, np.full_like(xs, DIVIDER_Y)], 1), False,
                    "solid_white"),
        MapInstance(2, MapClass.BOUNDARY, np.stack([xs, np.full_like(xs, -7.0)], 1), False, "curb"),
        MapInstance(3, MapClass.BOUNDARY, np.stack([xs, np.full_like(xs, 7.0)], 1), False, "curb"),
    ]  # fmt: skip
    world = WorldMap("straight", instances, drivable=[road])
    pose = xy_yaw_to_pose(3.0, 0.0, 0.0)
    images = Renderer(world, nuscenes_rig(SIZE), seed=3).render(pose, frame_seed=1)
    return world, pose, images


#: Lateral tolerance on the ground (m): the renderer paints into a 0.1 m raster (nearest pixel),
#: so a 0.15 m line is drawn up to about one raster pixel off its true position.
TOLERANCE = 0.12


def _paint_fraction(rig, image_hwc: np.ndarray, uv: np.ndarray) -> float:  # noqa: ANN001
    """Fraction of CAM_FRONT pixel positions uv (n, 2) with white paint (bright and grey: not
    asphalt, grass, sky or sidewalk) within TOLERANCE metres sideways on the ground. For flat
    ground a row is a distance ahead d = f * height / (row - cy), and a sideways offset of dy
    moves the column by f * dy / d = dy * (row - cy) / height pixels on that row."""
    cam = rig.names.index("CAM_FRONT")
    img = image_hwc.astype(np.float64)  # (H, W, 3)
    paint = (img.mean(axis=2) > 180) & (np.ptp(img, axis=2) < 40)  # (H, W)
    h, w = paint.shape
    cy, height = rig.intrinsics[cam][1, 2], rig.cam_to_ego[cam][2, 3]
    hit = np.zeros(uv.shape[0], bool)
    for j, (u, v) in enumerate(uv.tolist()):
        row = int(round(v))
        tol = TOLERANCE * (v - cy) / height  # pixels
        lo, hi = max(int(np.floor(u - tol)), 0), min(int(np.ceil(u + tol)), w - 1)
        hit[j] = 0 <= row < h and lo <= hi and bool(paint[row, lo : hi + 1].any())
    return float(hit.mean())


def _front_samples(rig, ego_pts: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """Pixel positions in CAM_FRONT of the divider points 5-25 m ahead (densified)."""
    cam = rig.names.index("CAM_FRONT")
    dense = densify(ego_pts, False, 0.25)
    dense = dense[(dense[:, 0] > 5.0) & (dense[:, 0] < 25.0)]
    uv, vis = project_ground_points(rig, dense)
    return uv[cam][vis[cam]]


def test_ground_truth_marking_lands_on_paint(scene) -> None:  # noqa: ANN001
    world, pose, images = scene
    rig = nuscenes_rig(SIZE)
    gt = frame_gt(world, pose, RANGE_60x30)
    (k,) = np.flatnonzero(gt.classes == int(MapClass.DIVIDER))
    front = images[rig.names.index("CAM_FRONT")].transpose(1, 2, 0)  # (H, W, 3)
    uv = _front_samples(rig, gt.points[k].astype(np.float64))
    assert uv.shape[0] > 50
    assert _paint_fraction(rig, front, uv) > 0.95
    shifted = gt.points[k].astype(np.float64) + [0.0, 0.5]
    assert _paint_fraction(rig, front, _front_samples(rig, shifted)) < 0.05  # it can fail


def test_drawn_overlay_covers_paint(scene) -> None:  # noqa: ANN001
    """The pixels draw_camera_overlays paints for the GT divider are the marking's pixels."""
    world, pose, images = scene
    rig = nuscenes_rig(SIZE)
    gt = frame_gt(world, pose, RANGE_60x30)
    (k,) = np.flatnonzero(gt.classes == int(MapClass.DIVIDER))
    cam = rig.names.index("CAM_FRONT")
    before = images[cam].transpose(1, 2, 0)  # (H, W, 3)
    ov = Overlay(gt.points[k], int(MapClass.DIVIDER), False, label=None, width=1)
    after = np.asarray(draw_camera_overlays(images, rig, [ov])[cam])  # (H, W, 3)
    changed = np.argwhere(np.any(after != before, axis=2))  # (n, 2) rows, cols
    near = changed[changed[:, 0] > 0.55 * SIZE[0]]  # rows below the horizon, < ~20 m ahead
    assert near.shape[0] > 50
    assert _paint_fraction(rig, before, near[:, ::-1].astype(np.float64)) > 0.95
    moved = Overlay(gt.points[k] + [0.0, 0.5], int(MapClass.DIVIDER), False, width=1)
    after = np.asarray(draw_camera_overlays(images, rig, [moved])[cam])  # (H, W, 3)
    changed = np.argwhere(np.any(after != before, axis=2))
    near = changed[changed[:, 0] > 0.55 * SIZE[0]]
    assert _paint_fraction(rig, before, near[:, ::-1].astype(np.float64)) < 0.05


def test_projection_matches_the_rig_module() -> None:
    """Another implementation (data.sim.rig.project_ego_points) gives the same pixels."""
    rig = nuscenes_rig((128, 352))
    pts = np.random.default_rng(0).uniform(-30, 30, size=(200, 2))  # (n, 2)
    uv, vis = project_ground_points(rig, pts)
    uv2, ok2 = project_ego_points(rig, np.concatenate([pts, np.zeros((200, 1))], axis=1))
    np.testing.assert_allclose(uv[vis], uv2[vis], atol=1e-9)
    assert vis.sum() > 50 and np.array_equal(vis, ok2 & vis)


def test_near_plane_clipping_by_hand() -> None:
    """A line from 10 m ahead to 10 m behind the front camera ends on the near plane."""
    rig = nuscenes_rig((128, 352))
    cam = rig.names.index("CAM_FRONT")
    (x0, _, height) = rig.cam_to_ego[cam][:3, 3]
    pieces = project_polyline(rig, cam, np.array([[10.0, 0.0], [-10.0, 0.0]]))
    assert len(pieces) == 1
    k = rig.intrinsics[cam]
    end = pieces[0][-1]
    # The cut is NEAR ahead of the camera on the ground, straight below its optical axis.
    np.testing.assert_allclose(end, [k[0, 2], k[1, 2] + k[1, 1] * height / NEAR], atol=1e-6)
    start = pieces[0][0]
    np.testing.assert_allclose(start, [k[0, 2], k[1, 2] + k[1, 1] * height / (10.0 - x0)])
    assert project_polyline(rig, cam, np.array([[-5.0, 0.0], [-10.0, 3.0]])) == []
    # A closed ring around the camera: pieces in front only, every pixel finite.
    ring = np.array([[8.0, 8.0], [8.0, -8.0], [-8.0, -8.0], [-8.0, 8.0]])
    pieces = project_polyline(rig, cam, ring, closed=True)
    assert pieces and all(np.isfinite(p).all() for p in pieces)


def test_bad_input_names_the_problem() -> None:
    rig = nuscenes_rig((64, 176))
    with pytest.raises(ValueError, match="points must have shape"):
        project_polyline(rig, 0, np.zeros((3, 3)))
    with pytest.raises(ValueError, match="camera 9 out of range"):
        project_polyline(rig, 9, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="images must have shape"):
        draw_camera_overlays(np.zeros((6, 3, 10, 10), np.uint8), rig, [])
