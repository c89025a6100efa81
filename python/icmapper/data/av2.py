"""Argoverse 2 reader (pyarrow only, no `av2` package): log map archive -> WorldMap, ego poses,
camera calibration, and sequences with the log's own ring-camera images (sensor logs) or
synthetic images rendered over the real map (map-only logs).

Log layout (the dataset's own):
    <log_dir>/map/log_map_archive_<log_id>____<CITY>_city_<n>.json
    <log_dir>/city_SE3_egovehicle.feather      timestamp_ns, qw qx qy qz, tx_m ty_m tz_m
    <log_dir>/calibration/egovehicle_SE3_sensor.feather, intrinsics.feather   (optional)
    <log_dir>/sensors/lidar/<timestamp_ns>.feather                          (sensor logs)
    <log_dir>/sensors/cameras/ring_*/<timestamp_ns>.jpg                     (sensor logs)

Sensor logs (real images; `images` auto with `sensors/cameras/` present, or real): keyframes at
the lidar sweep timestamps (the names of `sensors/lidar/*.feather`) subsampled to 2 Hz; for each
of the 7 ring cameras the image nearest to the sweep, within `CAMERA_TOLERANCE_NS` (25 ms: half
the 20 Hz ring-camera period, the devkit's own bound); a keyframe where a camera has no image
within it is skipped with a warning naming the sweep and the camera (the log's first and last
sweeps often lack a camera), and a log where every keyframe is skipped is a DataError. Poses of
`city_SE3_egovehicle.feather` are interpolated (translation linearly, rotation by slerp) at the
sweep and image timestamps; the keyframe's pose is the ego pose at its sweep (full SE(3)) and
camera -> reference ego = inv(city_SE3_ego(sweep)) @ city_SE3_ego(image) @ ego_SE3_camera, per
keyframe. Intrinsics from `intrinsics.feather` with the "fit" resize of `images.py` (the portrait
front camera keeps its aspect ratio). Lens distortion (k1, k2, k3) is not applied: the images are
used as they are with the pinhole model, as the devkit's `PinholeCamera` and StreamMapNet do.

Class extraction follows StreamMapNet (see docs/data.md): dividers = lane-segment boundaries whose
mark type is not NONE/UNKNOWN, de-duplicated, without those on a road boundary, split pieces
connected; boundaries = contours of the union of drivable areas; crossings = edge1 + reversed
edge2. World instance ids are derived from the map's ids (stable across runs), offset per class.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.feather as feather
from numpy.typing import NDArray

from icmapper.data.errors import DataError
from icmapper.data.extract import (
    LazyRenderer,
    Line,
    connect_lines,
    dedup_points,
    interpolate_poses,
    planar,
    polyline_length,
    remove_boundary_dividers,
    remove_repeated_lines,
    se3,
    subsample_indices,
    union_contours,
)
from icmapper.data.images import RealImages, fit_intrinsics, resolve_images
from icmapper.data.types import (
    KEYFRAME_HZ,
    CameraRig,
    LaneSegment,
    MapClass,
    MapInstance,
    Sequence,
    WorldMap,
)

#: The seven ring cameras, in the order of the rig.
AV2_RING_CAMERAS: tuple[str, ...] = (
    "ring_front_center",
    "ring_front_left",
    "ring_front_right",
    "ring_side_left",
    "ring_side_right",
    "ring_rear_left",
    "ring_rear_right",
)

#: Lane mark type -> paint style. NONE / UNKNOWN are not dividers.
MARK_STYLES: dict[str, str] = {
    "SOLID_WHITE": "solid_white",
    "DASHED_WHITE": "dashed_white",
    "DOUBLE_SOLID_WHITE": "double_white",
    "DOUBLE_DASH_WHITE": "double_dashed_white",
    "SOLID_YELLOW": "solid_yellow",
    "DASHED_YELLOW": "dashed_yellow",
    "DOUBLE_SOLID_YELLOW": "double_yellow",
    "DOUBLE_DASH_YELLOW": "double_dashed_yellow",
    "SOLID_DASH_WHITE": "solid_dashed_white",
    "DASH_SOLID_WHITE": "dashed_solid_white",
    "SOLID_DASH_YELLOW": "solid_dashed_yellow",
    "DASH_SOLID_YELLOW": "dashed_solid_yellow",
    "SOLID_BLUE": "solid_blue",
}
NO_MARK = ("NONE", "UNKNOWN")

#: World ids: class * ID_CLASS_OFFSET + map-derived id (crossing id; 2 * lane id + side for
#: dividers, 0 left / 1 right; rank of the contour for boundaries).
ID_CLASS_OFFSET = 10**10
#: Lane types the ego may drive on (lane graph); bike lanes still give dividers.
DRIVABLE_LANE_TYPES = ("VEHICLE", "BUS")

POSE_FILE = "city_SE3_egovehicle.feather"
MAX_POSE_GAP_S = 1.0
#: Largest |image time - sweep time| accepted for a keyframe's camera (half the 20 Hz period).
CAMERA_TOLERANCE_NS = 25_000_000


def _log_dir(log_dir: str | Path) -> Path:
    path = Path(log_dir)
    if not path.is_dir():
        raise DataError(f"Argoverse 2 log directory not found: {path}")
    return path


def _map_archive(log_dir: Path) -> Path:
    found = sorted((log_dir / "map").glob("log_map_archive_*.json"))
    if not found:
        raise DataError(f"no map archive {log_dir / 'map' / 'log_map_archive_*.json'}")
    return found[0]


def _xy(points: object, where: str) -> NDArray[np.float64]:
    try:
        arr = np.array([[p["x"], p["y"]] for p in points], dtype=np.float64)  # type: ignore[union-attr]
    except (TypeError, KeyError) as e:
        raise DataError(f"{where}: expected a list of {{x, y, z}} points ({e!r})") from None
    except ValueError as e:
        raise DataError(f"{where}: a coordinate is not a number ({e})") from None
    if arr.ndim != 2 or len(arr) < 2 or not np.all(np.isfinite(arr)):
        raise DataError(f"{where}: needs at least 2 finite points")
    return arr


def read_map_archive(path: Path) -> dict:
    """Parses a log map archive JSON and checks its three layers are there."""
    try:
        with open(path) as f:
            data = json.load(f)
    except json.JSONDecodeError as e:
        raise DataError(f"malformed map archive JSON {path}: {e}") from None
    if not isinstance(data, dict):
        raise DataError(f"map archive {path} is not a JSON object")
    for layer in ("lane_segments", "pedestrian_crossings", "drivable_areas"):
        if not isinstance(data.get(layer), dict):
            raise DataError(f"map archive {path} lacks the layer {layer!r}")
    return data


def _lane_graph(lane_segments: dict, path: Path) -> dict[int, LaneSegment]:
    from icmapper import geom

    lanes: dict[int, LaneSegment] = {}
    for key, ls in lane_segments.items():
        if ls.get("lane_type", "VEHICLE") not in DRIVABLE_LANE_TYPES:
            continue
        where = f"{path.name}: lane segment {key}"
        left = dedup_points(_xy(ls.get("left_lane_boundary"), where))
        right = dedup_points(_xy(ls.get("right_lane_boundary"), where))
        if len(left) < 2 or len(right) < 2:
            continue
        n = max(2, int(np.ceil(max(polyline_length(left), polyline_length(right)))) + 1)
        lr = np.asarray(geom.resample(left, n), dtype=np.float64)  # (n, 2)
        rr = np.asarray(geom.resample(right, n), dtype=np.float64)  # (n, 2)
        lanes[int(ls["id"])] = LaneSegment(
            id=int(ls["id"]),
            centerline=(lr + rr) / 2.0,
            successors=tuple(int(s) for s in ls.get("successors", [])),
            width=float(np.linalg.norm(lr - rr, axis=1).mean()),
        )
    for lane in lanes.values():
        lane.successors = tuple(s for s in lane.successors if s in lanes)
    return lanes


def world_from_archive(data: dict, name: str, path: Path = Path("<map>")) -> WorldMap:
    """Builds the WorldMap of a parsed map archive (see `read_map_archive`)."""
    # Road boundaries: contours of the union of drivable areas.
    drivable = []
    for key, da in data["drivable_areas"].items():
        ring = dedup_points(_xy(da.get("area_boundary"), f"{path.name}: drivable area {key}"))
        if len(ring) > 1 and np.allclose(ring[0], ring[-1]):
            ring = ring[:-1]
        if len(ring) >= 3:
            drivable.append(ring)
    contours = union_contours(drivable)

    # Dividers: marked lane boundaries, de-duplicated, minus those on a boundary, connected.
    lines: list[Line] = []
    for key in sorted(data["lane_segments"], key=str):
        ls = data["lane_segments"][key]
        lane_id = int(ls.get("id", key))
        if not 0 <= lane_id < ID_CLASS_OFFSET // 2:
            raise DataError(f"{path.name}: lane segment id {lane_id} out of the supported range")
        for side, bkey, mkey in (
            (0, "left_lane_boundary", "left_lane_mark_type"),
            (1, "right_lane_boundary", "right_lane_mark_type"),
        ):
            mark = str(ls.get(mkey, "UNKNOWN"))
            if mark in NO_MARK:
                continue
            pts = dedup_points(_xy(ls.get(bkey), f"{path.name}: lane segment {key} {bkey}"))
            if len(pts) < 2:
                continue
            style = MARK_STYLES.get(mark, mark.lower())
            lines.append(Line(2 * lane_id + side, pts, style))
    dividers = connect_lines(remove_boundary_dividers(remove_repeated_lines(lines), contours))

    instances: list[MapInstance] = []
    for key in sorted(data["pedestrian_crossings"], key=str):
        pc = data["pedestrian_crossings"][key]
        where = f"{path.name}: pedestrian crossing {key}"
        e1, e2 = _xy(pc.get("edge1"), where), _xy(pc.get("edge2"), where)
        ring = dedup_points(np.vstack([e1, e2[::-1]]))
        if len(ring) > 1 and np.allclose(ring[0], ring[-1]):
            ring = ring[:-1]
        cid = int(pc.get("id", key))
        if not 0 <= cid < ID_CLASS_OFFSET:
            raise DataError(f"{where}: id {cid} out of the supported range")
        if len(ring) >= 3:
            instances.append(MapInstance(cid, MapClass.PED_CROSSING, ring, True, "zebra"))
    for d in dividers:
        instances.append(
            MapInstance(ID_CLASS_OFFSET + d.id, MapClass.DIVIDER, d.points, False, d.style)
        )
    for k, c in enumerate(contours):
        instances.append(MapInstance(2 * ID_CLASS_OFFSET + k, MapClass.BOUNDARY, c, False, "curb"))
    return WorldMap(name, instances, drivable, _lane_graph(data["lane_segments"], path))


def load_av2_world(log_dir: str | Path) -> WorldMap:
    """The world map of one log: `<log_dir>/map/log_map_archive_*.json` -> WorldMap named by the
    log id (instances with map-derived ids, drivable polygons, lane graph of vehicle/bus lanes)."""
    log = _log_dir(log_dir)
    path = _map_archive(log)
    world = world_from_archive(read_map_archive(path), log.name, path)
    world.geo = archive_city(path)
    return world


def archive_city(path: Path) -> str:
    """The city code of a map archive named ``log_map_archive_<log>____<CITY>_city_<n>.json``
    (as the av2 devkit reads it), "" when the name does not say."""
    parts = path.stem.split("____")
    return parts[1].split("_")[0] if len(parts) == 2 else ""


def _read_feather(path: Path, columns: tuple[str, ...]) -> pa.Table:
    if not path.is_file():
        raise DataError(f"file not found: {path}")
    try:
        table = feather.read_table(path)
    except (pa.ArrowInvalid, OSError) as e:
        raise DataError(f"cannot read feather file {path}: {e}") from None
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise DataError(f"{path} lacks the columns {missing}")
    return table


def read_raw_poses(
    log_dir: str | Path,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64]]:
    """Every pose of `city_SE3_egovehicle.feather`, sorted by time -> (timestamps_ns (N,) int64,
    quaternions (N, 4) w x y z, translations (N, 3)). Raises DataError for a missing/broken
    feather, no rows, duplicated timestamps, a gap longer than 1 s or non-finite values."""
    path = _log_dir(log_dir) / POSE_FILE
    cols = ("timestamp_ns", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
    table = _read_feather(path, cols)
    try:
        arr = {c: table.column(c).to_numpy().astype(np.float64) for c in cols[1:]}
        ts_raw = table.column("timestamp_ns").to_numpy().astype(np.int64)
    except (ValueError, TypeError, pa.ArrowInvalid) as e:
        raise DataError(f"{path}: a column is not numeric ({e})") from None
    if len(ts_raw) == 0:
        raise DataError(f"{path} holds no poses")
    order = np.argsort(ts_raw, kind="stable")
    ts_ns = ts_raw[order]
    if np.any(np.diff(ts_ns) == 0):
        raise DataError(f"{path} has duplicated timestamps")
    gaps = np.diff(ts_ns) * 1e-9
    if np.any(gaps > MAX_POSE_GAP_S):
        raise DataError(
            f"{path} has a gap of {gaps.max():.3f} s between poses (> {MAX_POSE_GAP_S} s)"
        )
    quats = np.stack([arr[c][order] for c in ("qw", "qx", "qy", "qz")], axis=1)  # (N, 4)
    trans = np.stack([arr[c][order] for c in ("tx_m", "ty_m", "tz_m")], axis=1)  # (N, 3)
    if not (np.all(np.isfinite(quats)) and np.all(np.isfinite(trans))):
        raise DataError(f"{path} has non-finite poses")
    norms = np.linalg.norm(quats, axis=1)  # (N,)
    if np.any(norms < 1e-9):
        raise DataError(f"{path}: row {int(order[np.argmin(norms)])}: zero quaternion")
    return ts_ns, quats, trans


def load_av2_poses(
    log_dir: str | Path, hz: float = KEYFRAME_HZ
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Ego poses of a log subsampled to `hz` -> (timestamps (T,) seconds, poses (T, 4, 4) SE(3)
    ego->city). Raises DataError for a missing/broken feather, duplicated timestamps or a gap
    longer than 1 s between consecutive raw poses."""
    ts_ns, quats, trans = read_raw_poses(log_dir)
    idx = subsample_indices(ts_ns.astype(np.float64) * 1e-9, hz)
    poses = np.stack([se3(quats[i], trans[i]) for i in idx])  # (T, 4, 4)
    return ts_ns[idx].astype(np.float64) * 1e-9, poses


