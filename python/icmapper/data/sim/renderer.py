"""Camera images of a WorldMap by ray-casting the ground plane onto a painted world raster.

How it works (all vectorised numpy, no per-pixel Python):
- Once per rig (shared by the renderers of the same rig): every camera pixel's ray is cast from
  its mount onto the ego's ground plane (z = 0 in the ego frame; roll, pitch and height of the pose
  are ignored), giving a fixed ego-frame hit point, depth and haze weight per pixel; rays above the
  horizon (or hitting beyond 250 m) see sky / haze. A renderer's own arrays of camera size (sensor
  grain, sky colours) and its vehicles are drawn on its first frame, so opening many drives is
  cheap.
- Once per world, lazily on the first frame: the world is painted into a label raster (0.1 m per
  pixel): grass, sidewalk, kerb, asphalt, white and yellow paint. Drivable polygons are asphalt;
  boundaries are kerbs with a sidewalk band behind; dividers are painted by style (solid, dashed
  3 m / 6 m, double lines, 0.15 m wide); crossings get zebra bars. A few rasters stay in memory at
  once (least recently used ones are dropped and rebuilt on demand).
- Per frame: the fixed hit points are moved by the pose (x, y, yaw), labels gathered (nearest),
  coloured with a per-world palette and a tiled noise texture, hazed with distance; vehicles
  (parked at kerbs and moving along lanes, seeded) are ray/box intersected inside their projected
  rectangles with a depth test and cast a shadow; then exposure, white balance, blur and sensor
  noise drawn from the frame seed.

No I/O here. Output (C, 3, H, W) uint8.
"""

from __future__ import annotations

import copy
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import NDArray
from PIL import Image, ImageDraw
from shapely.geometry import Polygon

from icmapper.data.sim.geometry import arc_length, offset_curve, resample_by_length, sub_curve
from icmapper.data.types import CameraRig, MapClass, WorldMap, pose_to_xy_yaw

# Raster labels.
GRASS, SIDEWALK, KERB, ASPHALT, WHITE, YELLOW = range(6)
_NUM_LABELS = 6
_MAX_DEPTH = 250.0  # m; ground hits beyond are haze
_KEEP_RASTERS = 8  # rasters kept in memory across renderers (least recently used dropped)
_NOISE = 512  # side of the tiled noise texture (raster pixels)
_MARGIN = 60.0  # m of grass around the world in the raster

_built: OrderedDict[int, weakref.ref[Renderer]] = OrderedDict()


@dataclass
class _Raster:
    labels: NDArray[np.uint8]  # (Hr, Wr) label per pixel; row = y, column = x
    x0: float
    y0: float
    res: float  # metres per pixel


@dataclass
class _Vehicles:
    """Boxes: centre (n, 2) world, yaw (n,), size (n, 3) length/width/height, colour (n, 3) and, for
    moving ones, the lane polyline they follow with start arc length and speed."""

    centre: NDArray[np.float64]
    yaw: NDArray[np.float64]
    size: NDArray[np.float64]
    colour: NDArray[np.float32]
    lanes: list[NDArray[np.float64] | None]
    s0: NDArray[np.float64]
    speed: NDArray[np.float64]


@dataclass
class _Heavy:
    """A renderer's arrays of camera size, built on its first frame (dropped with its raster)."""

    grain: NDArray[np.float32]  # (2*C*3*H*W,) sensor noise drawn once, read at a random offset
    vehicles: _Vehicles
    sky: NDArray[np.float32]  # (C, H, W, 3) horizon-to-zenith colour per pixel


@dataclass(frozen=True)
class _RigRays:
    """Every pixel's ray of a rig cast onto the ego's ground plane (shared by the renderers of
    the same rig: every synthetic drive has the same one)."""

    dir_planes: NDArray[np.float32]  # (C, 3, H, W) ray directions, ego frame
    origins: NDArray[np.float64]  # (C, 3) camera centres, ego frame
    depth: NDArray[np.float32]  # (C, H, W) ray parameter of the ground hit, inf off the ground
    hit_full: NDArray[np.float32]  # (C, H, W, 2) ground hit, ego frame
    ground_flat: NDArray[np.int64]  # (N,) pixels that see the ground, into C*H*W
    hit: NDArray[np.float32]  # (N, 2) their ground hits
    fog: NDArray[np.float32]  # (N, 1) haze weight with distance
    sky_weight: NDArray[np.float64]  # (C, H, W, 1) zenith share of the sky colour


