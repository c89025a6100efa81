"""The look of the painted ground and the sky: a per-world palette and a tiled noise texture.

Both are drawn from the renderer's random stream in the order the renderer calls them
(``draw_palette`` first, then ``value_noise``), so a seed always gives the same look. No I/O,
no geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from icmapper.data.sim.paint import ASPHALT, GRASS, SIDEWALK

NOISE = 512  # side of the tiled noise texture (raster pixels); a power of two


@dataclass(frozen=True)
class Palette:
    """Colours of one world: per raster label a base colour and a texture amplitude, and the sky's
    horizon and zenith colours."""

    lut: NDArray[np.float32]  # (L, 3) base colour per label
    amp: NDArray[np.float32]  # (L,) texture amplitude per label
    horizon: NDArray[np.float32]  # (3,) sky colour at the horizon (and of the haze)
    zenith: NDArray[np.float32]  # (3,) sky colour overhead


def draw_palette(rng: np.random.Generator) -> Palette:
    """The palette of one world, drawn from ``rng`` (asphalt and sidewalk shades, grass tint,
    how blue the sky is)."""
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
    amp = np.array([0.30, 0.10, 0.06, 0.16, 0.08, 0.08], dtype=np.float32)  # (L,)
    sky_blue = rng.uniform(0.0, 1.0)
    horizon = np.array([205, 212, 220], dtype=np.float32)
    zenith = (1 - sky_blue) * np.array([180, 186, 196], np.float32) + sky_blue * np.array(
        [95, 140, 205], np.float32
    )
    return Palette(lut, amp, horizon, zenith)


def value_noise(rng: np.random.Generator, n: int = NOISE) -> NDArray[np.float32]:
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