def _calibration(log_dir: Path) -> tuple[dict[str, dict], dict[str, dict]] | None:
    """Extrinsics and intrinsics rows by sensor name (None without `calibration/`)."""
    calib = log_dir / "calibration"
    if not calib.is_dir():
        return None
    ext = _read_feather(
        calib / "egovehicle_SE3_sensor.feather",
        ("sensor_name", "qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m"),
    ).to_pylist()
    intr = _read_feather(
        calib / "intrinsics.feather",
        ("sensor_name", "fx_px", "fy_px", "cx_px", "cy_px", "height_px", "width_px"),
    ).to_pylist()
    ext_by = {r["sensor_name"]: r for r in ext}
    intr_by = {r["sensor_name"]: r for r in intr}
    for cam in AV2_RING_CAMERAS:
        if cam not in ext_by or cam not in intr_by:
            raise DataError(f"calibration in {calib} lacks the camera {cam!r}")
        where = f"{calib}: camera {cam}"
        try:
            vals = [float(ext_by[cam][c]) for c in ("qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")]
            vals += [float(intr_by[cam][c]) for c in ("fx_px", "fy_px", "cx_px", "cy_px")]
            hw = (int(intr_by[cam]["height_px"]), int(intr_by[cam]["width_px"]))
        except (TypeError, ValueError) as e:
            raise DataError(f"{where}: a value is not a number ({e})") from None
        if not np.all(np.isfinite(vals)) or min(hw) < 1:
            raise DataError(f"{where}: non-finite values or a bad image size {hw}")
    return ext_by, intr_by


