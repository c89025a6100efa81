"""A drive as a video: the per-frame pictures of a run as an MP4, or a GIF without an encoder.

MP4 needs ``imageio`` with its ``imageio-ffmpeg`` plugin (PyPI; the plugin ships a static ffmpeg
binary, so no system package is needed): H.264, yuv420p, frames padded to even sizes with the
picture background. When either is missing, or for a ``.gif`` path, Pillow writes an animated GIF
(palette per frame, larger and coarser, but no dependency beyond Pillow). No other I/O.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from PIL import Image

from icmapper.atomic import atomic_path
from icmapper.vis.style import BACKGROUND_RGB

#: Container suffixes written through imageio-ffmpeg.
FFMPEG_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")


def mp4_available() -> bool:
    """True when imageio and its ffmpeg plugin (with its binary) are importable."""
    try:
        import imageio.v2  # noqa: F401
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError, OSError):
        return False
    return True


def _pad_even(img: Image.Image, block: int = 2) -> Image.Image:
    """The image padded right / bottom to multiples of ``block`` pixels (yuv420p needs even)."""
    w, h = img.size
    pw, ph = -(-w // block) * block, -(-h // block) * block
    if (pw, ph) == (w, h):
        return img
    out = Image.new("RGB", (pw, ph), BACKGROUND_RGB)
    out.paste(img, (0, 0))
    return out


def write_video(frames: Iterable[Image.Image], path: str | os.PathLike, fps: float = 2.0) -> Path:
    """Writes ``frames`` (Pillow images of one size) as a video at ``path``; returns the path
    written: ``path`` itself, or ``path`` with a ``.gif`` suffix where MP4 cannot be written
    (a warning says why). Written to a temporary file first, then renamed."""
    out = Path(path)
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps}")
    suffix = out.suffix.lower()
    if suffix not in FFMPEG_SUFFIXES + (".gif",):
        raise ValueError(f"{out}: unknown video suffix {out.suffix!r} (use .mp4 or .gif)")
    if suffix != ".gif" and not mp4_available():
        warnings.warn(
            "imageio / imageio-ffmpeg not installed (pip install imageio imageio-ffmpeg): "
            f"writing a GIF instead of {out.name}",
            stacklevel=2,
        )
        out, suffix = out.with_suffix(".gif"), ".gif"
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        write = _write_gif if suffix == ".gif" else _write_ffmpeg
        n = write(frames, str(tmp), fps)
        if n == 0:
            raise ValueError("no frames to write")
    return out


def _write_ffmpeg(frames: Iterable[Image.Image], path: str, fps: float) -> int:
    import imageio.v2 as imageio

    n = 0
    size = None
    with imageio.get_writer(
        path, format="FFMPEG", mode="I", fps=fps, codec="libx264", pixelformat="yuv420p",
        quality=5, macro_block_size=1, ffmpeg_log_level="error",
    ) as writer:  # fmt: skip
        for img in frames:
            img = _pad_even(img.convert("RGB"))
            if size is None:
                size = img.size
            elif img.size != size:
                raise ValueError(f"frame {n} is {img.size}, the first frame was {size}")
            writer.append_data(np.asarray(img))  # (H, W, 3) uint8
            n += 1
    return n


def _write_gif(frames: Iterable[Image.Image], path: str, fps: float) -> int:
    imgs = [img.convert("RGB") for img in frames]
    if not imgs:
        return 0
    size = imgs[0].size
    for k, img in enumerate(imgs):
        if img.size != size:
            raise ValueError(f"frame {k} is {img.size}, the first frame was {size}")
    pal = [img.quantize(colors=255, method=Image.Quantize.MEDIANCUT) for img in imgs]
    pal[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=pal[1:],
        duration=int(round(1000.0 / fps)),
        loop=0,
        optimize=False,
    )
    return len(imgs)
