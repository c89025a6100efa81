"""Colours and fonts shared by every picture, video and viewer of ``icmapper.vis``.

Class colours are matplotlib's tab10 blue / orange / green, as in the other pictures of the
package (``mapping.plot``, ``data.preview``). No I/O besides loading Pillow's bundled font.
"""

from __future__ import annotations

import functools

from PIL import ImageFont

from icmapper.data.types import CLASS_NAMES

#: RGB of each class, in class order (ped_crossing, divider, boundary).
CLASS_RGB: tuple[tuple[int, int, int], ...] = ((31, 119, 180), (255, 127, 14), (44, 160, 44))
#: The same colours as CSS hex strings (the HTML viewer).
CLASS_HEX: tuple[str, ...] = tuple("#{:02x}{:02x}{:02x}".format(*c) for c in CLASS_RGB)
#: Ego path and frame (picture background, text).
EGO_RGB = (40, 40, 40)
PATH_RGB = (150, 150, 150)
BACKGROUND_RGB = (250, 250, 250)
TEXT_RGB = (20, 20, 20)

assert len(CLASS_RGB) == len(CLASS_NAMES)


def tint(rgb: tuple[int, int, int], amount: float) -> tuple[int, int, int]:
    """``rgb`` moved ``amount`` (0: unchanged, 1: white) towards white."""
    return tuple(int(round(c + (255 - c) * amount)) for c in rgb)  # type: ignore[return-value]


@functools.lru_cache(maxsize=16)
def font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """Pillow's bundled font at ``size`` pixels (its bitmap font where FreeType is missing)."""
    return ImageFont.load_default(size=size)