def _camera_to_ego(row: dict) -> NDArray[np.float64]:
    return se3(
        np.array([row["qw"], row["qx"], row["qy"], row["qz"]], dtype=np.float64),
        np.array([row["tx_m"], row["ty_m"], row["tz_m"]], dtype=np.float64),
    )


def _native_k(row: dict) -> NDArray[np.float64]:
    return np.array(
        [[row["fx_px"], 0.0, row["cx_px"]], [0.0, row["fy_px"], row["cy_px"]], [0.0, 0.0, 1.0]],
        dtype=np.float64,
    )


def load_av2_rig(log_dir: str | Path, image_size: tuple[int, int] = (128, 352)) -> CameraRig | None:
    """The seven ring cameras from `<log_dir>/calibration/` (None when the log has no
    calibration), for images rendered at `image_size` (H, W): intrinsics scaled from the native
    image per axis (fx by W / width, fy by H / height: the portrait front camera gets fx != fy;
    real images use the aspect-keeping "fit" resize instead, see `load_av2_sequence`)."""
    cal = _calibration(_log_dir(log_dir))
    if cal is None:
        return None
    ext_by, intr_by = cal
    h, w = image_size
    ks, ts = [], []
    for cam in AV2_RING_CAMERAS:
        i = intr_by[cam]
        k = _native_k(i)
        k[0] *= w / float(i["width_px"])
        k[1] *= h / float(i["height_px"])
        ks.append(k)
        ts.append(_camera_to_ego(ext_by[cam]))
    return CameraRig(AV2_RING_CAMERAS, np.asarray(ks, dtype=np.float64), np.stack(ts), (h, w))