_KEEP_RIGS = 4  # rigs whose rays are kept (least recently used dropped)
_rays_cache: OrderedDict[bytes, _RigRays] = OrderedDict()


def _rays_for(rig: CameraRig) -> _RigRays:
    """The cast rays of ``rig``, from the cache when a rig of the same geometry was seen."""
    key = (
        np.asarray(rig.image_size, np.int64).tobytes()
        + np.asarray(rig.intrinsics, np.float64).tobytes()
        + np.asarray(rig.cam_to_ego, np.float64).tobytes()
    )
    rays = _rays_cache.get(key)
    if rays is None:
        rays = _cast_rays(rig)
        _rays_cache[key] = rays
        while len(_rays_cache) > _KEEP_RIGS:
            _rays_cache.popitem(last=False)
    _rays_cache.move_to_end(key)
    return rays


def _cast_rays(rig: CameraRig) -> _RigRays:
    h, w = rig.image_size
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)  # (H, W) each
    pix = np.stack([u, v, np.ones_like(u)], axis=-1)  # (H, W, 3)
    k_inv = np.linalg.inv(rig.intrinsics)  # (C, 3, 3)
    d_cam = np.einsum("cij,hwj->chwi", k_inv, pix)  # (C, H, W, 3)
    d = np.einsum("cij,chwj->chwi", rig.cam_to_ego[:, :3, :3], d_cam)  # (C, H, W, 3) ego frame
    o = rig.cam_to_ego[:, :3, 3]  # (C, 3)
    if np.any(o[:, 2] <= 0):
        raise ValueError("every camera must be mounted above the ground (cam_to_ego z > 0)")
    dz = d[..., 2]  # (C, H, W)
    down = dz < -1e-6
    lam = np.where(down, -o[:, 2, None, None] / np.where(down, dz, -1.0), np.inf)  # (C, H, W)
    dist = lam * np.linalg.norm(d, axis=-1)  # (C, H, W)
    ground = dist < _MAX_DEPTH
    hit = o[:, None, None, :2] + np.where(ground, lam, 0.0)[..., None] * d[..., :2]  # (C,H,W,2)
    ground_flat = np.flatnonzero(ground)  # (N,) into C*H*W
    fog = 1.0 - np.exp(-dist.reshape(-1)[ground_flat] / 160.0)  # (N,)
    elev = dz / np.linalg.norm(d, axis=-1)  # (C, H, W) sine of elevation
    return _RigRays(
        dir_planes=np.ascontiguousarray(d.transpose(0, 3, 1, 2)).astype(np.float32),
        origins=o,
        depth=np.where(ground, lam, np.inf).astype(np.float32),
        hit_full=hit.astype(np.float32),
        ground_flat=ground_flat,
        hit=hit.reshape(-1, 2)[ground_flat].astype(np.float32),
        fog=fog.astype(np.float32)[:, None],
        sky_weight=np.clip(elev * 3.0, 0.0, 1.0)[..., None],
    )


