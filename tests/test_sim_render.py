"""Camera rig geometry, renderer output, determinism and painted markings where they project."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from icmapper.data import MapClass, WorldMap, xy_yaw_to_pose
from icmapper.data.nuscenes import NUSCENES_CAMERAS
from icmapper.data.sim import (
    Renderer,
    generate_city,
    nuscenes_rig,
    project_ego_points,
    sim_sequence,
    sim_sequences,
)
from icmapper.data.sim.geometry import arc_length, resample_by_length

SIZE = (64, 176)


def test_rig_layout_and_projection() -> None:
    rig = nuscenes_rig((128, 352))
    assert rig.names == NUSCENES_CAMERAS  # the real nuScenes reader's order (StreamMapNet's)
    assert rig.intrinsics.shape == (6, 3, 3) and rig.cam_to_ego.shape == (6, 4, 4)
    fwd = rig.cam_to_ego[:, :3, 2]  # camera z axes in the ego frame
    yaws = np.rad2deg(np.arctan2(fwd[:, 1], fwd[:, 0]))
    np.testing.assert_allclose(yaws, [0, -55, 55, 180, 110, -110], atol=1e-9)
    assert np.all(np.abs(rig.cam_to_ego[:, 2, 3] - 1.5) < 0.1)
    np.testing.assert_allclose(
        rig.cam_to_ego[:, :3, 1], np.tile([0, 0, -1.0], (6, 1)), atol=1e-12
    )  # y down
    # A ground point 12 m ahead lands in the front camera's centre column, below the horizon row
    # at the pinhole's row; it is behind the back camera.
    uv, ok = project_ego_points(rig, np.array([[12.0, 0.0, 0.0]]))
    k = rig.intrinsics[0]
    height, ahead = rig.cam_to_ego[0, 2, 3], 12.0 - rig.cam_to_ego[0, 0, 3]
    np.testing.assert_allclose(uv[0, 0], [176.0, k[1, 2] + k[1, 1] * height / ahead], atol=1e-9)
    assert ok[0, 0] and not ok[3, 0]
    # A point ahead-left is seen by the front-left camera, not by the front-right one.
    uv, ok = project_ego_points(rig, np.array([[8.0, 12.0, 0.0]]))
    assert ok[2, 0] and not ok[1, 0]


@pytest.fixture(scope="module")
def world() -> WorldMap:
    return generate_city(10_011)


def test_render_shape_dtype_determinism(world: WorldMap) -> None:
    renderer = Renderer(world, nuscenes_rig(SIZE), seed=1)
    lane = next(iter(world.lanes.values()))
    pose = xy_yaw_to_pose(*lane.centerline[0], 0.3)
    a = renderer.render(pose, frame_seed=7)
    assert a.shape == (6, 3, *SIZE) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, renderer.render(pose, frame_seed=7))
    np.testing.assert_array_equal(
        a, Renderer(world, nuscenes_rig(SIZE), seed=1).render(pose, frame_seed=7)
    )
    assert not np.array_equal(a, renderer.render(pose, frame_seed=8))
    # sky above, ground below: the top rows are brighter and bluer than the bottom rows
    top, bottom = a[:, :, :4].astype(float).mean(), a[:, :, -4:].astype(float).mean()
    assert top > bottom
    with pytest.raises(ValueError, match="pose"):
        renderer.render(np.eye(3))


def test_marking_appears_where_projected(world: WorldMap) -> None:
    quiet = dataclasses.replace(world, lanes={})  # no driving vehicles
    rig = nuscenes_rig((128, 352))
    renderer = Renderer(quiet, rig, seed=2)
    dividers = [
        m
        for m in world.instances
        if m.cls == MapClass.DIVIDER and m.style.startswith(("solid", "double"))
    ]
    dividers = [m for m in dividers if arc_length(m.points)[-1] > 30.0]
    assert dividers
    checked = 0
    for m in dividers[:4]:
        s = arc_length(m.points)
        p0, p1 = resample_by_length(m.points, np.array([2.0, 3.0]))
        t = (p1 - p0) / np.linalg.norm(p1 - p0)
        nrm = np.array([-t[1], t[0]])
        ego_xy = p0 - 1.6 * nrm  # in the lane to the right of the divider, at its start
        pose = xy_yaw_to_pose(*ego_xy, float(np.arctan2(t[1], t[0])))
        img = renderer.render(pose, frame_seed=0).astype(float).mean(axis=1)  # (C, H, W) grey
        along = resample_by_length(
            m.points, np.linspace(10.0, min(20.0, s[-1]), 40)
        )  # divider 8-18 m ahead
        side = along - 1.0 * nrm  # asphalt 1 m to its right

        def sample(world_pts: np.ndarray, ego_xy=ego_xy, t=t, img=img) -> np.ndarray:
            rel = world_pts - ego_xy
            c, sn = t
            ego = np.stack(
                [
                    c * rel[:, 0] + sn * rel[:, 1],
                    -sn * rel[:, 0] + c * rel[:, 1],
                    np.zeros(len(rel)),
                ],
                axis=1,
            )
            uv, ok = project_ego_points(rig, ego)
            u, v = uv[0, ok[0]].astype(int).T
            # brightest of +-2 columns: double lines leave a gap on the centreline
            return np.max(
                [img[0, v, np.clip(u + du, 0, img.shape[2] - 1)] for du in range(-2, 3)], axis=0
            )

        paint, asphalt = sample(along), sample(side)
        if len(paint) < 10 or len(asphalt) < 10:
            continue
        assert np.median(paint) > np.median(asphalt) + 25.0
        checked += 1
    assert checked >= 1


def test_sequences(world: WorldMap) -> None:
    seq = sim_sequence(10_011, 3, image_size=SIZE)
    assert seq.name == "sim-10011-3" and seq.source == "sim"
    img = seq.render(2)
    assert img.shape == (6, 3, *SIZE)
    np.testing.assert_array_equal(img, seq.frame(2).images)
    a = sim_sequences("val", 3, seed=4, image_size=SIZE)
    b = sim_sequences("val", 3, seed=4, image_size=SIZE)
    assert [s.name for s in a] == [s.name for s in b]
    assert all(int(s.name.split("-")[1]) in range(10_000, 10_100) for s in a)
    with pytest.raises(ValueError, match="split"):
        sim_sequences("dev", 1)


def test_renderers_share_rays_and_build_their_arrays_lazily(world: WorldMap) -> None:
    """Opening a drive casts no rays and draws no grain (a city of many drives at a large image
    size would not fit in memory otherwise); renderers of one rig share its rays; a renderer whose
    arrays were dropped (least recently used) renders the same images again."""
    from icmapper.data.sim import renderer as mod

    rig = nuscenes_rig(SIZE)
    a, b = Renderer(world, rig, seed=3), Renderer(world, nuscenes_rig(SIZE), seed=4)
    assert a._heavy is None and a._raster is None  # nothing of camera or world size yet
    assert a._rays is b._rays  # one cast per rig geometry
    assert Renderer(world, nuscenes_rig((32, 88)), seed=3)._rays is not a._rays
    pose = xy_yaw_to_pose(*next(iter(world.lanes.values())).centerline[0], 0.3)
    first = a.render(pose, frame_seed=7, t=1.0)
    assert a._heavy is not None
    others = [Renderer(world, rig, seed=10 + k) for k in range(mod._KEEP_RASTERS + 1)]
    for r in others:
        r.render(pose, frame_seed=1)
    assert a._heavy is None and a._raster is None  # dropped, least recently used
    np.testing.assert_array_equal(a.render(pose, frame_seed=7, t=1.0), first)
