"""Renderer benchmark: frames per second of `sim.Renderer` for the six-camera rig at 128x352 and
256x704 (one frame = all six images), measured over a synthetic drive after a warm-up frame, plus
the one-off costs (city generation, raster painting), and the cost of opening drives at the
paper config's 480x800: a renderer as made now (rays shared per rig, arrays of camera size drawn
on the first frame) against the former eager set-up (rays cast and sensor grain drawn for every
drive), with the ratio. Prints numbers; asserts nothing.

Run (repository root): `.venv/bin/python -m benchmarks render [--frames N] [--city SEED]
[--open N]`."""

from __future__ import annotations

import argparse
import time

import numpy as np
from icmapper.data.sim import renderer as renderer_module
from icmapper.data.sim.city import generate_city
from icmapper.data.sim.driver import drive
from icmapper.data.sim.renderer import Renderer
from icmapper.data.sim.rig import nuscenes_rig
from icmapper.data.types import WorldMap

SIZES = ((128, 352), (256, 704))
OPEN_SIZE = (480, 800)  # configs/paper.toml


def open_drives(world: WorldMap, n: int, eager: bool) -> float:
    """Seconds to make ``n`` renderers of ``world`` at OPEN_SIZE; ``eager`` adds what the former
    constructor did for each: cast every pixel's ray and draw the sensor grain."""
    renderer_module._rays_cache.clear()
    rig = nuscenes_rig(OPEN_SIZE)
    t0 = time.perf_counter()
    for k in range(n):
        Renderer(world, rig, seed=k)
        if eager:
            renderer_module._cast_rays(rig)
            size = 2 * rig.num_cameras * 3 * OPEN_SIZE[0] * OPEN_SIZE[1]
            np.random.default_rng(k).standard_normal(size).astype(np.float32)
    return time.perf_counter() - t0


def run_render_bench(args: argparse.Namespace) -> int:
    """Runs the benchmark (args.frames frames per size, args.city city seed) and prints a table."""
    frames = int(getattr(args, "frames", 40))
    city = int(getattr(args, "city", 10_003))
    t0 = time.perf_counter()
    world = generate_city(city)
    t_city = time.perf_counter() - t0
    _, poses = drive(world, 0)
    print(
        f"city {city}: generate_city {t_city * 1e3:.0f} ms, "
        f"{len(world.instances)} instances, {len(world.lanes)} lanes"
    )
    for size in SIZES:
        renderer = Renderer(world, nuscenes_rig(size), seed=0)
        t0 = time.perf_counter()
        renderer.render(poses[0], frame_seed=0)  # paints the raster
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        for i in range(frames):
            renderer.render(poses[i % len(poses)], frame_seed=i, t=0.5 * i)
        dt = time.perf_counter() - t0
        h, w = size
        print(
            f"6 x {h}x{w}: {frames / dt:6.1f} frames/s ({dt / frames * 1e3:.1f} ms/frame); "
            f"first frame incl. raster {t_first * 1e3:.0f} ms"
        )
    n_open = int(getattr(args, "open", 8))
    if n_open > 0:
        now, former = open_drives(world, n_open, False), open_drives(world, n_open, True)
        h, w = OPEN_SIZE
        print(
            f"opening {n_open} drives at 6 x {h}x{w}: {now / n_open * 1e3:.1f} ms/drive; "
            f"former eager set-up {former / n_open * 1e3:.0f} ms/drive; "
            f"ratio {former / max(now, 1e-9):.0f}x"
        )
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=40, help="frames timed per image size")
    parser.add_argument("--city", type=int, default=10_003, help="city seed")
    parser.add_argument("--open", type=int, default=8, help="drives opened at 480x800 (0: skip)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks render", description=__doc__)
    add_arguments(parser)
    return run_render_bench(parser.parse_args(argv))