class Renderer:
    """Renders the cameras of `rig` in `world` (see the module docstring).

    world: any WorldMap (drivable polygons, instances with classes/styles, optional lane graph for
    vehicles). rig: the CameraRig (intrinsics (C, 3, 3), cam_to_ego (C, 4, 4), image_size (H, W)).
    seed: palette, vehicles and the default frame seed. resolution: raster metres per pixel (it is
    coarsened for very large worlds so that the raster stays below `max_raster_pixels`).
    vehicles: False renders the world without vehicles (test fixtures).
    """

    def __init__(
        self,
        world: WorldMap,
        rig: CameraRig,
        seed: int = 0,
        resolution: float = 0.1,
        max_raster_pixels: int = 36_000_000,
        vehicles: bool = True,
    ) -> None:
        if not isinstance(world, WorldMap):
            raise TypeError(f"world must be a WorldMap, got {type(world).__name__}")
        if not isinstance(rig, CameraRig):
            raise TypeError(f"rig must be a CameraRig, got {type(rig).__name__}")
        if not (resolution > 0 and np.isfinite(resolution)):
            raise ValueError(f"resolution must be positive, got {resolution}")
        n_cam = rig.num_cameras
        if rig.intrinsics.shape != (n_cam, 3, 3) or rig.cam_to_ego.shape != (n_cam, 4, 4):
            raise ValueError("rig intrinsics must be (C, 3, 3) and cam_to_ego (C, 4, 4)")
        self.world, self.rig, self.seed = world, rig, int(seed)
        self.resolution, self.max_raster_pixels = float(resolution), int(max_raster_pixels)
        rng = np.random.default_rng([self.seed, 0x0E17])
        self._palette(rng)
        self._rays = _rays_for(rig)
        self._noise = _value_noise(rng, _NOISE)  # (N, N) float32 in about [-1, 1]
        # The grain, the vehicles and the sky are drawn on the first frame from this point of the
        # renderer's random stream (opening thousands of drives stays cheap; see _ensure_heavy).
        self._tail_state = rng.bit_generator.state
        self._with_vehicles = bool(vehicles)
        self._grain_seed: list[int] | None = None  # another rig's grain stream (with_rig)
        self._heavy: _Heavy | None = None
        self._raster: _Raster | None = None

    def with_rig(self, rig: CameraRig) -> Renderer:
        """A renderer of the same world (its raster shared, painted once), palette, texture and
        vehicles for other cameras: test fixtures render each camera of each frame through its
        own geometry without repainting the world."""
        if not isinstance(rig, CameraRig):
            raise TypeError(f"rig must be a CameraRig, got {type(rig).__name__}")
        other = copy.copy(self)
        other.rig = rig
        other._rays = _rays_for(rig)
        other._grain_seed = [self.seed, 0x6A]
        other._heavy = None
        other._raster = self._ensure_raster()
        return other

    # ------------------------------------------------------------------ setup
    def _palette(self, rng: np.random.Generator) -> None:
        lut = np.array(
            [
                [86, 108, 60],  # grass
                [158, 155, 147],  # sidewalk
                [196, 194, 186],  # kerb
                [74, 74, 78],  # asphalt
                [226, 226, 220],  # white paint
                [222, 178, 58],  # yellow paint
            ],
            dtype=np.float32,
        )
        lut[ASPHALT] += rng.uniform(-14, 22)
        lut[SIDEWALK] += rng.uniform(-20, 20)
        lut[GRASS] *= rng.uniform(0.8, 1.2, size=3).astype(np.float32)
        self._lut = lut  # (L, 3)
        self._amp = np.array([0.30, 0.10, 0.06, 0.16, 0.08, 0.08], dtype=np.float32)  # (L,)
        sky_blue = rng.uniform(0.0, 1.0)
        self._horizon = np.array([205, 212, 220], dtype=np.float32)
        self._zenith = (1 - sky_blue) * np.array([180, 186, 196], np.float32) + sky_blue * np.array(
            [95, 140, 205], np.float32
        )

    # ----------------------------------------------------------------- raster
    def _ensure_raster(self) -> _Raster:
        if self._raster is None:
            self._raster = _paint_world(
                self.world, self.resolution, self.max_raster_pixels, self.seed
            )
        self._touch()
        return self._raster

    def _ensure_heavy(self) -> _Heavy:
        """The grain, vehicles and sky of this renderer, drawn from its random stream where
        ``__init__`` left it (the same arrays whenever they are rebuilt)."""
        if self._heavy is None:
            rng = np.random.default_rng()
            rng.bit_generator.state = self._tail_state
            h, w = self.rig.image_size
            n = 2 * self.rig.num_cameras * 3 * h * w
            # drawn even for a with_rig copy: the vehicles come after it in the stream
            grain = rng.standard_normal(n).astype(np.float32)  # (n,)
            vehicles = _make_vehicles(self.world, rng) if self._with_vehicles else _no_vehicles()
            if self._grain_seed is not None:
                grain = np.random.default_rng(self._grain_seed).standard_normal(n)
                grain = grain.astype(np.float32)
            a = self._rays.sky_weight  # (C, H, W, 1)
            sky = ((1 - a) * self._horizon + a * self._zenith).astype(np.float32)  # (C, H, W, 3)
            self._heavy = _Heavy(grain, vehicles, sky)
        self._touch()
        return self._heavy

    def _touch(self) -> None:
        """Marks this renderer as used: the raster and per-renderer arrays of the renderers least
        recently used beyond ``_KEEP_RASTERS`` are dropped (rebuilt on demand)."""
        key = id(self)
        if key in _built and _built[key]() is self:
            _built.move_to_end(key)
            return
        _built[key] = weakref.ref(self)
        while len(_built) > _KEEP_RASTERS:
            _, ref = _built.popitem(last=False)
            other = ref()
            if other is not None and other is not self:
                other._raster = None
                other._heavy = None

    # ----------------------------------------------------------------- render
    def render(
        self, pose: NDArray[np.float64], frame_seed: int | None = None, t: float = 0.0
    ) -> NDArray[np.uint8]:
        """Images of all cameras for the ego at `pose` ((4, 4) ego->world).

        frame_seed: exposure, blur and noise of this frame (None: derived from the renderer seed);
        the same (pose, frame_seed, t) always gives the same images. t: time in seconds, moves the
        driving vehicles. Returns (C, 3, H, W) uint8.
        """
        x, y, yaw = pose_to_xy_yaw(pose)
        if not np.isfinite(t):
            raise ValueError(f"t must be finite, got {t}")
        r = self._ensure_raster()
        heavy, rays = self._ensure_heavy(), self._rays
        rig = self.rig
        c, (h, w) = rig.num_cameras, rig.image_size
        img = heavy.sky.copy().reshape(-1, 3)  # (C*H*W, 3)

        # Ground: move the fixed ego-frame hits into the raster, gather labels, colour.
        cy, sy = np.float32(np.cos(yaw)), np.float32(np.sin(yaw))
        inv = np.float32(1.0 / r.res)
        hx, hy = rays.hit[:, 0], rays.hit[:, 1]  # (N,)
        # +0.5: the painter puts coordinate k at the centre of raster pixel k (nearest pixel).
        col_f = (cy * hx - sy * hy + np.float32(x - r.x0 + 0.5 * r.res)) * inv  # (N,) raster column
        row_f = (sy * hx + cy * hy + np.float32(y - r.y0 + 0.5 * r.res)) * inv  # (N,) raster row
        ix = np.floor(col_f).astype(np.int32)
        iy = np.floor(row_f).astype(np.int32)
        hr, wr = r.labels.shape
        outside = (ix < 0) | (ix >= wr) | (iy < 0) | (iy >= hr)
        np.clip(ix, 0, wr - 1, out=ix)
        np.clip(iy, 0, hr - 1, out=iy)
        lab = r.labels[iy, ix]  # (N,)
        lab[outside] = GRASS
        tex = self._noise[iy & (_NOISE - 1), ix & (_NOISE - 1)]  # (N,)
        shade = 1.0 + self._amp[lab] * tex  # (N,)
        col = self._lut[lab] * shade[:, None]  # (N, 3)
        col += rays.fog * (self._horizon - col)  # haze with distance
        img[rays.ground_flat] = col
        img = img.reshape(c, h, w, 3)

        self._draw_vehicles(img, heavy.vehicles, x, y, yaw, t)

        # Camera effects: exposure / white balance, blur, sensor noise.
        rng = np.random.default_rng(
            [self.seed, 0 if frame_seed is None else int(frame_seed) + 1, 0xF2]
        )
        gain = np.exp(rng.normal(0.0, 0.12)) * np.exp(
            rng.normal(0.0, 0.04, size=(c, 1, 1, 1))
        )  # (C,1,1,1)
        gain = gain * np.exp(rng.normal(0.0, 0.03, size=(1, 1, 1, 3)))  # (C, 1, 1, 3)
        img *= gain.astype(np.float32)
        a = np.float32(rng.uniform(0.1, 0.6))
        img[:, :, 1:-1] = (1 - a) * img[:, :, 1:-1] + (a / 2) * (img[:, :, :-2] + img[:, :, 2:])
        b = np.float32(rng.uniform(0.0, 0.4))
        img[:, 1:-1] = (1 - b) * img[:, 1:-1] + (b / 2) * (img[:, :-2] + img[:, 2:])
        n = img.size
        off = int(rng.integers(0, heavy.grain.size - n))
        img += np.float32(rng.uniform(1.5, 5.0)) * heavy.grain[off : off + n].reshape(img.shape)
        out = np.clip(img, 0.0, 255.0).astype(np.uint8)  # (C, H, W, 3)
        return np.ascontiguousarray(out.transpose(0, 3, 1, 2))  # (C, 3, H, W)

    def _draw_vehicles(
        self,
        img: NDArray[np.float32],
        veh: _Vehicles,
        x: float,
        y: float,
        yaw: float,
        t: float,
    ) -> None:
        """Ray/box intersection of nearby vehicles into img (C, H, W, 3) in place, with shadows."""
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
        h, w = self.rig.image_size
        ego_to_cam = np.linalg.inv(self.rig.cam_to_ego)  # (C, 4, 4)
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
            for ci in range(self.rig.num_cameras):
                vis = _near_clipped(cam[ci])  # (m, 3) corners / edge cuts in front of the camera
                if vis.shape[0] == 0:
                    continue
                uv = vis @ self.rig.intrinsics[ci].T
                uv = uv[:, :2] / uv[:, 2:3]
                u0, v0 = np.maximum(np.floor(uv.min(axis=0)).astype(int), 0)
                u1, v1 = np.minimum(np.ceil(uv.max(axis=0)).astype(int) + 1, [w, h])
                if u0 >= u1 or v0 >= v1:
                    continue
                self._box_pass(
                    img[ci, v0:v1, u0:u1],
                    ci,
                    (v0, v1, u0, u1),
                    rot,
                    ego_xy[i],
                    veh.size[i],
                    veh.colour[i],
                )

    def _box_pass(
        self,
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
        hit = self._rays.hit_full[ci, v0:v1, u0:u1]  # (h, w, 2) ego frame
        gx0 = hit[..., 0] - np.float32(centre[0])
        gy0 = hit[..., 1] - np.float32(centre[1])
        depth = self._rays.depth[ci, v0:v1, u0:u1]  # (h, w), inf off the ground
        shadow = (np.abs(c * gx0 + s * gy0) < ln / 2 + 0.25) & (
            np.abs(-s * gx0 + c * gy0) < wd / 2 + 0.25
        )
        shadow &= depth < np.inf
        tile[shadow] *= 0.45
        # Body: slab test in the box frame (rays rotated by rot^T).
        dxe, dye, dz = (
            self._rays.dir_planes[ci, 0, v0:v1, u0:u1],
            self._rays.dir_planes[ci, 1, v0:v1, u0:u1],
            self._rays.dir_planes[ci, 2, v0:v1, u0:u1],
        )
        dx = c * dxe + s * dye  # (h, w)
        dy = -s * dxe + c * dye
        o = (self._rays.origins[ci] - np.array([centre[0], centre[1], 0.0])) @ rot  # (3,) box frame
        with np.errstate(divide="ignore", invalid="ignore"):
            tx1, tx2 = (-ln / 2 - o[0]) / dx, (ln / 2 - o[0]) / dx
            ty1, ty2 = (-wd / 2 - o[1]) / dy, (wd / 2 - o[1]) / dy
            tz1, tz2 = (0.0 - o[2]) / dz, (ht - o[2]) / dz
        nx, ny, nz = np.minimum(tx1, tx2), np.minimum(ty1, ty2), np.minimum(tz1, tz2)
        tnear = np.maximum(np.maximum(nx, ny), nz)  # (h, w)
        tfar = np.minimum(
            np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2)), np.maximum(tz1, tz2)
        )
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
)  # the 12 edges of a box whose corners are ordered (sx, sy, z) as in _draw_vehicles


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


