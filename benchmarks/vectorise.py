"""The vectoriser, engine against the former Python one (``python -m benchmarks vectorise``): prints
measured numbers and ratios from one run (never asserts).

Two mask sets, each vectorised by the engine (``icmapper._icmap.vectorise``, Rust) and by the
reference (``icmapper.testing.vectorise_reference``: numpy / scipy / scikit-image / shapely / torch,
the runtime's vectoriser before the port), both at one thread (torch and the engine's classes
serial), with the shipped settings (upsampled 4x):

- ``50x25``: the shipped checkpoint's own probabilities on its 50x25 BEV (the 64 frames of
  ``tests/data/vectorise_masks.npz``, recorded from sim:val:12 by
  ``scripts/record_vectorise_masks.py``);
- ``100x50``: masks of the paper config's 100x50 BEV (60 x 30 m): the rasterised ground truth of
  sim:val frames at that size (0.95 on a target cell, 0.05 elsewhere), as the GPU measurement of
  issue 33 fed it for the segmentation output.

For each: the median ms/frame of both and their ratio (the engine's result is checked to be the
reference's: same classes, points within 1e-3 m), the engine with the classes of a frame in
parallel (its pool), and the frames/s of two threads vectorising at once against one (each call
serial; the GIL is released in the engine).
"""

from __future__ import annotations

import argparse
import os
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

MASKS = Path(__file__).resolve().parents[1] / "tests" / "data" / "vectorise_masks.npz"


def recorded_masks(limit: int | None) -> tuple[list[np.ndarray], float, float]:
    """The shipped checkpoint's recorded probabilities (K, 50, 25) and the half extents."""
    d = np.load(MASKS)
    hx, hy = (float(v) for v in d["_half"])
    frames = [d[k] for k in d.files if k != "_half"]
    return frames[:limit], hx, hy


def ground_truth_masks(source: str, limit: int) -> tuple[list[np.ndarray], float, float]:
    """Rasterised ground truth (3, 100, 50) over 60 x 30 m of the first ``limit`` frames of
    ``source``."""
    import torch
    from icmapper.data.gt import sequence_gt
    from icmapper.data.sources import open_source
    from icmapper.data.types import PerceptionRange
    from icmapper.models.segmentation import rasterise

    rng = PerceptionRange.from_name("60x30")
    out: list[np.ndarray] = []
    for seq in open_source(source, image_size=(32, 64)):
        for g in sequence_gt(seq, rng):
            pts, cls = torch.as_tensor(g.points), torch.as_tensor(g.classes)
            mask = rasterise(pts, cls, 100, 50, rng.half_x, rng.half_y).numpy()  # (3, 100, 50)
            out.append((0.05 + 0.9 * mask).astype(np.float32))
            if len(out) >= limit:
                return out, rng.half_x, rng.half_y
    return out, rng.half_x, rng.half_y


def _engine(prob: np.ndarray, hx: float, hy: float, parallel: bool) -> Any:
    """The engine's call with the shipped settings resolved for this grid, as
    ``models.vectorise.vectorise`` makes it (the binding's own defaults are the 50x25 grid's:
    its ``shrink`` of 0.9 m is twice the 100x50 grid's target radius)."""
    from icmapper import _icmap
    from icmapper.models.vectorise import VectoriseParams

    p = VectoriseParams().for_grid(prob.shape[1], prob.shape[2], hx, hy)
    return _icmap.vectorise(prob, hx, hy, **p.engine_settings(), parallel=parallel)


def _per_frame(fn: Any, frames: list[np.ndarray], rounds: int) -> list[float]:
    """Seconds per frame (the best of ``rounds`` passes for each frame)."""
    best = [float("inf")] * len(frames)
    for _ in range(rounds):
        for i, f in enumerate(frames):
            t0 = time.perf_counter()
            fn(f)
            best[i] = min(best[i], time.perf_counter() - t0)
    return best


def _threads_throughput(frames: list[np.ndarray], hx: float, hy: float, n: int, reps: int) -> float:
    """Frames/s of ``n`` threads each vectorising the frames ``reps`` times (serial calls)."""

    def work() -> None:
        for _ in range(reps):
            for f in frames:
                _engine(f, hx, hy, False)

    threads = [threading.Thread(target=work) for _ in range(n)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return n * reps * len(frames) / (time.perf_counter() - t0)


def _same(ref: Any, got: Any) -> bool:
    classes, _, points = got
    return bool(
        np.array_equal(ref.classes, classes)
        and (len(classes) == 0 or float(np.abs(ref.points - points).max()) <= 1e-3)
    )


def run_set(
    name: str, frames: list[np.ndarray], hx: float, hy: float, a: argparse.Namespace
) -> None:
    from icmapper.testing.vectorise_reference import vectorise_reference

    same = sum(_same(vectorise_reference(f, hx, hy), _engine(f, hx, hy, False)) for f in frames)
    ref = _per_frame(lambda f: vectorise_reference(f, hx, hy), frames, a.rounds)
    eng = _per_frame(lambda f: _engine(f, hx, hy, False), frames, a.rounds)
    par = _per_frame(lambda f: _engine(f, hx, hy, True), frames, a.rounds)
    reps = max(1, a.thread_reps)
    one = _threads_throughput(frames, hx, hy, 1, reps)
    two = _threads_throughput(frames, hx, hy, 2, reps)
    k, x, y = frames[0].shape
    med = {n: 1e3 * float(np.median(v)) for n, v in (("ref", ref), ("eng", eng), ("par", par))}
    mean_ratio = float(np.sum(ref) / np.sum(eng))
    print(f"{name}: {len(frames)} frames of ({k}, {x}, {y}), upsampled 4x to {4 * x}x{4 * y}; "
          f"engine = reference on {same}/{len(frames)}")  # fmt: skip
    print(f"  reference (Python, 1 thread)   {med['ref']:8.2f} ms/frame (median)")
    print(f"  engine (Rust, 1 thread)        {med['eng']:8.3f} ms/frame (median)   "
          f"{med['ref'] / med['eng']:6.1f}x  (total time {mean_ratio:.1f}x)")  # fmt: skip
    print(f"  engine, classes in parallel    {med['par']:8.3f} ms/frame (median)   "
          f"{med['eng'] / med['par']:6.2f}x the serial engine")  # fmt: skip
    print(f"  two threads at once            {two:8.0f} frames/s vs one {one:.0f}: "
          f"{two / one:.2f}x")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks vectorise", description=__doc__)
    p.add_argument("--frames", type=int, default=64, help="recorded frames (at most 64)")
    p.add_argument("--gt-frames", type=int, default=64, help="ground-truth frames at 100x50")
    p.add_argument("--source", default="sim:val:2", help="source of the ground-truth masks")
    p.add_argument("--rounds", type=int, default=3, help="passes over the frames (best kept)")
    p.add_argument("--thread-reps", type=int, default=5, help="passes of each thread")
    a = p.parse_args(argv)

    import torch

    torch.set_num_threads(1)
    print(f"threads: torch {torch.get_num_threads()}, OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS', 'unset')}, cores {os.cpu_count()}")  # fmt: skip
    frames, hx, hy = recorded_masks(a.frames)
    run_set("50x25 (shipped checkpoint)", frames, hx, hy, a)
    gt, hx, hy = ground_truth_masks(a.source, a.gt_frames)
    run_set(f"100x50 (rasterised ground truth, {a.source})", gt, hx, hy, a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
