"""Real camera images from disk: frames/s of JPEG decode + resize for 6 cameras per frame
(nuScenes' 1600 x 900), by decoder candidate and by DataLoader worker count, against a naive
Pillow open + full decode + resize baseline measured in the same run.

    python -m benchmarks images [--seconds S] [--frames N] [--workers 0 1 2 ... | auto]

``--workers``: the DataLoader worker counts measured (default 0, 1, 2 and ``auto``: what
``data.num_workers = -1`` resolves to on this machine, ``training.config.resolve_num_workers``);
on a many-core GPU machine pass e.g. ``--workers 0 4 8 15 auto``.

Candidates (each gives (3, H, W) uint8 with the "fit" resize of ``icmapper.data.images``):
naive Pillow; Pillow with ``draft`` (libjpeg DCT-scaled decode) + resize; simplejpeg with
``min_height/min_width`` (DCT-scaled decode) + Pillow resize — icmapper's ``decode_resize`` —
and the same with accurate DCT; torchvision ``decode_jpeg`` + ``interpolate`` when torchvision is
installed (it is not a dependency). The test images are rendered by the simulator at 450 x 800,
upscaled to 1600 x 900 with sensor noise added (JPEG size close to nuScenes' ~150-250 KB).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

NATIVE = (900, 1600)
SIZES = ((480, 800), (64, 176))


def _write_images(folder: Path, n: int) -> list[Path]:
    from icmapper.data import sim
    from PIL import Image

    world = sim.generate_city(10_000)
    rig = sim.nuscenes_rig((NATIVE[0] // 2, NATIVE[1] // 2))
    _, poses = sim.drive(world, 0)
    imgs = sim.Renderer(world, rig, 0).render(poses[min(3, len(poses) - 1)])  # (6, 3, h, w)
    rng = np.random.default_rng(0)
    paths = []
    for k in range(n):
        img = Image.fromarray(np.ascontiguousarray(imgs[k % 6].transpose(1, 2, 0)))
        big = np.asarray(img.resize((NATIVE[1], NATIVE[0]), Image.Resampling.BICUBIC), np.float32)
        big = np.clip(big + rng.normal(0, 3.0, big.shape), 0, 255).astype(np.uint8)
        p = folder / f"img{k:03d}.jpg"
        Image.fromarray(big).save(p, quality=90)
        paths.append(p)
    return paths


def _fit(size: tuple[int, int]) -> tuple[int, int]:
    from icmapper.data.images import fit_size

    return fit_size(NATIVE, size)


def _pad(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    out = np.zeros((3, *size), np.uint8)  # (3, H, W)
    out[:, : img.shape[0], : img.shape[1]] = img.transpose(2, 0, 1)
    return out


def naive(path: Path, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    nh, nw = _fit(size)
    img = Image.open(path).convert("RGB").resize((nw, nh), Image.Resampling.BILINEAR)
    return _pad(np.asarray(img), size)


def pillow_draft(path: Path, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    nh, nw = _fit(size)
    im = Image.open(path)
    im.draft("RGB", (nw, nh))
    f = NATIVE[1] / im.size[0]
    box = (0.0, 0.0, NATIVE[1] / f, NATIVE[0] / f)
    return _pad(
        np.asarray(im.convert("RGB").resize((nw, nh), Image.Resampling.BILINEAR, box=box)), size
    )


def simplejpeg_fast(path: Path, size: tuple[int, int]) -> np.ndarray:
    from icmapper.data.images import decode_resize

    return decode_resize(path, NATIVE, size)


def simplejpeg_accurate(path: Path, size: tuple[int, int]) -> np.ndarray:
    import simplejpeg
    from PIL import Image

    nh, nw = _fit(size)
    arr = simplejpeg.decode_jpeg(path.read_bytes(), min_height=nh, min_width=nw)
    f = NATIVE[1] / arr.shape[1]
    box = (0.0, 0.0, NATIVE[1] / f, NATIVE[0] / f)
    img = Image.fromarray(arr).resize((nw, nh), Image.Resampling.BILINEAR, box=box)
    return _pad(np.asarray(img), size)


def torchvision_decode(path: Path, size: tuple[int, int]) -> np.ndarray:
    import torch
    import torch.nn.functional as F
    import torchvision.io as tio

    nh, nw = _fit(size)
    x = tio.decode_jpeg(tio.read_file(str(path)))  # (3, h, w) uint8
    y = F.interpolate(x[None].float(), size=(nh, nw), mode="bilinear", antialias=True)[0]
    out = np.zeros((3, *size), np.uint8)
    out[:, :nh, :nw] = y.round().clamp(0, 255).to(torch.uint8).numpy()
    return out


def _rate(fn: Callable[[Path, tuple[int, int]], np.ndarray], paths: list[Path], size, seconds):  # noqa: ANN001, ANN202
    fn(paths[0], size)
    t0, frames = time.perf_counter(), 0
    while time.perf_counter() - t0 < seconds:
        i = frames % (len(paths) // 6)
        for p in paths[6 * i : 6 * i + 6]:
            fn(p, size)
        frames += 1
    return frames / (time.perf_counter() - t0)


class _Frames:
    """A Dataset of frames of 6 JPEGs decoded by `fn` (module-level, so workers can pickle it)."""

    def __init__(self, fn, paths: list[Path], size: tuple[int, int], n: int):  # noqa: ANN001
        self.fn, self.paths, self.size, self.n = fn, paths, size, n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, i: int) -> np.ndarray:
        k = i % (len(self.paths) // 6)
        return np.stack([self.fn(p, self.size) for p in self.paths[6 * k : 6 * k + 6]])


def _loader_rate(fn, paths: list[Path], size, workers: int, frames: int) -> float:  # noqa: ANN001
    from torch.utils.data import DataLoader

    dl = DataLoader(_Frames(fn, paths, size, frames), batch_size=1, num_workers=workers)
    t0 = time.perf_counter()
    n = sum(1 for _ in dl)
    return n / (time.perf_counter() - t0)


def worker_counts(items: list[str]) -> list[tuple[str, int]]:
    """``--workers`` -> (label, DataLoader workers): integers as given, ``auto`` as
    ``data.num_workers = -1`` resolves here (its label says to what). SystemExit on anything
    else."""
    from icmapper.training.config import resolve_num_workers

    out = []
    for item in items:
        if item == "auto":
            n = resolve_num_workers(-1)
            out.append((f"auto ({n})", n))
        elif item.isdigit():
            out.append((item, int(item)))
        else:
            raise SystemExit(f"--workers: expected integers >= 0 or auto, got {item!r}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks images", description=__doc__)
    ap.add_argument("--seconds", type=float, default=3.0, help="per decoder and size")
    ap.add_argument("--frames", type=int, default=24, help="frames per DataLoader run")
    ap.add_argument("--workers", nargs="+", default=["0", "1", "2", "auto"],
                    help="DataLoader worker counts (integers >= 0, or auto)")  # fmt: skip
    args = ap.parse_args(argv)
    counts = worker_counts(args.workers)
    import torch

    torch.set_num_threads(1)
    candidates: dict[str, Callable] = {
        "naive Pillow open+resize": naive,
        "Pillow draft+resize": pillow_draft,
        "simplejpeg fastdct+resize (icmapper)": simplejpeg_fast,
        "simplejpeg accurate+resize": simplejpeg_accurate,
    }
    try:
        import torchvision.io  # noqa: F401

        candidates["torchvision decode_jpeg+interpolate"] = torchvision_decode
    except (ImportError, RuntimeError, OSError) as e:
        print(f"torchvision: not measured ({type(e).__name__})")
    with tempfile.TemporaryDirectory() as tmp:
        paths = _write_images(Path(tmp), 12)
        kb = np.mean([p.stat().st_size for p in paths]) / 1024
        print(f"6 cameras x {NATIVE[1]}x{NATIVE[0]} JPEG (mean {kb:.0f} KB) per frame")
        for size in SIZES:
            print(f"\n-> {size[0]}x{size[1]} (H x W), one process, frames/s (ratio to naive)")
            base = None
            for name, fn in candidates.items():
                r = _rate(fn, paths, size, args.seconds)
                base = base or r
                print(f"  {name:<40} {r:7.2f}  ({r / base:.2f}x)")
            print(f"-> {size[0]}x{size[1]}, DataLoader workers, frames/s (ratio to naive)")
            for label, workers in counts:
                rn = _loader_rate(naive, paths, size, workers, args.frames)
                rs = _loader_rate(simplejpeg_fast, paths, size, workers, args.frames)
                print(f"  workers={label}: naive {rn:6.2f}  icmapper {rs:6.2f}  ({rs / rn:.2f}x)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