def _value_noise(rng: np.random.Generator, n: int) -> NDArray[np.float32]:
    """Tileable multi-octave value noise (n, n) float32, roughly in [-1, 1]."""
    out = np.zeros((n, n), np.float32)
    for cells, weight in ((4, 0.5), (16, 0.3), (64, 0.25), (n, 0.35)):
        grid = rng.uniform(-1, 1, size=(cells, cells)).astype(np.float32)
        rep = n // cells
        up = np.repeat(np.repeat(grid, rep, axis=0), rep, axis=1)
        # smooth the blocks with a tileable box blur of the block size
        if rep > 1:
            k = rep
            for ax in (0, 1):
                cs = np.cumsum(
                    np.concatenate([up, up.take(np.arange(k), axis=ax)], axis=ax), axis=ax
                )
                up = (cs.take(np.arange(k, n + k), axis=ax) - cs.take(np.arange(0, n), axis=ax)) / k
        out += weight * up
    return out / np.abs(out).max()


def _world_points(world: WorldMap) -> NDArray[np.float64]:
    pts = [m.points for m in world.instances if len(m.points)]
    pts += [p for p in world.drivable if len(p)]
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def _paint_world(world: WorldMap, res: float, max_pixels: int, seed: int) -> _Raster:
    """Paints the label raster of a world (see the module docstring)."""
    pts = _world_points(world)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if pts.shape[0] == 0:
        lo, hi = np.zeros(2), np.ones(2)
    else:
        lo, hi = pts.min(axis=0) - _MARGIN, pts.max(axis=0) + _MARGIN
    ext = hi - lo
    res = max(res, float(np.sqrt(ext[0] * ext[1] / max_pixels)))
    wr, hr = int(np.ceil(ext[0] / res)) + 1, int(np.ceil(ext[1] / res)) + 1
    img = Image.new("L", (wr, hr), GRASS)
    draw = ImageDraw.Draw(img)

    def px(p: NDArray) -> list[tuple[float, float]]:
        q = (np.asarray(p, np.float64) - lo) / res
        return [(float(a), float(b)) for a, b in q]

    def line(p: NDArray, value: int, width_m: float) -> None:
        if len(p) >= 2:
            draw.line(px(p), fill=value, width=max(1, int(round(width_m / res))), joint="curve")

    bounds = [m for m in world.instances if m.cls == MapClass.BOUNDARY and len(m.points) >= 2]
    for m in bounds:  # sidewalk band behind every kerb
        line(m.points, SIDEWALK, 6.0)
    for poly in world.drivable:
        if len(poly) >= 3:
            draw.polygon(px(poly), fill=ASPHALT)
    for m in bounds:
        line(m.points, KERB, 0.3)
    rng = np.random.default_rng([seed, 0xA1])
    for m in world.instances:
        if m.cls == MapClass.DIVIDER and len(m.points) >= 2:
            _paint_divider(line, np.asarray(m.points, np.float64), m.style or "solid_white", rng)
        elif m.cls == MapClass.PED_CROSSING and len(m.points) >= 3:
            for bar in _zebra_bars(np.asarray(m.points, np.float64)):
                draw.polygon(px(bar), fill=WHITE)
    return _Raster(np.asarray(img, dtype=np.uint8), float(lo[0]), float(lo[1]), res)


