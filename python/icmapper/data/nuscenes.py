"""nuScenes reader (plain JSON, no devkit): official tables + map expansion -> Sequences with
keyframe poses at 2 Hz and the six cameras' keyframe JPEGs with their full 3-D geometry (or, where
the dataroot has no images or the renderer is asked for, synthetic images rendered over the map).

Layout (the dataset's own):
    <dataroot>/<version>/{scene,sample,sample_data,ego_pose,calibrated_sensor,sensor,log}.json
    <dataroot>/maps/expansion/<location>.json     (node, line, polygon, lane_divider,
                                                   road_divider, ped_crossing, road_segment, lane)
    <dataroot>/samples/CAM_*/<name>.jpg           keyframe images (sample_data "filename")

Real images ("images" mode real, or auto with <dataroot>/samples/ present), as BEVFormer/MapTR's
``obtain_sensor2top``: the keyframe's reference pose is the ego pose of its LIDAR_TOP sample_data
(full SE(3)); each camera's keyframe sample_data has its own timestamp and ego pose, so
camera -> reference ego = inv(ref_ego->world) @ cam_ego->world @ cam->cam_ego (calibrated_sensor),
per keyframe (``Sequence.frame_rigs``). Intrinsics from calibrated_sensor, native size per
sample_data (width/height; the JPEG header when absent), resized by ``images.fit_intrinsics``.
Every JPEG is checked when the source opens (``images.check_jpeg``); a camera missing at a
keyframe is a DataError naming the scene, sample and channel.

Class extraction follows StreamMapNet: dividers = lane_divider + road_divider lines; crossings =
ped_crossing polygons with touching/overlapping pieces unioned; boundaries = contours of the union
of road_segment and lane polygons. Each scene's world holds the map elements whose bounding box
comes within `WORLD_MARGIN` m of the scene's poses. nuScenes has no instance identity: its
sequences have source "nuscenes" and `gt.sequence_gt` derives GT ids by matching. The lane graph
is not read (arcline paths): nuScenes worlds have no lanes, so no synthetic drives on them.

A split file is JSON `{"train": [scene names], "val": [...], ...}` (other list-valued keys allowed,
non-list keys such as "source" ignored), e.g. ../shared/data/splits/nuscenes_newsplit.json.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from icmapper.data.errors import DataError
from icmapper.data.extract import LazyRenderer, dedup_points, planar, se3, union_contours
from icmapper.data.images import RealImages, fit_intrinsics, resolve_images
from icmapper.data.types import CameraRig, MapClass, MapInstance, Sequence, WorldMap

TABLES = ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor", "log")
#: The six cameras in StreamMapNet's order.
NUSCENES_CAMERAS: tuple[str, ...] = (
    "CAM_FRONT",
    "CAM_FRONT_RIGHT",
    "CAM_FRONT_LEFT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_BACK_RIGHT",
)
POSE_CHANNELS = ("LIDAR_TOP", "CAM_FRONT")
NATIVE_IMAGE_SIZE = (900, 1600)
#: Map elements within this distance (m, bounding boxes) of a scene's poses form its world.
WORLD_MARGIN = 100.0
ID_CLASS_OFFSET = 10**10


def _read_json(path: Path) -> object:
    if not path.is_file():
        raise DataError(f"file not found: {path}")
    try:
        with open(path) as f:
            return json.load(f)
    except json.JSONDecodeError as e:
        raise DataError(f"malformed JSON {path}: {e}") from None


def _load_tables(dataroot: Path, version: str) -> dict[str, dict[str, dict]]:
    root = dataroot / version
    if not root.is_dir():
        raise DataError(f"nuScenes tables folder not found: {root}")
    tables: dict[str, dict[str, dict]] = {}
    for name in TABLES:
        path = root / f"{name}.json"
        rows = _read_json(path)
        if not isinstance(rows, list) or not all(
            isinstance(r, dict) and "token" in r for r in rows
        ):
            raise DataError(f"{path} must be a JSON list of records with a 'token'")
        tables[name] = {r["token"]: r for r in rows}
    return tables


def read_split(split_file: str | Path, split: str) -> list[str]:
    """Scene names of `split` in a split file `{"train": [...], "val": [...]}`."""
    path = Path(split_file)
    data = _read_json(path)
    if not isinstance(data, dict):
        raise DataError(f"split file {path} must be a JSON object of lists")
    names = sorted(k for k, v in data.items() if isinstance(v, list))
    if split not in names:
        raise DataError(f"unknown split {split!r} in {path}; available: {names}")
    return [str(s) for s in data[split]]


class _MapLayers:
    """Geometry of one map expansion file: nodes, lines and polygons by token."""

    def __init__(self, path: Path):
        data = _read_json(path)
        if not isinstance(data, dict):
            raise DataError(f"map file {path} is not a JSON object")
        for layer in (
            "node",
            "line",
            "polygon",
            "lane_divider",
            "road_divider",
            "ped_crossing",
            "road_segment",
            "lane",
        ):
            if not isinstance(data.get(layer), list):
                raise DataError(f"map file {path} lacks the layer {layer!r}")
        self.path = path
        self.data = data
        self.nodes = {}
        for n in data["node"]:
            try:
                xy = (float(n["x"]), float(n["y"]))
            except (KeyError, TypeError, ValueError) as e:
                raise DataError(
                    f"map file {path}: node {n.get('token', '?')!r} has a bad coordinate ({e})"
                ) from None
            if not all(np.isfinite(xy)):
                raise DataError(f"map file {path}: node {n.get('token', '?')!r} is not finite")
            self.nodes[n["token"]] = xy
        self.lines = {ln["token"]: ln["node_tokens"] for ln in data["line"]}
        self.polygons = {p["token"]: p["exterior_node_tokens"] for p in data["polygon"]}

    def _pts(self, tokens: list[str], what: str) -> NDArray[np.float64]:
        try:
            return dedup_points(np.array([self.nodes[t] for t in tokens], dtype=np.float64))
        except KeyError as e:
            raise DataError(f"{self.path}: {what} refers to the unknown node {e}") from None

    def line(self, token: str, what: str) -> NDArray[np.float64]:
        if token not in self.lines:
            raise DataError(f"{self.path}: {what} refers to the unknown line {token!r}")
        return self._pts(self.lines[token], what)

    def polygon(self, token: str, what: str) -> NDArray[np.float64]:
        if token not in self.polygons:
            raise DataError(f"{self.path}: {what} refers to the unknown polygon {token!r}")
        ring = self._pts(self.polygons[token], what)
        if len(ring) > 1 and np.allclose(ring[0], ring[-1]):
            ring = ring[:-1]
        return ring


def _near(points: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]) -> bool:
    return bool(np.all(points.max(axis=0) >= lo) and np.all(points.min(axis=0) <= hi))


def _scene_world(layers: _MapLayers, name: str, poses: NDArray[np.float64]) -> WorldMap:
    lo = poses[:, :2, 3].min(axis=0) - WORLD_MARGIN
    hi = poses[:, :2, 3].max(axis=0) + WORLD_MARGIN
    d = layers.data
    instances: list[MapInstance] = []
    crossings = [
        layers.polygon(r["polygon_token"], f"ped_crossing {r['token']}") for r in d["ped_crossing"]
    ]
    crossings = [c for c in crossings if len(c) >= 3 and _near(c, lo, hi)]
    if crossings:
        from icmapper import geom

        for k, ring in enumerate(geom.polygon_union(crossings)):
            instances.append(
                MapInstance(
                    k, MapClass.PED_CROSSING, np.asarray(ring, dtype=np.float64), True, "zebra"
                )
            )
    k = 0
    for layer, style in (("lane_divider", "dashed_white"), ("road_divider", "double_yellow")):
        for r in d[layer]:
            pts = layers.line(r["line_token"], f"{layer} {r['token']}")
            if len(pts) >= 2 and _near(pts, lo, hi):
                instances.append(
                    MapInstance(ID_CLASS_OFFSET + k, MapClass.DIVIDER, pts, False, style)
                )
                k += 1
    drivable = []
    for layer in ("road_segment", "lane"):
        for r in d[layer]:
            ring = layers.polygon(r["polygon_token"], f"{layer} {r['token']}")
            if len(ring) >= 3 and _near(ring, lo, hi):
                drivable.append(ring)
    for k, contour in enumerate(union_contours(drivable)):
        instances.append(
            MapInstance(2 * ID_CLASS_OFFSET + k, MapClass.BOUNDARY, contour, False, "curb")
        )
    return WorldMap(name, instances, drivable, {})


def load_nuscenes(
    dataroot: str | Path,
    version: str = "v1.0-trainval",
    split_file: str | Path | None = None,
    split: str | None = None,
    image_size: tuple[int, int] = (128, 352),
    render: bool = True,
    seed: int = 0,
    images: str = "auto",
) -> list[Sequence]:
    """The scenes of a nuScenes dataroot as Sequences (sorted by scene name).

    `split_file` + `split` select scenes by name (scenes of the split absent from the dataroot
    are skipped; none present is an error). Timestamps in seconds.

    images: "real" (the keyframe JPEGs of the six cameras, full SE(3) poses, per-keyframe rigs;
    see the module docstring), "render" (planar poses, one rig from the scene's first sample with
    intrinsics scaled per axis, synthetic images rendered over the map) or "auto" (real when
    `<dataroot>/samples/` exists). `render=False`: the sequences carry no images (geometry and
    ground truth only; JPEGs are not checked).
    """
    root = Path(dataroot)
    if not root.is_dir():
        raise DataError(f"nuScenes dataroot not found: {root}")
    if (split is None) != (split_file is None):
        raise ValueError("give both split_file and split, or neither")
    real = resolve_images(images, (root / "samples").is_dir(), root / "samples")
    tables = _load_tables(root, version)
    scenes = sorted(tables["scene"].values(), key=lambda s: str(s.get("name", s["token"])))
    if split is not None and split_file is not None:
        wanted = set(read_split(split_file, split))
        scenes = [s for s in scenes if s.get("name") in wanted]
        if not scenes:
            raise DataError(f"no scene of split {split!r} ({split_file}) is in {root / version}")

    channel_of = {}
    for cs in tables["calibrated_sensor"].values():
        sensor = tables["sensor"].get(cs.get("sensor_token", ""))
        if sensor is None:
            raise DataError(f"calibrated_sensor {cs['token']} refers to an unknown sensor")
        channel_of[cs["token"]] = sensor["channel"]
    by_sample: dict[str, dict[str, dict]] = {}
    for sd in tables["sample_data"].values():
        if not sd.get("is_key_frame", True):
            continue
        ch = channel_of.get(sd.get("calibrated_sensor_token", ""))
        if ch is None:
            raise DataError(f"sample_data {sd['token']} refers to an unknown calibrated_sensor")
        by_sample.setdefault(sd["sample_token"], {})[ch] = sd

    maps: dict[str, _MapLayers] = {}
    out = []
    for scene in scenes:
        name = str(scene.get("name", scene["token"]))
        samples = []
        tok = scene.get("first_sample_token", "")
        while tok:
            s = tables["sample"].get(tok)
            if s is None:
                raise DataError(f"scene {name}: unknown sample {tok!r}")
            samples.append(s)
            tok = s.get("next", "")
            if len(samples) > len(tables["sample"]):
                raise DataError(f"scene {name}: the sample chain loops")
        if not samples:
            raise DataError(f"scene {name} has no samples")
        poses = np.empty((len(samples), 4, 4))
        for i, s in enumerate(samples):
            sds = by_sample.get(s["token"], {})
            sd = next((sds[c] for c in POSE_CHANNELS if c in sds), None)
            if sd is None:
                raise DataError(f"scene {name}: sample {s['token']} has no {POSE_CHANNELS} data")
            poses[i] = _ego_pose(tables, sd, name)
        timestamps = np.array([s["timestamp"] for s in samples], dtype=np.float64) * 1e-6
        log = tables["log"].get(scene.get("log_token", ""))
        if log is None:
            raise DataError(f"scene {name} refers to an unknown log")
        location = str(log["location"])
        if location not in maps:
            maps[location] = _MapLayers(root / "maps" / "expansion" / f"{location}.json")
        if real:
            rigs, files, native = [], [], []
            for s, ref_pose in zip(samples, poses, strict=True):
                rig, paths, hw = _real_rig(
                    tables, root, by_sample.get(s["token"], {}), ref_pose, name, s, image_size
                )
                rigs.append(rig)
                files.append(paths)
                native.append(hw)
            world = replace(_scene_world(maps[location], name, poses), geo=location)
            loader = RealImages(files, native, image_size) if render else None
            if loader is not None:
                loader.check()
            out.append(
                Sequence(
                    name,
                    "nuscenes",
                    world,
                    timestamps,
                    poses,
                    rigs[0],
                    loader,
                    True,
                    rigs,
                    "real" if render else "none",
                )  # fmt: skip
            )
            continue
        poses = np.stack([planar(p) for p in poses])  # (T, 4, 4) the renderer's flat ground
        rig = _rig(tables, by_sample.get(samples[0]["token"], {}), name, image_size)
        world = replace(_scene_world(maps[location], name, poses), geo=location)
        renderer = LazyRenderer(world, rig, poses, seed) if render else None
        out.append(Sequence(name, "nuscenes", world, timestamps, poses, rig, renderer, True))
    return out


def _ego_pose(tables: dict, sd: dict, scene: str) -> NDArray[np.float64]:
    """(4, 4) ego->world of a sample_data's ego_pose record."""
    ep = tables["ego_pose"].get(sd.get("ego_pose_token", ""))
    if ep is None:
        raise DataError(f"scene {scene}: sample_data {sd['token']} has no ego_pose")
    try:
        return se3(np.asarray(ep["rotation"], float), np.asarray(ep["translation"], float))
    except (KeyError, TypeError, ValueError) as e:
        raise DataError(f"scene {scene}: ego_pose {ep['token']} is malformed ({e})") from None


