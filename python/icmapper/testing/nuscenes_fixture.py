"""A tiny nuScenes-format dataset written to disk, for tests and demos (not a reader: see
``icmapper.data.nuscenes``).

``write_nuscenes_fixture(dataroot)`` writes the official JSON tables and a map-expansion file of a
straight test road in the dataset's own layout, so that the reader, the "nuscenes:PATH" source and
the GT derivation can be exercised without the real dataset. With ``images=True`` it also writes
the six cameras' keyframe JPEGs (``samples/CAM_*/``), rendered by the simulator through the true
camera geometry, with a weaving, pitching and rolling ego, per-camera time offsets (each camera
sample_data has its own timestamp and ego pose), rotated cameras and one camera (CAM_BACK) of
another native size: the fixture of the real-image reader and its devkit oracle tests.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from icmapper.data.nuscenes import NUSCENES_CAMERAS


def _quat_yaw(yaw: float) -> list[float]:
    return [float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))]


#: Camera time offsets (ms) from the LIDAR_TOP keyframe timestamp in the image fixture (nuScenes'
#: cameras fire one after another as the lidar sweeps past them).
CAMERA_OFFSETS_MS = dict(zip(NUSCENES_CAMERAS, (0.0, 12.0, -12.0, 37.0, -25.0, 25.0), strict=True))
#: Native (h, w) of the image fixture's cameras (nuScenes' 900 x 1600 / 4; CAM_BACK differs).
IMAGE_FIXTURE_SIZES = {c: (225, 400) for c in NUSCENES_CAMERAS} | {"CAM_BACK": (240, 320)}


def fixture_ego_pose(k: int, t: float) -> np.ndarray:
    """(4, 4) ego->world of the image fixture's scene k at time t (s from its start): along +x at
    10 m/s from x = 20 + 60 k, weaving across the lane (yaw follows), pitching, rolling and
    bouncing a little."""
    from icmapper.testing.camera_images import euler_pose

    x = 20.0 + 60.0 * k + 10.0 * t
    y = -1.75 + 1.2 * np.sin(0.9 * t + k)
    yaw = float(np.arctan2(1.2 * 0.9 * np.cos(0.9 * t + k), 10.0))
    return euler_pose(
        x, y, 0.03 * np.sin(2.0 * t), yaw, 0.02 * np.sin(1.7 * t + k), 0.015 * np.cos(1.3 * t)
    )


def write_nuscenes_fixture(
    dataroot: str | Path,
    version: str = "v1.0-mini",
    scene_lengths: tuple[int, ...] = (6, 5, 4),
    location: str = "test-town",
    images: bool = False,
    seed: int = 0,
) -> Path:
    """Writes a tiny nuScenes-format dataset for tests and demos; returns `dataroot` (read it with
    `icmapper.data.nuscenes.load_nuscenes(dataroot, version)` or the source "nuscenes:DATAROOT").

    Map: a straight 14 m wide road along x in [0, 400] (two road_segment polygons + two lane
    polygons), a road divider at y = 0, lane dividers at y = +-3.5, a crossing at x = 100 made of
    two touching pieces and one at x = 250. Scene k ("scene-000<k+1>") drives along +x at 5 m per
    keyframe (10 m/s, 2 Hz) from x = 20 + 60 k, with LIDAR_TOP and the six cameras per sample.

    images=True: the drive of `fixture_ego_pose` instead (full SE(3)), cameras pitched down and
    rolled, each camera's sample_data at its own time (`CAMERA_OFFSETS_MS`) with its own ego pose,
    native sizes `IMAGE_FIXTURE_SIZES`, and the JPEGs rendered (seeded by `seed`).
    """
    from icmapper.testing.camera_images import look_rotation, matrix_to_quat

    root = Path(dataroot)
    tdir = root / version
    tdir.mkdir(parents=True, exist_ok=True)
    (root / "maps" / "expansion").mkdir(parents=True, exist_ok=True)

    nodes, lines, polygons = [], [], []

    def node(x: float, y: float) -> str:
        tok = f"n{len(nodes)}"
        nodes.append({"token": tok, "x": x, "y": y})
        return tok

    def line(pts: list[tuple[float, float]]) -> str:
        tok = f"l{len(lines)}"
        lines.append({"token": tok, "node_tokens": [node(*p) for p in pts]})
        return tok

    def poly(pts: list[tuple[float, float]]) -> str:
        tok = f"p{len(polygons)}"
        polygons.append(
            {"token": tok, "exterior_node_tokens": [node(*p) for p in pts], "holes": []}
        )
        return tok

    def rect(x0: float, x1: float, y0: float, y1: float) -> str:
        return poly([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])

    road = [
        {
            "token": f"rs{i}",
            "polygon_token": rect(x0, x1, -7, 7),
            "is_intersection": False,
            "drivable_area_token": "",
        }
        for i, (x0, x1) in enumerate(((0, 200), (200, 400)))
    ]
    lanes = [
        {"token": f"ln{i}", "polygon_token": rect(0, 400, y0, y1), "lane_type": "CAR"}
        for i, (y0, y1) in enumerate(((-7, 0), (0, 7)))
    ]
    xs = [float(x) for x in np.linspace(0, 400, 41)]
    map_json = {
        "version": "1.3",
        "node": nodes,
        "line": lines,
        "polygon": polygons,
        "road_segment": road,
        "lane": lanes,
        "road_divider": [
            {
                "token": "rd0",
                "line_token": line([(x, 0.0) for x in xs]),
                "road_segment_token": "rs0",
            }
        ],
        "lane_divider": [
            {
                "token": f"ld{i}",
                "line_token": line([(x, y) for x in xs]),
                "lane_divider_segments": [],
            }
            for i, y in enumerate((-3.5, 3.5))
        ],
        "ped_crossing": [
            {"token": f"pc{i}", "polygon_token": rect(x0, x1, y0, y1), "road_segment_token": "rs0"}
            for i, (x0, x1, y0, y1) in enumerate(
                ((100, 104, -7, 0.5), (100, 104, 0.5, 7), (250, 254, -7, 7))
            )
        ],
        "drivable_area": [],
        "walkway": [],
        "stop_line": [],
        "carpark_area": [],
        "road_block": [],
        "traffic_light": [],
        "canvas_edge": {},
        "connectivity": {},
        "arcline_path_3": {},
    }

    sensors = [{"token": "s_lidar", "channel": "LIDAR_TOP", "modality": "lidar"}]
    cal = [
        {
            "token": "c_lidar",
            "sensor_token": "s_lidar",
            "translation": [0.9, 0.0, 1.8],
            "rotation": [1.0, 0.0, 0.0, 0.0],
            "camera_intrinsic": [],
        }
    ]
    cam_yaw = dict(zip(NUSCENES_CAMERAS, (0.0, -0.96, 0.96, np.pi, 1.9, -1.9), strict=True))
    for ci, (cam, yaw) in enumerate(cam_yaw.items()):
        sensors.append({"token": f"s_{cam}", "channel": cam, "modality": "camera"})
        if images:
            h, w = IMAGE_FIXTURE_SIZES[cam]
            f = 1266.4 / 4 if w == 400 else 180.0
            rot = look_rotation(yaw, 0.06 + 0.015 * ci, 0.02 - 0.01 * ci)
            k_cam = [[f, 0.0, w / 2 + 3.0], [0.0, f * 1.002, 0.46 * h], [0.0, 0.0, 1.0]]
            cal.append(
                {
                    "token": f"c_{cam}",
                    "sensor_token": f"s_{cam}",
                    "translation": [1.0 - 0.3 * abs(np.sin(yaw)), 0.4 * np.sin(yaw), 1.5],
                    "rotation": matrix_to_quat(rot),
                    "camera_intrinsic": k_cam,
                }
            )
            continue
        # camera frame (x right, y down, z forward) -> ego, looking along `yaw`.
        r = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        c, s = np.cos(yaw), np.sin(yaw)
        r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ r
        w = np.sqrt(max(1e-12, 1 + np.trace(r))) / 2
        q = [
            w,
            (r[2, 1] - r[1, 2]) / (4 * w),
            (r[0, 2] - r[2, 0]) / (4 * w),
            (r[1, 0] - r[0, 1]) / (4 * w),
        ]
        cal.append(
            {
                "token": f"c_{cam}",
                "sensor_token": f"s_{cam}",
                "translation": [1.0, 0.0, 1.5],
                "rotation": q,
                "camera_intrinsic": [[1266.4, 0.0, 816.3], [0.0, 1266.4, 491.5], [0.0, 0.0, 1.0]],
            }
        )

    logs = [
        {
            "token": "log0",
            "logfile": "fixture",
            "vehicle": "v",
            "date_captured": "2024-01-01",
            "location": location,
        }
    ]
    scenes, samples, sample_data, ego_poses = [], [], [], []
    t0 = 1_600_000_000_000_000
    ts0 = [t0 + k * 100_000_000 for k in range(len(scene_lengths))]
    for k, n in enumerate(scene_lengths):
        toks = [f"smp{k}_{i}" for i in range(n)]
        scenes.append(
            {
                "token": f"scn{k}",
                "log_token": "log0",
                "nbr_samples": n,
                "first_sample_token": toks[0] if n else "",
                "last_sample_token": toks[-1] if n else "",
                "name": f"scene-{k + 1:04d}",
                "description": "fixture",
            }
        )
        for i, tok in enumerate(toks):
            ts = t0 + k * 100_000_000 + i * 500_000
            samples.append(
                {
                    "token": tok,
                    "timestamp": ts,
                    "scene_token": f"scn{k}",
                    "prev": toks[i - 1] if i else "",
                    "next": toks[i + 1] if i + 1 < n else "",
                }
            )
            ep = f"ep{k}_{i}"
            if not images:
                ego_poses.append(
                    {
                        "token": ep,
                        "timestamp": ts,
                        "rotation": _quat_yaw(0.0),
                        "translation": [20.0 + 60.0 * k + 5.0 * i, -1.75, 0.0],
                    }
                )
            for cs in cal:
                ch = cs["sensor_token"][2:]
                cam = ch.startswith("CAM")
                sd_ts, sd_ep = ts, ep
                hw = (900, 1600) if cam else (0, 0)
                name = f"samples/{ch}/{tok}.jpg"
                if images:
                    sd_ts = ts + int(1000 * CAMERA_OFFSETS_MS.get(ch, 0.0))
                    sd_ep = f"ep{k}_{i}_{ch}"
                    pose = fixture_ego_pose(k, (sd_ts - ts0[k]) * 1e-6)
                    ego_poses.append(
                        {
                            "token": sd_ep,
                            "timestamp": sd_ts,
                            "rotation": matrix_to_quat(pose[:3, :3]),
                            "translation": [float(v) for v in pose[:3, 3]],
                        }
                    )
                    hw = IMAGE_FIXTURE_SIZES[ch] if cam else (0, 0)
                    name = (
                        f"samples/{ch}/scene-{k + 1:04d}__{ch}__{sd_ts}.jpg"
                        if cam
                        else f"samples/{ch}/scene-{k + 1:04d}__{ch}__{sd_ts}.pcd.bin"
                    )
                sample_data.append(
                    {
                        "token": f"sd{k}_{i}_{ch}",
                        "sample_token": tok,
                        "ego_pose_token": sd_ep,
                        "calibrated_sensor_token": cs["token"],
                        "timestamp": sd_ts,
                        "fileformat": "jpg" if cam else "pcd",
                        "is_key_frame": True,
                        "height": hw[0],
                        "width": hw[1],
                        "filename": name,
                        "prev": "",
                        "next": "",
                    }
                )

    def dump(path: Path, obj: object) -> None:
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(obj))
        tmp.replace(path)

    for name, rows in (
        ("scene", scenes),
        ("sample", samples),
        ("sample_data", sample_data),
        ("ego_pose", ego_poses),
        ("calibrated_sensor", cal),
        ("sensor", sensors),
        ("log", logs),
        # Tables the devkit loads (no annotations; a blank semantic-prior map mask).
        ("category", []),
        ("attribute", []),
        ("visibility", []),
        ("instance", []),
        ("sample_annotation", []),
        (
            "map",
            [
                {
                    "token": "map0",
                    "log_tokens": ["log0"],
                    "category": "semantic_prior",
                    "filename": f"maps/{location}.png",
                }
            ],
        ),
    ):
        dump(tdir / f"{name}.json", rows)
    dump(root / "maps" / "expansion" / f"{location}.json", map_json)
    from PIL import Image

    Image.new("L", (8, 8)).save(root / "maps" / f"{location}.png")
    if images:
        _render_images(root, version, tdir, cal, sample_data, ego_poses, seed)
    return root


def _render_images(
    root: Path,
    version: str,
    tdir: Path,
    cal: list[dict],
    sample_data: list[dict],
    ego_poses: list[dict],
    seed: int,
) -> None:
    """Renders every camera sample_data's JPEG through its own ego pose and calibration."""
    from icmapper.data.extract import se3
    from icmapper.data.nuscenes import load_nuscenes
    from icmapper.testing.camera_images import CameraShot, render_jpegs

    seqs = load_nuscenes(root, version, images="render", render=False)
    by_scene = {s.name: s.world for s in seqs}
    cs_by = {c["token"]: c for c in cal}
    ep_by = {e["token"]: e for e in ego_poses}
    shots: dict[str, list[CameraShot]] = {}
    for sd in sample_data:
        if sd["fileformat"] != "jpg":
            continue
        cs, ep = cs_by[sd["calibrated_sensor_token"]], ep_by[sd["ego_pose_token"]]
        cam_to_ego = se3(np.asarray(cs["rotation"]), np.asarray(cs["translation"]))
        ego = se3(np.asarray(ep["rotation"]), np.asarray(ep["translation"]))
        scene = sd["filename"].split("/")[-1].split("__")[0]
        shots.setdefault(scene, []).append(
            CameraShot(
                root / sd["filename"],
                ego @ cam_to_ego,
                np.asarray(cs["camera_intrinsic"], np.float64),
                (int(sd["height"]), int(sd["width"])),
            )
        )
    for scene, items in shots.items():
        render_jpegs(by_scene[scene], items, seed=seed)
