"""Camera images of a WorldMap by ray-casting the ground plane onto a painted world raster.

How it works (all vectorised numpy, no per-pixel Python), one module per job:
- Once per rig (``rays``, shared by the renderers of the same rig): every camera pixel's ray is
  cast from its mount onto the ego's ground plane, giving a fixed ego-frame hit point, depth and
  haze weight per pixel; rays above the horizon see sky / haze. A renderer's own arrays of camera
  size (sensor grain, sky colours) and its vehicles are drawn on its first frame, so opening many
  drives is cheap.
- Once per world, lazily on the first frame (``paint``): the world is painted into a label raster
  (0.1 m per pixel): grass, sidewalk, kerb, asphalt, white and yellow paint. A few rasters stay in
  memory at once (least recently used ones are dropped and rebuilt on demand).
- Per frame (here): the fixed hit points are moved by the pose (x, y, yaw), labels gathered
  (nearest), coloured with a per-world palette and a tiled noise texture (``texture``), hazed with
  distance; vehicles (``vehicles``: parked at kerbs and moving along lanes, seeded) are ray/box
  intersected with a depth test and cast a shadow; then exposure, white balance, blur and sensor
  noise drawn from the frame seed (``sensor``).

This module holds the ``Renderer`` (its random stream, what it keeps in memory) and the per-frame
composition. No I/O. Output (C, 3, H, W) uint8.
"""

from __future__ import annotations

import copy
import weakref
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.data.sim.paint import GRASS, Raster, paint_world
from icmapper.data.sim.rays import cast_rays as _cast_rays  # noqa: F401 (benchmarks/render.py)
from icmapper.data.sim.rays import rays_cache as _rays_cache  # noqa: F401 (benchmarks/render.py)
from icmapper.data.sim.rays import rays_for
from icmapper.data.sim.sensor import expose
from icmapper.data.sim.texture import NOISE, draw_palette, value_noise
from icmapper.data.sim.vehicles import Vehicles, draw_vehicles, make_vehicles, no_vehicles
from icmapper.data.types import CameraRig, WorldMap, pose_to_xy_yaw

_KEEP_RASTERS = 8  # rasters kept in memory across renderers (least recently used dropped)

_built: OrderedDict[int, weakref.ref[Renderer]] = OrderedDict()


@dataclass
class _Heavy:
    """A renderer's arrays of camera size, built on its first frame (dropped with its raster)."""

    grain: NDArray[np.float32]  # (2*C*3*H*W,) sensor noise drawn once, read at a random offset
    vehicles: Vehicles
    sky: NDArray[np.float32]  # (C, H, W, 3) horizon-to-zenith colour per pixel


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
        self._palette = draw_palette(rng)
        self._rays = rays_for(rig)
        self._noise = value_noise(rng, NOISE)  # (N, N) float32 in about [-1, 1]
        # The grain, the vehicles and the sky are drawn on the first frame from this point of the
        # renderer's random stream (opening thousands of drives stays cheap; see _ensure_heavy).
        self._tail_state = rng.bit_generator.state
        self._with_vehicles = bool(vehicles)
        self._grain_seed: list[int] | None = None  # another rig's grain stream (with_rig)
        self._heavy: _Heavy | None = None
        self._raster: Raster | None = None

    def with_rig(self, rig: CameraRig) -> Renderer:
        """A renderer of the same world (its raster shared, painted once), palette, texture and
        vehicles for other cameras: test fixtures render each camera of each frame through its
        own geometry without repainting the world."""
        if not isinstance(rig, CameraRig):
            raise TypeError(f"rig must be a CameraRig, got {type(rig).__name__}")
        other = copy.copy(self)
        other.rig = rig
        other._rays = rays_for(rig)
        other._grain_seed = [self.seed, 0x6A]
        other._heavy = None
        other._raster = self._ensure_raster()
        return other

    # ----------------------------------------------------------------- raster
    def _ensure_raster(self) -> Raster:
        if self._raster is None:
            self._raster = paint_world(
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
            vehicles = make_vehicles(self.world, rng) if self._with_vehicles else no_vehicles()
            if self._grain_seed is not None:
                grain = np.random.default_rng(self._grain_seed).standard_normal(n)
                grain = grain.astype(np.float32)
            a = self._rays.sky_weight  # (C, H, W, 1)
            pal = self._palette
            sky = ((1 - a) * pal.horizon + a * pal.zenith).astype(np.float32)  # (C, H, W, 3)
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
        pal = self._palette
        tex = self._noise[iy & (NOISE - 1), ix & (NOISE - 1)]  # (N,)
        shade = 1.0 + pal.amp[lab] * tex  # (N,)
        col = pal.lut[lab] * shade[:, None]  # (N, 3)
        col += rays.fog * (pal.horizon - col)  # haze with distance
        img[rays.ground_flat] = col
        img = img.reshape(c, h, w, 3)

        draw_vehicles(img, heavy.vehicles, rig, rays, x, y, yaw, t)

        # Camera effects: exposure / white balance, blur, sensor noise.
        rng = np.random.default_rng(
            [self.seed, 0 if frame_seed is None else int(frame_seed) + 1, 0xF2]
        )
        return expose(img, rng, heavy.grain)  # (C, 3, H, W)