def _native_size(sd: dict, path: Path) -> tuple[int, int]:
    """(h, w) of a camera sample_data: its height/width fields, else the JPEG header."""
    h, w = int(sd.get("height") or 0), int(sd.get("width") or 0)
    if h > 0 and w > 0:
        return h, w
    from PIL import Image

    try:
        with Image.open(path) as im:
            return int(im.size[1]), int(im.size[0])
    except OSError as e:
        raise DataError(f"cannot read the size of image {path}: {e}") from None


def _real_rig(
    tables: dict,
    root: Path,
    sds: dict[str, dict],
    ref_pose: NDArray[np.float64],
    scene: str,
    sample: dict,
    image_size: tuple[int, int],
) -> tuple[CameraRig, list[Path], list[tuple[int, int]]]:
    """One keyframe's six cameras: rig (cam -> reference ego composed through the camera's own
    ego pose), JPEG paths and native (h, w) sizes."""
    ks, ts, paths, native = [], [], [], []
    ref_inv = np.linalg.inv(ref_pose)  # (4, 4) world -> reference ego
    for cam in NUSCENES_CAMERAS:
        sd = sds.get(cam)
        if sd is None:
            raise DataError(
                f"scene {scene}: sample {sample['token']} has no {cam} keyframe sample_data"
            )
        cs = tables["calibrated_sensor"][sd["calibrated_sensor_token"]]
        k = np.asarray(cs.get("camera_intrinsic"), dtype=np.float64)
        if k.shape != (3, 3):
            raise DataError(f"calibrated_sensor {cs['token']}: camera_intrinsic must be 3x3")
        path = root / str(sd.get("filename", ""))
        hw = _native_size(sd, path)
        cam_to_cam_ego = se3(
            np.asarray(cs["rotation"], float), np.asarray(cs["translation"], float)
        )
        cam_ego = _ego_pose(tables, sd, scene)  # (4, 4) ego at the camera's timestamp -> world
        ts.append(ref_inv @ cam_ego @ cam_to_cam_ego)  # (4, 4) camera -> reference ego
        ks.append(fit_intrinsics(k, hw, image_size))
        paths.append(path)
        native.append(hw)
    rig = CameraRig(NUSCENES_CAMERAS, np.stack(ks), np.stack(ts), tuple(image_size))  # type: ignore[arg-type]
    return rig, paths, native


def _rig(tables: dict, sds: dict[str, dict], scene: str, image_size: tuple[int, int]) -> CameraRig:
    h, w = image_size
    ks, ts = [], []
    for cam in NUSCENES_CAMERAS:
        if cam not in sds:
            raise DataError(f"scene {scene}: the first sample has no {cam} sample_data")
        sd = sds[cam]
        cs = tables["calibrated_sensor"][sd["calibrated_sensor_token"]]
        k = np.asarray(cs.get("camera_intrinsic"), dtype=np.float64)
        if k.shape != (3, 3):
            raise DataError(f"calibrated_sensor {cs['token']}: camera_intrinsic must be 3x3")
        nh = int(sd.get("height") or NATIVE_IMAGE_SIZE[0])
        nw = int(sd.get("width") or NATIVE_IMAGE_SIZE[1])
        k = k.copy()
        k[0] *= w / nw
        k[1] *= h / nh
        ks.append(k)
        ts.append(se3(np.asarray(cs["rotation"], float), np.asarray(cs["translation"], float)))
    return CameraRig(NUSCENES_CAMERAS, np.stack(ks), np.stack(ts), (h, w))
