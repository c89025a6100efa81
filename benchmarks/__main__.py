"""``python -m benchmarks NAME [options]``: runs one benchmark program (``--help`` after the name
gives its options). The benchmark's module is imported only when it runs, so listing them imports
neither torch nor shapely."""

from __future__ import annotations

import argparse
import importlib
import sys

#: name -> (module with ``main(argv) -> int``, one-line help), in help order.
BENCHMARKS: dict[str, tuple[str, str]] = {
    "geometry": (
        "benchmarks.geometry",
        "native geometry engine vs shapely/scipy reference, per-frame workload",
    ),
    "render": ("benchmarks.render", "camera renderer frames/s (6 cameras)"),
    "eval": (
        "benchmarks.evaluation",
        "all metrics on 150 sequences x 40 frames x 50 predictions vs numpy+shapely AP",
    ),
    "networks": (
        "benchmarks.networks",
        "training steps/s and per-module inference latency (small config)",
    ),
    "mapper": ("benchmarks.mapper", "per-frame latency of the online mapper by stage"),
    "pipeline": (
        "benchmarks.pipeline",
        "the whole Mapper at paper scale (fresh weights, rasterised GT as the segmentation): "
        "ms/frame by stage, frames/s",
    ),
    "vectorise": (
        "benchmarks.vectorise",
        "the vectoriser: Rust engine vs the former Python one, 1 thread and 2 threads at once",
    ),
    "train-step": (
        "benchmarks.train_step",
        "training frames/s: the former training step vs the current one (one run)",
    ),
    "python-geometry": (
        "benchmarks.python_geometry",
        "icmapper.geom's engine calls vs batched numpy forms (resample, Chamfer, point clouds)",
    ),
    "city": (
        "benchmarks.city",
        "city run of N drives of one synthetic city: in-process vs Ray with 1 and 2 workers",
    ),
    "longrun": (
        "benchmarks.longrun",
        "resident memory over a 10,000-frame mapping run (oracle detections)",
    ),
    "images": (
        "benchmarks.images",
        "real camera images: JPEG decode + resize frames/s by decoder and DataLoader workers",
    ),
    "viewer": (
        "benchmarks.viewer",
        "HTML viewer frame time in headless Chromium on 10^4 and 10^5-instance maps",
    ),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description="Benchmark programs of icmapper (print measured numbers and ratios).",
    )
    sub = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK")
    for name, (_, help_text) in BENCHMARKS.items():
        p = sub.add_parser(
            name,
            help=help_text,
            add_help=False,  # `--help` goes to the benchmark's own parser
            prefix_chars="\0",  # no options here: every argument goes to the benchmark's parser
        )
        p.add_argument("args", nargs="*")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.benchmark is None:
        parser.print_help()
        return 2
    module = importlib.import_module(BENCHMARKS[args.benchmark][0])
    return int(module.main(list(args.args)) or 0)


if __name__ == "__main__":
    sys.exit(main())