def _sensor_stamps(folder: Path, suffix: str) -> tuple[NDArray[np.int64], list[Path]]:
    """Timestamps (sorted, ns) and paths of the `<timestamp_ns><suffix>` files of a folder."""
    if not folder.is_dir():
        raise DataError(f"sensor folder not found: {folder}")
    found = []
    for p in folder.iterdir():
        if p.name.endswith(suffix) and p.name[: -len(suffix)].isdigit():
            found.append((int(p.name[: -len(suffix)]), p))
    found.sort()
    return np.array([t for t, _ in found], dtype=np.int64), [p for _, p in found]


def load_av2_sensor_frames(
    log_dir: str | Path, image_size: tuple[int, int], hz: float = KEYFRAME_HZ
) -> tuple[NDArray[np.int64], NDArray[np.float64], list[CameraRig], list[list[Path]], list]:
    """The keyframes of a sensor log (module docstring) -> (sweep timestamps_ns (T,), poses
    (T, 4, 4) full SE(3) ego->city at the sweeps, per-keyframe rigs (7 ring cameras, cam ->
    reference ego, "fit" intrinsics for `image_size`), JPEG paths [T][7], native (h, w) [T][7])."""
    log = _log_dir(log_dir)
    cal = _calibration(log)
    if cal is None:
        raise DataError(f"sensor log {log} has no calibration/ folder")
    ext_by, intr_by = cal
    sweeps, _ = _sensor_stamps(log / "sensors" / "lidar", ".feather")
    if len(sweeps) == 0:
        raise DataError(f"no lidar sweeps (<timestamp_ns>.feather) in {log / 'sensors' / 'lidar'}")
    cams = {
        cam: _sensor_stamps(log / "sensors" / "cameras" / cam, ".jpg") for cam in AV2_RING_CAMERAS
    }
    for cam, (stamps, _) in cams.items():
        if len(stamps) == 0:
            raise DataError(f"no images in {log / 'sensors' / 'cameras' / cam}")
    keys = sweeps[subsample_indices(sweeps.astype(np.float64) * 1e-9, hz)]  # (T,) ns
    ts_ns, quats, trans = read_raw_poses(log)
    native = [(int(intr_by[c]["height_px"]), int(intr_by[c]["width_px"])) for c in AV2_RING_CAMERAS]
    ks = np.stack(
        [
            fit_intrinsics(_native_k(intr_by[c]), hw, image_size)
            for c, hw in zip(AV2_RING_CAMERAS, native, strict=True)
        ]
    )  # fmt: skip  (7, 3, 3)
    ego_cam = np.stack([_camera_to_ego(ext_by[c]) for c in AV2_RING_CAMERAS])  # (7, 4, 4)
    kept, files, img_ns = [], [], []
    for sweep in keys:
        row, ok = [], []
        for cam in AV2_RING_CAMERAS:
            stamps, paths = cams[cam]
            j = int(np.argmin(np.abs(stamps - sweep)))
            if abs(int(stamps[j]) - int(sweep)) > CAMERA_TOLERANCE_NS:
                warnings.warn(
                    f"{log.name}: sweep {sweep}.feather skipped: {cam} has no image within "
                    f"{CAMERA_TOLERANCE_NS / 1e6:g} ms (nearest {stamps[j]}.jpg)",
                    stacklevel=2,
                )
                break
            row.append(paths[j])
            ok.append(int(stamps[j]))
        else:
            kept.append(int(sweep))
            files.append(row)
            img_ns.append(ok)
    if not kept:
        raise DataError(f"sensor log {log}: no keyframe has all ring cameras within tolerance")
    where = log / POSE_FILE
    ref = interpolate_poses(ts_ns, quats, trans, np.array(kept, np.int64), str(where))  # (T,4,4)
    cam_poses = interpolate_poses(
        ts_ns, quats, trans, np.array(img_ns, np.int64).reshape(-1), str(where)
    ).reshape(len(kept), len(AV2_RING_CAMERAS), 4, 4)  # (T, 7, 4, 4) ego->city at each image
    rigs = []
    for t in range(len(kept)):
        c2e = np.linalg.inv(ref[t])[None] @ cam_poses[t] @ ego_cam  # (7, 4, 4) cam -> ref ego
        rigs.append(CameraRig(AV2_RING_CAMERAS, ks.copy(), c2e, tuple(image_size)))  # type: ignore[arg-type]
    return (
        np.array(kept, np.int64),
        ref,
        rigs,
        files,
        [list(native) for _ in kept],
    )