def _paint_divider(line, pts: NDArray, style: str, rng: np.random.Generator) -> None:  # noqa: ANN001
    """Paints one divider polyline by style: colour (white / yellow), solid / dashed, single /
    double. `line(points, value, width_m)` draws a polyline."""
    value = YELLOW if "yellow" in style else WHITE
    if "double" in style:
        offsets = (-0.17, 0.17)
    else:
        offsets = (0.0,)
    dashed = "dashed" in style
    s = arc_length(pts)
    for off in offsets:
        p = offset_curve(pts, off) if off else pts
        if not dashed:
            line(p, value, 0.15)
            continue
        period, dash = 9.0, 3.0
        start = float(rng.uniform(0.0, period))
        for a in np.arange(start - period, s[-1], period):
            a0, a1 = max(a, 0.0), min(a + dash, s[-1])
            if a1 - a0 > 0.3:
                line(sub_curve(p, a0, a1, 0.5), value, 0.15)


def _zebra_bars(ring: NDArray) -> list[NDArray[np.float64]]:
    """Zebra bars (each (n, 2) polygon) inside a crossing ring: 0.5 m wide bars every 1 m along the
    long side of the crossing's minimum rotated rectangle, running along its short side."""
    poly = Polygon(ring)
    if not poly.is_valid:
        poly = poly.buffer(0)
    if poly.is_empty or poly.area < 0.5:
        return []
    rect = np.asarray(poly.minimum_rotated_rectangle.exterior.coords)[:4]  # (4, 2)
    e1, e2 = rect[1] - rect[0], rect[3] - rect[0]
    long_e, short_e = (e1, e2) if np.linalg.norm(e1) >= np.linalg.norm(e2) else (e2, e1)
    length = float(np.linalg.norm(long_e))
    u = long_e / length
    bars = []
    for a in np.arange(0.25, length - 0.25, 1.0):
        p0 = rect[0] + a * u
        bar = Polygon(
            [
                p0 - 0.05 * short_e,
                p0 + 0.5 * u - 0.05 * short_e,
                p0 + 0.5 * u + 1.05 * short_e,
                p0 + 1.05 * short_e,
            ]
        )
        piece = bar.intersection(poly).buffer(-0.05)
        for g in getattr(piece, "geoms", [piece]):
            if isinstance(g, Polygon) and not g.is_empty:
                bars.append(np.asarray(g.exterior.coords))
    return bars


def _no_vehicles() -> _Vehicles:
    z = np.zeros((0,), np.float64)
    return _Vehicles(np.zeros((0, 2)), z, np.zeros((0, 3)), np.zeros((0, 3), np.float32), [], z, z)


def _make_vehicles(world: WorldMap, rng: np.random.Generator) -> _Vehicles:
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
    return _Vehicles(
        np.array(centres, np.float64).reshape(n, 2),
        np.array(yaws, np.float64).reshape(n),
        np.array(sizes, np.float64).reshape(n, 3),
        np.array(cols, np.float32).reshape(n, 3),
        lanes,
        np.array(s0, np.float64).reshape(n),
        np.array(speed, np.float64).reshape(n),
    )
