"""The label raster of a world: the ground the renderer's cameras see, painted once per world.

Labels (``GRASS`` .. ``YELLOW``) at about 0.1 m per pixel: grass everywhere, drivable polygons as
asphalt, boundaries as kerbs with a sidewalk band behind, dividers painted by style (solid, dashed
3 m / 6 m, double lines, 0.15 m wide), crossings as zebra bars. Colour, texture and cameras are the
renderer's (``texture``, ``renderer``). No I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw
from shapely.geometry import Polygon

from icmapper.data.sim.geometry import arc_length, offset_curve, sub_curve
from icmapper.data.types import MapClass, WorldMap

# Raster labels.
GRASS, SIDEWALK, KERB, ASPHALT, WHITE, YELLOW = range(6)
_MARGIN = 60.0  # m of grass around the world in the raster


@dataclass
class Raster:
    """A painted world: one label per pixel, the world position of pixel (0, 0) and the scale."""

    labels: NDArray[np.uint8]  # (Hr, Wr) label per pixel; row = y, column = x
    x0: float
    y0: float
    res: float  # metres per pixel


def world_points(world: WorldMap) -> NDArray[np.float64]:
    """Every point of the world's instances and drivable polygons (n, 2), for its extent."""
    pts = [m.points for m in world.instances if len(m.points)]
    pts += [p for p in world.drivable if len(p)]
    return np.concatenate(pts) if pts else np.zeros((0, 2))


def paint_world(world: WorldMap, res: float, max_pixels: int, seed: int) -> Raster:
    """Paints the label raster of a world (see the module docstring)."""
    pts = world_points(world)
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
            paint_divider(line, np.asarray(m.points, np.float64), m.style or "solid_white", rng)
        elif m.cls == MapClass.PED_CROSSING and len(m.points) >= 3:
            for bar in zebra_bars(np.asarray(m.points, np.float64)):
                draw.polygon(px(bar), fill=WHITE)
    return Raster(np.asarray(img, dtype=np.uint8), float(lo[0]), float(lo[1]), res)


def paint_divider(line, pts: NDArray, style: str, rng: np.random.Generator) -> None:  # noqa: ANN001
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


def zebra_bars(ring: NDArray) -> list[NDArray[np.float64]]:
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