def _rig(log: Path, rig: str, image_size: tuple[int, int]) -> CameraRig:
    if rig == "nuscenes":
        from icmapper.data import sim

        return sim.nuscenes_rig(image_size)
    if rig == "av2":
        r = load_av2_rig(log, image_size)
        if r is None:
            raise DataError(f"rig='av2' asked but {log / 'calibration'} does not exist")
        return r
    raise ValueError(f"rig must be 'nuscenes' or 'av2', got {rig!r}")


def load_av2_sequence(
    log_dir: str | Path,
    image_size: tuple[int, int] = (128, 352),
    rig: str = "nuscenes",
    render: bool = True,
    seed: int = 0,
    images: str = "auto",
) -> Sequence:
    """The log's own drive as a Sequence at 2 Hz over its real map.

    images: "real" (a sensor log: the 7 ring cameras' JPEGs, full SE(3) poses, per-keyframe
    rigs; see the module docstring), "render" or "auto" (real when `<log>/sensors/cameras/`
    exists). Rendered sequences have planar poses (x, y, yaw; z = 0) because the images are
    rendered on a flat ground with `sim.Renderer`; `rig`: "nuscenes" (the simulator's 6-camera
    rig) or "av2" (the log's 7 ring cameras, needs calibration). `render=False` gives a sequence
    without images (real sensor logs keep their geometry; JPEGs are not checked).
    """
    log = _log_dir(log_dir)
    real = resolve_images(images, (log / "sensors" / "cameras").is_dir(), log / "sensors")
    world = load_av2_world(log)
    if real:
        stamps, poses, rigs, files, native = load_av2_sensor_frames(log, image_size)
        loader = RealImages(files, native, image_size) if render else None
        if loader is not None:
            loader.check()
        return Sequence(
            log.name,
            "av2",
            world,
            stamps.astype(np.float64) * 1e-9,
            poses,
            rigs[0],
            loader,
            False,
            rigs,
            "real" if render else "none",
        )
    timestamps, poses = load_av2_poses(log)
    flat = np.stack([planar(p) for p in poses])  # (T, 4, 4)
    cams = _rig(log, rig, image_size)
    renderer = LazyRenderer(world, cams, flat, seed) if render else None
    return Sequence(log.name, "av2", world, timestamps, flat, cams, renderer)


