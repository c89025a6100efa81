"""Vehicles of a rendered world: where they are (parked at kerbs, driving along lanes) and how
they are drawn into the camera images (ray/box intersection with a depth test, and a shadow).

``make_vehicles`` draws them from the renderer's random stream once; ``draw_vehicles`` draws the
ones near the ego into a frame's images in place. No I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray

from icmapper.data.sim.geometry import arc_length, resample_by_length
from icmapper.data.sim.rays import RigRays
from icmapper.data.types import CameraRig, MapClass, WorldMap


@dataclass
class Vehicles:
    """Boxes: centre (n, 2) world, yaw (n,), size (n, 3) length/width/height, colour (n, 3) and, for
    moving ones, the lane polyline they follow with start arc length and speed."""

    centre: NDArray[np.float64]
    yaw: NDArray[np.float64]
    size: NDArray[np.float64]
    colour: NDArray[np.float32]
    lanes: list[NDArray[np.float64] | None]
    s0: NDArray[np.float64]
    speed: NDArray[np.float64]


def no_vehicles() -> Vehicles:
    """No vehicles (a world rendered without traffic)."""
    z = np.zeros((0,), np.float64)
    return Vehicles(np.zeros((0, 2)), z, np.zeros((0, 3)), np.zeros((0, 3), np.float32), [], z, z)


def make_vehicles(world: WorldMap, rng: np.random.Generator) -> Vehicles:
    """Parked vehicles along kerbs (on the drivable side) and vehicles driving along lanes."""
    centres, yaws, sizes, cols, lanes, s0, speed = [], [], [], [], [], [], []
    drivable = [shapely.Polygon(p) for p in world.drivable if len(p) >= 3]
    area = (
        shapely.union_all([p if p.is_valid else p.buffer(0) for p in drivable])
        if drivable
        else None
    )

    def car(
        centre: NDArray, yaw: float, lane: NDArray | None = None, s: float = 0.0, v: float = 0.0
    ) -> None:
        kind = rng.random()
        size = [rng.uniform(4.2, 5.0), rng.uniform(1.75, 1.95), rng.uniform(1.4, 1.7)]
        if kind > 0.85:  # vans / trucks
            size = [rng.uniform(5.5, 8.0), rng.uniform(2.1, 2.5), rng.uniform(2.3, 3.2)]
        centres.append(centre)
        yaws.append(yaw)
        sizes.append(size)
        grey = rng.uniform(30, 220)
        base = np.array([grey, grey, grey]) if rng.random() < 0.6 else rng.uniform(30, 200, size=3)
        cols.append(base)
        lanes.append(lane)
        s0.append(s)
        speed.append(v)

    if area is not None:
        for m in world.instances:
            if m.cls != MapClass.BOUNDARY or len(m.points) < 2:
                continue
            pts = np.asarray(m.points, np.float64)
            total = float(arc_length(pts)[-1])
            for s in np.sort(rng.uniform(0, total, size=int(rng.poisson(total / 45.0)))):
                p, q = resample_by_length(pts, np.array([s, min(s + 0.5, total)]))
                t = q - p
                if np.linalg.norm(t) < 1e-6:
                    continue
                t /= np.linalg.norm(t)
                nrm = np.array([-t[1], t[0]])
                for side in (1.0, -1.0):
                    cand = p + side * 1.15 * nrm
                    if area.contains(shapely.Point(cand)) and area.contains(
                        shapely.Point(p + side * 3.0 * nrm)
                    ):
                        car(cand, float(np.arctan2(t[1], t[0])))
                        break
    lane_list = [np.asarray(lane.centerline, np.float64) for _, lane in sorted(world.lanes.items())]
    lane_list = [
        cl for cl in lane_list if cl.ndim == 2 and len(cl) >= 2 and arc_length(cl)[-1] > 30.0
    ]
    for k in rng.permutation(len(lane_list))[: max(1, len(lane_list) // 6)] if lane_list else []:
        cl = lane_list[int(k)]
        car(
            cl[0], 0.0, cl, float(rng.uniform(0, arc_length(cl)[-1])), float(rng.uniform(4.0, 12.0))
        )
    n = len(centres)
    return Vehicles(
        np.array(centres, np.float64).reshape(n, 2),
        np.array(yaws, np.float64).reshape(n),
        np.array(sizes, np.float64).reshape(n, 3),
        np.array(cols, np.float32).reshape(n, 3),
        lanes,
        np.array(s0, np.float64).reshape(n),
        np.array(speed, np.float64).reshape(n),
    )


def draw_vehicles(
    img: NDArray[np.float32],
    veh: Vehicles,
    rig: CameraRig,
    rays: RigRays,
    x: float,
    y: float,
    yaw: float,
    t: float,
) -> None:
    """Ray/box intersection of the vehicles near the ego at (x, y, yaw) at time ``t`` into img
    (C, H, W, 3) of the cameras of ``rig`` (their cast ``rays``) in place, with shadows."""
    if veh.centre.shape[0] == 0:
        return
    centre, vyaw = veh.centre.copy(), veh.yaw.copy()
    for i, lane in enumerate(veh.lanes):
        if lane is not None:
            length = float(arc_length(lane)[-1])
            s = (veh.s0[i] + veh.speed[i] * t) % length
            p = resample_by_length(lane, np.array([s, min(s + 1.0, length)]))
            centre[i] = p[0]
            if np.linalg.norm(p[1] - p[0]) > 1e-6:
                vyaw[i] = np.arctan2(p[1, 1] - p[0, 1], p[1, 0] - p[0, 0])
    c, s_ = np.cos(yaw), np.sin(yaw)
    rel = centre - np.array([x, y])  # (n, 2)
    ego_xy = np.stack(
        [c * rel[:, 0] + s_ * rel[:, 1], -s_ * rel[:, 0] + c * rel[:, 1]], axis=1
    )  # (n, 2)
    dist = np.linalg.norm(ego_xy, axis=1)
    near = np.flatnonzero((dist > 7.0) & (dist < 70.0))
    h, w = rig.image_size
    ego_to_cam = np.linalg.inv(rig.cam_to_ego)  # (C, 4, 4)
    for i in near[np.argsort(-dist[near])]:
        byaw = vyaw[i] - yaw
        cb, sb = np.cos(byaw), np.sin(byaw)
        rot = np.array([[cb, -sb, 0.0], [sb, cb, 0.0], [0.0, 0.0, 1.0]])  # box -> ego
        ln, wd, ht = veh.size[i]
        corners = np.array(
            [
                [sx * (ln / 2 + 0.3), sy * (wd / 2 + 0.3), z]
                for sx in (-1, 1)
                for sy in (-1, 1)
                for z in (0.0, ht)
            ]
        )  # (8, 3) box frame (with the shadow margin)
        pts = corners @ rot.T + np.array([ego_xy[i, 0], ego_xy[i, 1], 0.0])  # (8, 3) ego
        cam = (
            np.einsum("cij,nj->cni", ego_to_cam[:, :3, :3], pts) + ego_to_cam[:, None, :3, 3]
        )  # (C, 8, 3)
        for ci in range(rig.num_cameras):
            vis = _near_clipped(cam[ci])  # (m, 3) corners / edge cuts in front of the camera
            if vis.shape[0] == 0:
                continue
            uv = vis @ rig.intrinsics[ci].T
            uv = uv[:, :2] / uv[:, 2:3]
            u0, v0 = np.maximum(np.floor(uv.min(axis=0)).astype(int), 0)
            u1, v1 = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + 1, [w, h])
            if u0 >= u1 or v0 >= v1:
                continue
            _box_pass(
                rays,
                img[ci, v0:v1, u0:u1],
                ci,
                (v0, v1, u0, u1),
                rot,
                ego_xy[i],
                veh.size[i],
                veh.colour[i],
            )


def _box_pass(
    rays: RigRays,
    tile: NDArray[np.float32],
    ci: int,
    win: tuple[int, int, int, int],
    rot: NDArray,
    centre: NDArray,
    size: NDArray,
    colour: NDArray,
) -> None:
    """Shadow and body of one box in one camera window `tile` (h, w, 3), in place."""
    v0, v1, u0, u1 = win
    ln, wd, ht = (float(v) for v in size)
    c, s = np.float32(rot[0, 0]), np.float32(rot[1, 0])
    # Shadow on the ground hits inside the (slightly enlarged) footprint.
    hit = rays.hit_full[ci, v0:v1, u0:u1]  # (h, w, 2) ego frame
    gx0 = hit[..., 0] - np.float32(centre[0])
    gy0 = hit[..., 1] - np.float32(centre[1])
    depth = rays.depth[ci, v0:v1, u0:u1]  # (h, w), inf off the ground
    shadow = (np.abs(c * gx0 + s * gy0) < ln / 2 + 0.25) & (
        np.abs(-s * gx0 + c * gy0) < wd / 2 + 0.25
    )
    shadow &= depth < np.inf
    tile[shadow] *= 0.45
    # Body: slab test in the box frame (rays rotated by rot^T).
    dxe, dye, dz = (
        rays.dir_planes[ci, 0, v0:v1, u0:u1],
        rays.dir_planes[ci, 1, v0:v1, u0:u1],
        rays.dir_planes[ci, 2, v0:v1, u0:u1],
    )
    dx = c * dxe + s * dye  # (h, w)
    dy = -s * dxe + c * dye
    o = (rays.origins[ci] - np.array([centre[0], centre[1], 0.0])) @ rot  # (3,) box frame
    with np.errstate(divide="ignore", invalid="ignore"):
        tx1, tx2 = (-ln / 2 - o[0]) / dx, (ln / 2 - o[0]) / dx
        ty1, ty2 = (-wd / 2 - o[1]) / dy, (wd / 2 - o[1]) / dy
        tz1, tz2 = (0.0 - o[2]) / dz, (ht - o[2]) / dz
    nx, ny, nz = np.minimum(tx1, tx2), np.minimum(ty1, ty2), np.minimum(tz1, tz2)
    tnear = np.maximum(np.maximum(nx, ny), nz)  # (h, w)
    tfar = np.minimum(np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2)), np.maximum(tz1, tz2))
    body = (tnear < tfar) & (tnear > 0) & (tnear < depth)
    if not np.any(body):
        return
    tn = tnear[body]
    shade = np.where(tn == nz[body], 1.12, np.where(tn == ny[body], 0.9, 0.72)).astype(
        np.float32
    )  # (k,)
    zhit = o[2] + tn * dz[body]  # (k,) hit height
    col = colour[None, :] * shade[:, None]  # (k, 3)
    glass = (tn != nz[body]) & (zhit > 0.55 * ht) & (zhit < 0.93 * ht)
    col[glass] = np.array([38, 46, 56], np.float32)
    col[zhit < 0.3] *= 0.35
    tile[body] = col


_BOX_EDGES = np.array(
    [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
)  # the 12 edges of a box whose corners are ordered (sx, sy, z) as in draw_vehicles


def _near_clipped(cam: NDArray, near: float = 0.1) -> NDArray[np.float64]:
    """Corners (8, 3) of a box in camera coordinates clipped to z >= near: the corners in front
    plus the points where edges cross the near plane. Returns (m, 3)."""
    z = cam[:, 2]
    front = cam[z >= near]
    if front.shape[0] == 8 or front.shape[0] == 0:
        return front
    a, b = cam[_BOX_EDGES[:, 0]], cam[_BOX_EDGES[:, 1]]  # (12, 3)
    za, zb = a[:, 2], b[:, 2]
    cross = (za - near) * (zb - near) < 0
    t = (near - za[cross]) / (zb[cross] - za[cross])
    cuts = a[cross] + t[:, None] * (b[cross] - a[cross])
    return np.concatenate([front, cuts])
