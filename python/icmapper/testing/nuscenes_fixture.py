"""A tiny nuScenes-format dataset written to disk, for tests and demos (not a reader: see
``icmapper.data.nuscenes``).

``write_nuscenes_fixture(dataroot)`` writes the official JSON tables and a map-expansion file of a
straight test road in the dataset's own layout, so that the reader, the "nuscenes:PATH" source and
the GT derivation can be exercised without the real dataset.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from icmapper.data.nuscenes import NUSCENES_CAMERAS


def _quat_yaw(yaw: float) -> list[float]:
    return [float(np.cos(yaw / 2)), 0.0, 0.0, float(np.sin(yaw / 2))]


def write_nuscenes_fixture(
    dataroot: str | Path,
    version: str = "v1.0-mini",
    scene_lengths: tuple[int, ...] = (6, 5, 4),
    location: str = "test-town",
) -> Path:
    """Writes a tiny nuScenes-format dataset for tests and demos; returns `dataroot` (read it with
    `icmapper.data.nuscenes.load_nuscenes(dataroot, version)` or the source "nuscenes:DATAROOT").

    Map: a straight 14 m wide road along x in [0, 400] (two road_segment polygons + two lane
    polygons), a road divider at y = 0, lane dividers at y = +-3.5, a crossing at x = 100 made of
    two touching pieces and one at x = 250. Scene k ("scene-000<k+1>") drives along +x at 5 m per
    keyframe (10 m/s, 2 Hz) from x = 20 + 60 k, with LIDAR_TOP and the six cameras per sample.
    """
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
    for cam, yaw in cam_yaw.items():
        sensors.append({"token": f"s_{cam}", "channel": cam, "modality": "camera"})
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
                sample_data.append(
                    {
                        "token": f"sd{k}_{i}_{ch}",
                        "sample_token": tok,
                        "ego_pose_token": ep,
                        "calibrated_sensor_token": cs["token"],
                        "timestamp": ts,
                        "fileformat": "jpg" if ch.startswith("CAM") else "pcd",
                        "is_key_frame": True,
                        "height": 900 if ch.startswith("CAM") else 0,
                        "width": 1600 if ch.startswith("CAM") else 0,
                        "filename": f"samples/{ch}/{tok}.jpg",
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
    ):
        dump(tdir / f"{name}.json", rows)
    dump(root / "maps" / "expansion" / f"{location}.json", map_json)
    return root
