"""Renderer benchmark: frames per second of `sim.Renderer` for the six-camera rig at 128x352 and
256x704 (one frame = all six images), measured over a synthetic drive after a warm-up frame, plus
the one-off costs (city generation, raster painting). Prints numbers; asserts nothing.

Run (repository root): `.venv/bin/python -m benchmarks render [--frames N] [--city SEED]`."""

from __future__ import annotations

import argparse
import time

from icmapper.data.sim.city import generate_city
from icmapper.data.sim.driver import drive
from icmapper.data.sim.renderer import Renderer
from icmapper.data.sim.rig import nuscenes_rig

SIZES = ((128, 352), (256, 704))


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
    return 0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=40, help="frames timed per image size")
    parser.add_argument("--city", type=int, default=10_003, help="city seed")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks render", description=__doc__)
    add_arguments(parser)
    return run_render_bench(parser.parse_args(argv))
