"""nuScenes real images: the reader against the official devkit (nuscenes-devkit) on the image
fixture, painted markings where the reader's geometry puts them, and bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.errors import DataError
from icmapper.data.images import fit_size
from icmapper.data.nuscenes import NUSCENES_CAMERAS, load_nuscenes
from icmapper.data.sources import open_source, source_tag, split_options
from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

SIZE = (90, 176)  # (H, W): fit-resize of 225x400 -> 90x160, of 240x320 -> 90x120


@pytest.fixture(scope="module")
def dataroot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_nuscenes_fixture(
        tmp_path_factory.mktemp("nusc_img"), scene_lengths=(4, 3), images=True
    )


@pytest.fixture(scope="module")
def nusc(dataroot: Path):  # noqa: ANN201
    from icmapper.testing.devkits import require_devkit

    (devkit, _, _) = require_devkit(
        "nuscenes.nuscenes", "nuscenes.utils.geometry_utils", "pyquaternion"
    )
    return devkit.NuScenes(version="v1.0-mini", dataroot=str(dataroot), verbose=False)


def _devkit_frames(nusc, scene_name: str) -> list[dict]:  # noqa: ANN001
    """Per keyframe of a scene, from the devkit: reference pose and, per camera, the image path,
    native intrinsics and size, camera -> reference ego (obtain_sensor2top) and the camera's
    own world -> camera chain."""
    from nuscenes.utils.geometry_utils import transform_matrix
    from pyquaternion import Quaternion

    scene = next(s for s in nusc.scene if s["name"] == scene_name)
    out = []
    tok = scene["first_sample_token"]
    while tok:
        sample = nusc.get("sample", tok)
        lidar = nusc.get("sample_data", sample["data"]["LIDAR_TOP"])
        ref = nusc.get("ego_pose", lidar["ego_pose_token"])
        ref_pose = transform_matrix(ref["translation"], Quaternion(ref["rotation"]))
        cams = {}
        for cam in NUSCENES_CAMERAS:
            sd_token = sample["data"][cam]
            path, _, k = nusc.get_sample_data(sd_token)
            sd = nusc.get("sample_data", sd_token)
            cs = nusc.get("calibrated_sensor", sd["calibrated_sensor_token"])
            ep = nusc.get("ego_pose", sd["ego_pose_token"])
            cam_ego = transform_matrix(ep["translation"], Quaternion(ep["rotation"]))
            cam_mount = transform_matrix(cs["translation"], Quaternion(cs["rotation"]))
            cams[cam] = {
                "path": path,
                "k": np.asarray(k),
                "hw": (sd["height"], sd["width"]),
                "cam_to_ref": np.linalg.inv(ref_pose) @ cam_ego @ cam_mount,
                "world_to_cam": np.linalg.inv(cam_ego @ cam_mount),
            }
        out.append({"pose": ref_pose, "cams": cams})
        tok = sample["next"]
    return out


def test_reader_matches_devkit(dataroot: Path, nusc) -> None:  # noqa: ANN001
    from nuscenes.utils.geometry_utils import view_points

    seqs = load_nuscenes(dataroot, "v1.0-mini", image_size=SIZE)
    assert [s.name for s in seqs] == ["scene-0001", "scene-0002"]
    rng = np.random.default_rng(0)
    worst = 0.0
    for seq in seqs:
        assert seq.images == "real" and seq.frame_rigs is not None
        expected = _devkit_frames(nusc, seq.name)
        assert len(expected) == len(seq)
        for i, exp in enumerate(expected):
            rig = seq.rig_of(i)
            np.testing.assert_allclose(seq.poses[i], exp["pose"], atol=1e-9)
            for c, cam in enumerate(NUSCENES_CAMERAS):
                e = exp["cams"][cam]
                assert str(seq.render.files[i][c]) == e["path"]
                assert seq.render.native[i][c] == e["hw"]
                nh, nw = fit_size(e["hw"], SIZE)
                k_exp = np.diag([nw / e["hw"][1], nh / e["hw"][0], 1.0]) @ e["k"]
                np.testing.assert_allclose(rig.intrinsics[c], k_exp, atol=1e-9)
                np.testing.assert_allclose(rig.cam_to_ego[c], e["cam_to_ref"], atol=1e-9)
                # World points in front of the camera, projected both ways at native resolution.
                depth = rng.uniform(3.0, 40.0, 50)
                cam_pts = np.stack(
                    [rng.uniform(-0.8, 0.8, 50) * depth, rng.uniform(-0.4, 0.5, 50) * depth, depth]
                )  # (3, 50) camera frame
                world = np.linalg.inv(e["world_to_cam"]) @ np.vstack([cam_pts, np.ones(50)])
                uv_dev = view_points((e["world_to_cam"] @ world)[:3], e["k"], normalize=True)[
                    :2
                ]  # (2, 50)
                ours = np.linalg.inv(rig.cam_to_ego[c]) @ np.linalg.inv(seq.poses[i]) @ world
                pix = rig.intrinsics[c] @ ours[:3]  # (3, 50) resized image
                uv = pix[:2] / pix[2]
                uv_native = uv / np.array([[nw / e["hw"][1]], [nh / e["hw"][0]]])
                worst = max(worst, float(np.abs(uv_native - uv_dev).max()))
    assert worst < 0.5, worst
    # The composition matters: per-camera time offsets move the cameras by up to ~0.4 m.
    rig0 = seqs[0].rig_of(1)
    static = load_nuscenes(dataroot, "v1.0-mini", image_size=SIZE, images="render").pop(0).rig
    assert np.abs(rig0.cam_to_ego[:, :3, 3] - static.cam_to_ego[:, :3, 3]).max() > 0.1


def yellow_profile(fr, cam: int, ahead: tuple[float, float], ys: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """Share of yellow pixels (R - B > 40) along ego-parallel ground lines at lateral offsets
    `ys` (world y, m), `ahead` metres in front of the ego, in camera `cam` of frame `fr`."""
    img, rig = fr.images[cam].astype(float), fr.rig
    xs = np.linspace(fr.pose[0, 3] + ahead[0], fr.pose[0, 3] + ahead[1], 40)
    out = []
    for y in ys:
        world = np.stack([xs, np.full_like(xs, y), np.zeros_like(xs), np.ones_like(xs)])
        cam_pts = np.linalg.inv(rig.cam_to_ego[cam]) @ np.linalg.inv(fr.pose) @ world
        pix = rig.intrinsics[cam] @ cam_pts[:3]
        u = np.clip(np.floor(pix[0] / pix[2]).astype(int), 0, img.shape[2] - 1)
        v = np.clip(np.floor(pix[1] / pix[2]).astype(int), 0, img.shape[1] - 1)
        out.append(np.mean(img[0, v, u] - img[2, v, u] > 40))
    return np.asarray(out)


def test_markings_land_where_the_images_show_them(dataroot: Path) -> None:
    """The double yellow road divider (lines at y = +-0.17 m) projected through the reader's
    geometry: the yellow seen in CAM_FRONT peaks at those offsets, within the renderer's 0.1 m
    raster, and nothing is yellow 0.6 m beside them."""
    seq = load_nuscenes(dataroot, "v1.0-mini", image_size=(225, 400))[0]
    ys = np.arange(-0.8, 0.81, 0.02)
    for i in range(len(seq)):
        prof = yellow_profile(seq.frame(i), 0, (5.0, 11.0), ys)
        for side in (-1, 1):
            half = (ys * side > 0.02) & (np.abs(ys) < 0.45)
            centre = float((prof[half] * ys[half]).sum() / prof[half].sum())
            assert abs(centre - side * 0.17) < 0.1, (i, side, centre)
            assert prof[half].max() > 0.9
        assert prof[np.abs(ys) > 0.6].max() < 0.1


def test_spec_options_and_render_mode(dataroot: Path) -> None:
    real = open_source(f"nuscenes:{dataroot}", image_size=SIZE)
    rendered = open_source(f"nuscenes:{dataroot}:images=render", image_size=SIZE)
    assert real[0].images == "real" and rendered[0].images == "rendered"
    assert rendered[0].frame_rigs is None
    np.testing.assert_allclose(rendered[0].poses[:, 2, 3], 0.0)  # planar for the renderer
    assert np.abs(real[0].poses[:, 2, 3]).max() > 0.0  # full SE(3)
    # Same 2-D poses either way.
    np.testing.assert_allclose(real[0].poses[:, :2, 3], rendered[0].poses[:, :2, 3])
    assert open_source(f"nuscenes:{dataroot}", render=False)[0].images == "none"
    assert split_options("av2:/x:images=render") == ("av2:/x", {"images": "render"})
    assert source_tag("av2:/data/logs:images=render") == "av2-logs-images-render"
    with pytest.raises(ValueError, match="unknown option 'color'"):
        open_source(f"nuscenes:{dataroot}:color=red")
    with pytest.raises(ValueError, match="images must be one of auto|real|render"):
        open_source(f"nuscenes:{dataroot}:images=yes")


def test_images_real_without_images_is_an_error(tmp_path: Path) -> None:
    root = write_nuscenes_fixture(tmp_path / "plain", scene_lengths=(3,))
    with pytest.raises(DataError, match="holds no camera images"):
        open_source(f"nuscenes:{root}:images=real")
    assert open_source(f"nuscenes:{root}")[0].images == "rendered"  # auto


def _copy(dataroot: Path, tmp_path: Path) -> Path:
    import shutil

    dst = tmp_path / "copy"
    shutil.copytree(dataroot, dst)
    return dst


def test_missing_and_truncated_jpegs_fail_at_open_naming_the_file(
    dataroot: Path, tmp_path: Path
) -> None:
    root = _copy(dataroot, tmp_path)
    victim = sorted((root / "samples" / "CAM_BACK_LEFT").glob("*.jpg"))[2]
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])
    with pytest.raises(DataError, match=f"truncated JPEG file.*{victim.name}"):
        load_nuscenes(root, "v1.0-mini", image_size=SIZE)
    victim.unlink()
    with pytest.raises(DataError, match=f"image not found: .*{victim.name}"):
        load_nuscenes(root, "v1.0-mini", image_size=SIZE)
    # Without images (evaluation) the files are not needed.
    assert len(load_nuscenes(root, "v1.0-mini", image_size=SIZE, render=False)) == 2


def test_corrupt_jpeg_fails_at_decode_naming_the_file(dataroot: Path, tmp_path: Path) -> None:
    root = _copy(dataroot, tmp_path)
    victim = sorted((root / "samples" / "CAM_FRONT").glob("*.jpg"))[0]
    data = bytearray(victim.read_bytes())
    data[2:-2] = b"\x00" * (len(data) - 4)
    victim.write_bytes(bytes(data))
    seq = load_nuscenes(root, "v1.0-mini", image_size=SIZE)[0]
    with pytest.raises(DataError, match=victim.name):
        seq.frame(0)


def test_camera_missing_at_a_keyframe(dataroot: Path, tmp_path: Path) -> None:
    root = _copy(dataroot, tmp_path)
    path = root / "v1.0-mini" / "sample_data.json"
    rows = json.loads(path.read_text())
    rows = [r for r in rows if r["token"] != "sd0_2_CAM_FRONT_RIGHT"]
    path.write_text(json.dumps(rows))
    with pytest.raises(DataError, match="sample smp0_2 has no CAM_FRONT_RIGHT"):
        load_nuscenes(root, "v1.0-mini", image_size=SIZE)


def test_native_size_comes_from_each_sample_data(dataroot: Path) -> None:
    seq = load_nuscenes(dataroot, "v1.0-mini", image_size=SIZE)[0]
    back = NUSCENES_CAMERAS.index("CAM_BACK")
    assert seq.render.native[0][back] == (240, 320)
    assert seq.render.native[0][0] == (225, 400)
    img = seq.frame(0).images  # (6, 3, H, W)
    assert img.shape == (6, 3, *SIZE)
    nh, nw = fit_size((225, 400), SIZE)
    assert (nh, nw) == (90, 160)
    assert img[0, :, :, nw:].max() == 0 and img[0, :, :nh, :nw].mean() > 20  # padding, content
