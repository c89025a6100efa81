"""A tiny Argoverse 2 *sensor* log written to disk, for tests and demos (not a reader: see
``icmapper.data.av2``).

``write_av2_sensor_log(root)`` writes one log in the dataset's own layout: a map archive (a road
loop around a city block, so the drivable-area union has a hole; lane segments with marked
boundaries; a crossing), ``city_SE3_egovehicle.feather`` (poses every 10 ms and at every sweep and
image time), the calibration feathers (7 ring cameras, the front centre one portrait; either
built in or the extrinsics of a real calibration folder, intrinsics scaled down), lidar sweep
names at 10 Hz (``sensors/lidar/<ns>.feather``, a few points each) and the ring-camera JPEGs
around every 2 Hz keyframe, each camera with its own time offset, rendered through the true
camera geometry while the ego moves and turns (plus a decoy image 50 ms later, which the reader
must not pick).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.feather as feather

from icmapper.data.av2 import AV2_RING_CAMERAS
from icmapper.testing.camera_images import (
    CameraShot,
    euler_pose,
    look_rotation,
    matrix_to_quat,
    render_jpegs,
)

LOG_ID = "0c6e62d7-bdfa-3061-8d3d-03b13aa21f68"
CITY = "PIT"
T0_NS = 315_966_000_000_000_000
#: Per-camera time offsets (ms) from the sweep, in AV2_RING_CAMERAS order (all within 25 ms).
CAMERA_OFFSETS_MS = (0.0, -8.0, 8.0, -16.0, 16.0, -21.0, 21.0)
#: Camera yaws (deg) and the built-in calibration's native (h, w) (AV2's / 8; front portrait).
CAMERA_YAWS_DEG = (0.0, 45.0, -45.0, 90.0, -90.0, 153.0, -153.0)
NATIVE_SCALE = 8


def fixture_ego_pose(t: float) -> np.ndarray:
    """(4, 4) ego->city at t seconds into the log: along +x at 8 m/s from x = 15, turning
    (weaving across the lane, yaw up to ~0.2 rad), pitching and rolling a little."""
    x = 15.0 + 8.0 * t
    y = -4.0 + 1.5 * np.sin(1.1 * t)
    yaw = float(np.arctan2(1.5 * 1.1 * np.cos(1.1 * t), 8.0))
    return euler_pose(
        x, y, 0.02 * np.sin(1.5 * t), yaw, 0.015 * np.sin(2.1 * t), 0.01 * np.cos(1.7 * t)
    )


def _pts(xy: list[tuple[float, float]]) -> list[dict]:
    return [{"x": float(x), "y": float(y), "z": 0.0} for x, y in xy]


def _map_archive() -> dict:
    """A road loop: the main road y in [-8, 8] for x in [0, 200], a back road y in [40, 48] and
    two connectors x in [0, 8] / [192, 200]; the block between them is a hole of the union."""

    def rect(x0: float, x1: float, y0: float, y1: float) -> list[dict]:
        return _pts([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])

    areas = [rect(0, 200, -8, 8), rect(0, 200, 40, 48), rect(0, 8, 8, 40), rect(192, 200, 8, 40)]
    xs = np.linspace(0, 200, 21)

    def lane(lid: int, y_left: float, y_right: float, left: str, right: str, flip: bool) -> dict:
        lx = xs[::-1] if flip else xs
        return {
            "id": lid,
            "is_intersection": False,
            "lane_type": "VEHICLE",
            "left_lane_boundary": _pts([(x, y_left) for x in lx]),
            "right_lane_boundary": _pts([(x, y_right) for x in lx]),
            "left_lane_mark_type": left,
            "right_lane_mark_type": right,
            "successors": [],
            "predecessors": [],
            "left_neighbor_id": None,
            "right_neighbor_id": None,
        }

    lanes = [
        lane(101, 0.0, -4.0, "DOUBLE_SOLID_YELLOW", "DASHED_WHITE", False),
        lane(102, -4.0, -8.0, "DASHED_WHITE", "NONE", False),
        lane(103, 0.0, 4.0, "DOUBLE_SOLID_YELLOW", "DASHED_WHITE", True),
        lane(104, 4.0, 8.0, "DASHED_WHITE", "NONE", True),
    ]
    crossing = {
        "id": 7,
        "edge1": _pts([(48.0, -8.0), (48.0, 8.0)]),
        "edge2": _pts([(52.0, -8.0), (52.0, 8.0)]),
    }
    return {
        "lane_segments": {str(ls["id"]): ls for ls in lanes},
        "pedestrian_crossings": {"7": crossing},
        "drivable_areas": {
            str(k): {"id": k, "area_boundary": a} for k, a in enumerate(areas, start=1)
        },
    }


def _calibration(
    calibration_from: Path | None,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, tuple[int, int]]]:
    """Camera->ego (4, 4), native intrinsics (3, 3) and native (h, w) per ring camera."""
    ext, ks, sizes = {}, {}, {}
    rows_e: dict[str, dict] = {}
    rows_i: dict[str, dict] = {}
    if calibration_from is not None:
        rows_e = {
            r["sensor_name"]: r
            for r in feather.read_table(calibration_from / "egovehicle_SE3_sensor.feather")
            .to_pylist()
        }  # fmt: skip
        rows_i = {
            r["sensor_name"]: r
            for r in feather.read_table(calibration_from / "intrinsics.feather").to_pylist()
        }
    for c, (cam, yaw) in enumerate(zip(AV2_RING_CAMERAS, CAMERA_YAWS_DEG, strict=True)):
        if cam in rows_e and cam in rows_i:
            from icmapper.data.extract import se3

            e, i = rows_e[cam], rows_i[cam]
            ext[cam] = se3(
                np.array([e["qw"], e["qx"], e["qy"], e["qz"]], float),
                np.array([e["tx_m"], e["ty_m"], e["tz_m"]], float),
            )
            s = 1.0 / NATIVE_SCALE
            h, w = round(i["height_px"] * s), round(i["width_px"] * s)
            ks[cam] = np.array(
                [
                    [i["fx_px"] * w / i["width_px"], 0.0, i["cx_px"] * w / i["width_px"]],
                    [0.0, i["fy_px"] * h / i["height_px"], i["cy_px"] * h / i["height_px"]],
                    [0.0, 0.0, 1.0],
                ]
            )
            sizes[cam] = (h, w)
            continue
        m = np.eye(4)
        m[:3, :3] = look_rotation(np.deg2rad(yaw), 0.05 + 0.01 * c, 0.01 * (c % 3) - 0.01)
        m[:3, 3] = [1.6 * np.cos(np.deg2rad(yaw)) * 0.8, 0.8 * np.sin(np.deg2rad(yaw)), 1.4]
        portrait = cam == "ring_front_center"
        h, w = (256, 194) if portrait else (194, 256)
        f = 1776.0 / NATIVE_SCALE if portrait else 1687.5 / NATIVE_SCALE
        ks[cam] = np.array([[f, 0.0, w / 2 - 2.5], [0.0, f, h / 2 + 1.5], [0.0, 0.0, 1.0]])
        ext[cam] = m
        sizes[cam] = (h, w)
    return ext, ks, sizes


def _write_feather(path: Path, columns: dict[str, list]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    feather.write_feather(pa.table(columns), str(path))


def write_av2_sensor_log(
    root: str | Path,
    duration_s: float = 2.0,
    calibration_from: str | Path | None = None,
    seed: int = 0,
    log_id: str = LOG_ID,
) -> Path:
    """Writes one AV2 sensor log under `root` (module docstring); returns the log directory
    (read it with ``icmapper.data.av2.load_av2_sequence`` or the source "av2:LOG_DIR").

    duration_s: lidar sweeps every 100 ms over [0, duration_s]; keyframes (with images) every
    500 ms. calibration_from: a real `calibration/` folder whose extrinsics (and intrinsics,
    scaled down by 8) are used; None: the built-in one.
    """
    from icmapper.data.av2 import world_from_archive

    log = Path(root) / log_id
    (log / "map").mkdir(parents=True, exist_ok=True)
    archive = _map_archive()
    (log / "map" / f"log_map_archive_{log_id}____{CITY}_city_00000.json").write_text(
        json.dumps(archive)
    )
    ext, ks, sizes = _calibration(Path(calibration_from) if calibration_from else None)
    rows_e: dict[str, list] = {k: [] for k in ("sensor_name", "qw", "qx", "qy", "qz")}
    rows_e |= {k: [] for k in ("tx_m", "ty_m", "tz_m")}
    rows_i: dict[str, list] = {
        k: []
        for k in ("sensor_name", "fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "k3")
        + ("height_px", "width_px")
    }
    for cam in AV2_RING_CAMERAS:
        q = matrix_to_quat(ext[cam][:3, :3])
        for key, v in zip(("qw", "qx", "qy", "qz"), q, strict=True):
            rows_e[key].append(v)
        for key, v in zip(("tx_m", "ty_m", "tz_m"), ext[cam][:3, 3], strict=True):
            rows_e[key].append(float(v))
        rows_e["sensor_name"].append(cam)
        k = ks[cam]
        for key, v in (
            ("sensor_name", cam),
            ("fx_px", k[0, 0]),
            ("fy_px", k[1, 1]),
            ("cx_px", k[0, 2]),
            ("cy_px", k[1, 2]),
            ("k1", -0.25),
            ("k2", -0.1),
            ("k3", 0.2),
            ("height_px", sizes[cam][0]),
            ("width_px", sizes[cam][1]),
        ):
            rows_i[key].append(v)
    _write_feather(log / "calibration" / "egovehicle_SE3_sensor.feather", rows_e)
    _write_feather(log / "calibration" / "intrinsics.feather", rows_i)

    sweeps = [T0_NS + 100_000_000 * k for k in range(int(round(duration_s * 10)) + 1)]
    for s in sweeps:
        _write_feather(
            log / "sensors" / "lidar" / f"{s}.feather",
            {"x": [1.0, 2.0], "y": [0.0, 0.5], "z": [0.1, 0.2], "intensity": [3, 4]},
        )
    keys = sweeps[::5]
    image_ns: dict[str, list[int]] = {cam: [] for cam in AV2_RING_CAMERAS}
    for s in keys:
        for cam, off in zip(AV2_RING_CAMERAS, CAMERA_OFFSETS_MS, strict=True):
            image_ns[cam].append(s + int(off * 1e6))
    pose_ns = set(range(T0_NS - 60_000_000, sweeps[-1] + 120_000_000, 10_000_000))
    pose_ns |= set(sweeps)
    for cam in AV2_RING_CAMERAS:
        pose_ns |= set(image_ns[cam])
    stamps = sorted(pose_ns)
    cols: dict[str, list] = {k: [] for k in ("timestamp_ns", "qw", "qx", "qy", "qz")}
    cols |= {k: [] for k in ("tx_m", "ty_m", "tz_m")}
    for t in stamps:
        pose = fixture_ego_pose((t - T0_NS) * 1e-9)
        cols["timestamp_ns"].append(t)
        for key, v in zip(("qw", "qx", "qy", "qz"), matrix_to_quat(pose[:3, :3]), strict=True):
            cols[key].append(v)
        for key, v in zip(("tx_m", "ty_m", "tz_m"), pose[:3, 3], strict=True):
            cols[key].append(float(v))
    _write_feather(log / "city_SE3_egovehicle.feather", cols)

    world = world_from_archive(archive, log_id)
    shots = []
    for cam in AV2_RING_CAMERAS:
        for t in image_ns[cam]:
            pose = fixture_ego_pose((t - T0_NS) * 1e-9)
            shots.append(
                CameraShot(
                    log / "sensors" / "cameras" / cam / f"{t}.jpg",
                    pose @ ext[cam],
                    ks[cam],
                    sizes[cam],
                )
            )
    render_jpegs(world, shots, seed=seed)
    for cam in AV2_RING_CAMERAS:  # decoys 50 ms after each image: never the nearest to a sweep
        for t in image_ns[cam]:
            src = log / "sensors" / "cameras" / cam / f"{t}.jpg"
            (src.parent / f"{t + 50_000_000}.jpg").write_bytes(src.read_bytes())
    return log
