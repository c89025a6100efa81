"""Real camera images from disk: JPEG decode + resize to the configured size, with the camera
intrinsics following the resize. Used by the nuScenes and Argoverse 2 readers; no geometry of
the logs here.

Resize policy ("fit"): every camera image is scaled by one factor s = min(H / h, W / w) (native
(h, w) -> target (H, W)), so nothing is squashed (the portrait AV2 front camera stays portrait),
and placed in the top-left corner of the (H, W) canvas; the rest (bottom rows or right columns)
is black padding. Pixel coordinates use the corner convention (pixel k covers [k, k + 1)), so the
intrinsics follow exactly: fx, cx scale by nw / w and fy, cy by nh / h, where (nh, nw) =
(round(h s), round(w s)) is the resized image; padding at the bottom/right moves nothing.

Decoder: simplejpeg (libjpeg-turbo, bundled in its wheel) decodes straight to a reduced size with
libjpeg's DCT scaling (M/8 of the native size, the smallest one still at least (nh, nw)); Pillow
then resizes that to (nh, nw) exactly (bilinear, antialiased), with a box that maps the native
image extent so the reduced decode adds no offset. ``benchmarks/bench_images.py`` measured the
candidates (BENCHMARKS.md). Normalisation to float happens in the network (``MapDetector``), on
the accelerator: the data pipeline moves uint8.

Open-time checks (``check_jpeg``): the file exists and starts with the JPEG start-of-image marker
and ends with the end-of-image marker (a truncated download lacks it), so a run over a large
dataset fails when it opens the source, not hours later. Decoding errors and images whose size
differs from the native size the metadata gives raise ``DataError`` naming the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from icmapper.data.errors import DataError

#: Accepted values of the ``images`` option of the real-data readers.
IMAGE_MODES = ("auto", "real", "render")

_SOI = b"\xff\xd8"
_EOI = b"\xff\xd9"


def resolve_images(mode: str, has_images: bool, where: Path) -> bool:
    """True when a reader should load real images: mode "real" (DataError when the data has
    none), "auto" (when it has them) or "render" (never)."""
    if mode not in IMAGE_MODES:
        raise ValueError(f"images must be one of {IMAGE_MODES}, got {mode!r}")
    if mode == "real" and not has_images:
        raise DataError(f"images=real asked but {where} holds no camera images")
    return mode == "real" or (mode == "auto" and has_images)


def fit_size(native_hw: tuple[int, int], size: tuple[int, int]) -> tuple[int, int]:
    """(nh, nw): the native (h, w) image scaled by min(H / h, W / w) into size (H, W)."""
    h, w = (int(v) for v in native_hw)
    big_h, big_w = (int(v) for v in size)
    if h < 1 or w < 1 or big_h < 1 or big_w < 1:
        raise ValueError(f"image sizes must be positive, got native {native_hw} target {size}")
    s = min(big_h / h, big_w / w)
    return min(big_h, max(1, round(h * s))), min(big_w, max(1, round(w * s)))


def fit_intrinsics(
    k: NDArray[np.float64], native_hw: tuple[int, int], size: tuple[int, int]
) -> NDArray[np.float64]:
    """The (3, 3) pixel intrinsics of a native (h, w) camera after the "fit" resize to (H, W)."""
    nh, nw = fit_size(native_hw, size)
    out = np.asarray(k, dtype=np.float64).copy()  # (3, 3)
    out[0] *= nw / native_hw[1]
    out[1] *= nh / native_hw[0]
    return out


def check_jpeg(path: Path) -> None:
    """Raises DataError unless `path` is a file that starts and ends like a complete JPEG."""
    try:
        with open(path, "rb") as f:
            head = f.read(2)
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - 2))
            tail = f.read(2)
    except FileNotFoundError:
        raise DataError(f"image not found: {path}") from None
    except OSError as e:
        raise DataError(f"cannot read image {path}: {e}") from None
    if head != _SOI:
        raise DataError(f"not a JPEG file: {path}")
    if size < 4 or tail != _EOI:
        raise DataError(f"truncated JPEG file (no end-of-image marker): {path}")


def _scale_num(native_hw: tuple[int, int], got_hw: tuple[int, int]) -> int | None:
    """The M of libjpeg's M/8 DCT scaling that turns native (h, w) into got (h, w), else None."""
    h, w = native_hw
    for m in range(1, 17):
        if (-(-h * m // 8), -(-w * m // 8)) == got_hw:
            return m
    return None


def decode_resize(
    path: Path, native_hw: tuple[int, int], size: tuple[int, int]
) -> NDArray[np.uint8]:
    """One JPEG of native size (h, w) -> (3, H, W) uint8 with the "fit" resize (module docstring).

    Raises DataError naming the file when it is missing, cannot be decoded, or is not (h, w).
    """
    import simplejpeg
    from PIL import Image

    nh, nw = fit_size(native_hw, size)
    try:
        data = Path(path).read_bytes()
    except OSError as e:
        raise DataError(f"cannot read image {path}: {e}") from None
    try:
        arr = simplejpeg.decode_jpeg(
            data, colorspace="RGB", fastdct=True, fastupsample=True, min_height=nh, min_width=nw
        )  # (h', w', 3) uint8 at M/8 of the native size
    except ValueError as e:
        raise DataError(f"cannot decode JPEG {path}: {e}") from None
    m = _scale_num(native_hw, arr.shape[:2])
    if m is None:
        head = simplejpeg.decode_jpeg_header(data)
        raise DataError(
            f"image {path} is {head[1]}x{head[0]} (W x H), but its metadata says "
            f"{native_hw[1]}x{native_hw[0]}"
        )
    h, w = native_hw
    box = (0.0, 0.0, w * m / 8.0, h * m / 8.0)  # the native extent in decoded pixels
    img = np.asarray(
        Image.fromarray(arr).resize((nw, nh), Image.Resampling.BILINEAR, box=box)
    )  # (nh, nw, 3)
    out = np.zeros((3, size[0], size[1]), dtype=np.uint8)  # (3, H, W) black padding
    out[:, :nh, :nw] = img.transpose(2, 0, 1)
    return out


class RealImages:
    """``Sequence.render`` of a real-image source: frame i's cameras read from disk.

    files[i][c]: the JPEG of camera c at keyframe i; native[i][c]: its native (h, w); size: the
    (H, W) of every output image. Calling it gives (C, 3, H, W) uint8. Plain data, so sequences
    pickle cheaply into DataLoader workers (each worker decodes its own frames).
    """

    def __init__(
        self,
        files: list[list[Path]],
        native: list[list[tuple[int, int]]],
        size: tuple[int, int],
    ):
        if len(files) != len(native) or any(
            len(f) != len(n) for f, n in zip(files, native, strict=True)
        ):
            raise ValueError("files and native sizes must have the same shape")
        self.files = files
        self.native = native
        self.size = (int(size[0]), int(size[1]))

    def __len__(self) -> int:
        return len(self.files)

    def __call__(self, i: int) -> NDArray[np.uint8]:
        return np.stack(
            [
                decode_resize(p, hw, self.size)
                for p, hw in zip(self.files[i], self.native[i], strict=True)
            ]
        )  # (C, 3, H, W)

    def check(self) -> None:
        """Open-time check of every file (``check_jpeg``): DataError naming the first bad one."""
        for row in self.files:
            for p in row:
                check_jpeg(p)