def av2_drives(
    log_dir: str | Path,
    num: int,
    seed: int = 0,
    image_size: tuple[int, int] = (128, 352),
    duration_s: float | None = None,
    render: bool = True,
) -> list[Sequence]:
    """`num` synthetic drives along the real lane graph of a log (sim.drive on the real world
    map, nuScenes-like rig, rendered images); drive k is named `<log_id>-drive<k>`."""
    from icmapper.data import sim

    if num < 0:
        raise ValueError(f"num must be >= 0, got {num}")
    log = _log_dir(log_dir)
    world = load_av2_world(log)
    rig = sim.nuscenes_rig(image_size)
    seeds = np.random.SeedSequence([int(seed), 2]).generate_state(max(num, 1))
    out = []
    for k in range(num):
        timestamps, poses = sim.drive(world, int(seeds[k]), duration_s=duration_s)
        poses = np.asarray(poses, dtype=np.float64)
        renderer = LazyRenderer(world, rig, poses, int(seeds[k])) if render else None
        out.append(
            Sequence(
                f"{log.name}-drive{k}",
                "av2",
                world,
                np.asarray(timestamps, dtype=np.float64),
                poses,
                rig,
                renderer,
            )
        )
    return out


def find_av2_logs(path: str | Path) -> list[Path]:
    """A log directory itself (it has `map/`) or the sorted log directories inside a folder."""
    p = Path(path)
    if not p.is_dir():
        raise DataError(f"Argoverse 2 path not found: {p}")
    if (p / "map").is_dir():
        return [p]
    logs = sorted(d for d in p.iterdir() if d.is_dir() and (d / "map").is_dir())
    if not logs:
        raise DataError(f"{p} is neither an Argoverse 2 log (no map/) nor a folder of logs")
    return logs
