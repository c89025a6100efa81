"""Argoverse 2 sensor logs: the reader against the official `av2` devkit's camera and
synchronisation code on the sensor-log fixture (built-in calibration and the real one of
../shared/data/av2-mini), painted markings, the portrait front camera, bad input, and the
reader defects (holes of the drivable union, non-numeric coordinates)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from icmapper.data.av2 import AV2_RING_CAMERAS, load_av2_sequence, load_av2_world
from icmapper.data.errors import DataError
from icmapper.data.images import fit_size
from icmapper.data.types import MapClass
from icmapper.testing.av2_fixture import write_av2_sensor_log

SIZE = (96, 160)
REAL_CALIB_LOG = "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_av2_sensor_log(tmp_path_factory.mktemp("av2_img"))


def _devkit():  # noqa: ANN202
    from icmapper.testing.devkits import require_devkit

    io_utils, pin, sdb = require_devkit(
        "av2.utils.io", "av2.geometry.camera.pinhole_camera", "av2.utils.synchronization_database"
    )
    return io_utils, pin.PinholeCamera, sdb.SynchronizationDB


def _check_against_devkit(log: Path) -> float:
    """Compares the reader with the devkit per keyframe and camera; returns the worst projection
    disagreement (px, native resolution)."""
    io_utils, pinhole_camera, sync_db = _devkit()
    seq = load_av2_sequence(log, image_size=SIZE)
    assert seq.images == "real" and len(seq) >= 2
    sdb = sync_db(str(log.parent), collect_single_log_id=log.name)
    city_se3_ego = io_utils.read_city_SE3_ego(log)
    rng = np.random.default_rng(1)
    worst = 0.0
    for i in range(len(seq)):
        sweep = int(round(seq.timestamps[i] * 1e9))
        sweep = min(city_se3_ego, key=lambda t: abs(t - sweep))  # exact ns (float seconds)
        ref = city_se3_ego[sweep]
        np.testing.assert_allclose(seq.poses[i], ref.transform_matrix, atol=1e-9)
        rig = seq.rig_of(i)
        for c, cam in enumerate(AV2_RING_CAMERAS):
            pin = pinhole_camera.from_feather(log, cam)
            img_ts = sdb.get_closest_cam_channel_timestamp(sweep, cam, log.name)
            assert img_ts is not None
            expected_path = log / "sensors" / "cameras" / cam / f"{img_ts}.jpg"
            assert seq.render.files[i][c] == expected_path
            hw = (pin.height_px, pin.width_px)
            assert seq.render.native[i][c] == hw
            nh, nw = fit_size(hw, SIZE)
            k_exp = np.diag([nw / hw[1], nh / hw[0], 1.0]) @ pin.intrinsics.K
            np.testing.assert_allclose(rig.intrinsics[c], k_exp, atol=1e-9)
            cam_pose = city_se3_ego[img_ts]
            c2r = ref.inverse().compose(cam_pose).compose(pin.ego_SE3_cam).transform_matrix
            np.testing.assert_allclose(rig.cam_to_ego[c], c2r, atol=1e-9)
            # Ego points at the sweep, projected with the devkit's motion compensation.
            depth = rng.uniform(3.0, 40.0, 50)
            cam_pts = np.stack(
                [rng.uniform(-0.5, 0.5, 50) * depth, rng.uniform(-0.4, 0.5, 50) * depth, depth]
            ).T  # (50, 3)
            ego_pts = c2r[:3, :3] @ cam_pts.T + c2r[:3, 3:4]  # (3, 50) reference ego frame
            uv_dev, _, _ = pin.project_ego_to_img_motion_compensated(
                ego_pts.T, city_SE3_ego_cam_t=cam_pose, city_SE3_ego_lidar_t=ref
            )  # (50, 3)
            ours = np.linalg.inv(rig.cam_to_ego[c]) @ np.vstack([ego_pts, np.ones(50)])
            pix = rig.intrinsics[c] @ ours[:3]
            uv = (pix[:2] / pix[2]).T / np.array([nw / hw[1], nh / hw[0]])
            worst = max(worst, float(np.abs(uv - uv_dev[:, :2]).max()))
    return worst


def test_reader_matches_devkit(log: Path) -> None:
    assert _check_against_devkit(log) < 0.5


def test_reader_matches_devkit_with_real_calibration(shared_data: Path, tmp_path: Path) -> None:
    calib = shared_data / "av2-mini" / REAL_CALIB_LOG / "calibration"
    assert calib.is_dir(), f"the shared data lacks the real calibration {calib}"
    log = write_av2_sensor_log(tmp_path, duration_s=1.0, calibration_from=calib)
    assert _check_against_devkit(log) < 0.5


def test_portrait_front_camera_keeps_its_aspect(log: Path) -> None:
    seq = load_av2_sequence(log, image_size=(128, 128))
    h, w = seq.render.native[0][0]
    assert h > w  # ring_front_center is portrait
    nh, nw = fit_size((h, w), (128, 128))
    assert nh == 128 and abs(nw / nh - w / h) < 0.01
    k = seq.rig_of(0).intrinsics[0]
    assert abs(k[0, 0] / k[1, 1] - 1.0) < 0.01  # square pixels stay square
    img = seq.frame(0).images[0]  # (3, 128, 128)
    assert img[:, :, nw + 1 :].max() == 0 and img[:, :, : nw - 1].mean() > 20


def test_markings_land_where_the_images_show_them(log: Path) -> None:
    """The double yellow centre line (y = +-0.17 m) seen by ring_front_center where the reader's
    geometry projects it (the ego weaves and turns, cameras have time offsets)."""
    from tests.test_data_real_nuscenes import yellow_profile

    seq = load_av2_sequence(log, image_size=(256, 256))
    ys = np.arange(-0.8, 0.81, 0.02)
    for i in range(len(seq)):
        fr = seq.frame(i)
        if abs(fr.pose[1, 3]) > 3.0 - 0.5:  # the centre line is 2.5..5.5 m to the left
            prof = yellow_profile(fr, 0, (6.0, 12.0), ys)
            assert prof.max() > 0.5, i
            for side in (-1, 1):
                half = (ys * side > 0.02) & (np.abs(ys) < 0.45)
                centre = float((prof[half] * ys[half]).sum() / max(prof[half].sum(), 1e-9))
                assert abs(centre - side * 0.17) < 0.1, (i, side, centre)
            assert prof[np.abs(ys) > 0.6].mean() < 0.1


def _copy(log: Path, tmp_path: Path) -> Path:
    dst = tmp_path / log.name
    shutil.copytree(log, dst)
    return dst


def test_sweep_without_images_in_tolerance_is_skipped(log: Path, tmp_path: Path) -> None:
    copy = _copy(log, tmp_path)
    seq = load_av2_sequence(copy, image_size=SIZE)
    victim = seq.render.files[2][3]
    victim.unlink()  # the decoy 50 ms later is now the nearest: out of tolerance
    with pytest.warns(UserWarning, match=f"{AV2_RING_CAMERAS[3]} has no image within 25 ms"):
        fewer = load_av2_sequence(copy, image_size=SIZE)
    assert len(fewer) == len(seq) - 1
    assert victim.parent / f"{int(victim.stem) + 50_000_000}.jpg" not in {
        p for row in fewer.render.files for p in row
    }


def test_truncated_jpeg_fails_at_open(log: Path, tmp_path: Path) -> None:
    copy = _copy(log, tmp_path)
    victim = load_av2_sequence(copy, image_size=SIZE).render.files[1][0]
    victim.write_bytes(victim.read_bytes()[:300])
    with pytest.raises(DataError, match=f"truncated JPEG.*{victim.name}"):
        load_av2_sequence(copy, image_size=SIZE)


def test_map_only_log_keeps_working(shared_data: Path) -> None:
    logs = sorted((shared_data / "av2-mini").glob("*-*-*-*-*"))
    seq = load_av2_sequence(logs[0], image_size=(32, 88))
    assert seq.images == "rendered" and seq.frame_rigs is None
    np.testing.assert_allclose(seq.poses[:, 2, 3], 0.0)
    with pytest.raises(DataError, match="holds no camera images"):
        load_av2_sequence(logs[0], images="real")


def test_holes_of_the_drivable_union_are_boundaries(log: Path) -> None:
    """The fixture's road loop encloses a block x in [8, 192], y in [8, 40]: its contour is a
    boundary too (shapely's union of the drivable areas is the oracle)."""
    import shapely

    world = load_av2_world(log)
    bounds = [m for m in world.instances if m.cls == MapClass.BOUNDARY]
    assert len(bounds) == 2
    union = shapely.union_all([shapely.Polygon(p) for p in world.drivable])
    (hole,) = union.interiors
    island = bounds[1].points
    assert np.allclose(island[0], island[-1])  # closes on itself
    assert shapely.Polygon(island).symmetric_difference(shapely.Polygon(hole)).area < 1e-6
    assert abs(shapely.Polygon(island).area - 184 * 32) < 1e-6


def test_non_numeric_coordinate_names_the_file(log: Path, tmp_path: Path) -> None:
    copy = _copy(log, tmp_path)
    (archive,) = (copy / "map").glob("log_map_archive_*.json")
    data = json.loads(archive.read_text())
    next(iter(data["drivable_areas"].values()))["area_boundary"][1]["x"] = "12,5"
    archive.write_text(json.dumps(data))
    with pytest.raises(DataError, match=f"{archive.name}.*not a number"):
        load_av2_world(copy)


def test_nuscenes_non_numeric_coordinate_names_the_file(tmp_path: Path) -> None:
    from icmapper.data.nuscenes import load_nuscenes
    from icmapper.testing.nuscenes_fixture import write_nuscenes_fixture

    root = write_nuscenes_fixture(tmp_path / "n", scene_lengths=(2,))
    path = root / "maps" / "expansion" / "test-town.json"
    data = json.loads(path.read_text())
    data["node"][3]["y"] = "n/a"
    path.write_text(json.dumps(data))
    with pytest.raises(DataError, match="test-town.json: node 'n3' has a bad coordinate"):
        load_nuscenes(root, "v1.0-mini")
