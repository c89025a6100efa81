"""The `icmapper` command line: a thin dispatcher.

Each feature module owns its sub-commands through a ``register(subparsers)`` function that adds
parsers whose ``func`` attribute runs the command; this module only wires them together.

The benchmark programs are not part of the installed package: they live in the repository's
``benchmarks/`` folder and run with ``python -m benchmarks NAME`` from the repository root.
``icmapper bench ...`` (their former command) exits with an error that says so.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# Feature modules that contribute sub-commands, in help order.
_COMMAND_MODULES = (
    "icmapper.data.cli",  # scenes preview
    "icmapper.training.cli",  # train
    "icmapper.mapping.cli",  # map, compare
    "icmapper.eval.cli",  # eval
    "icmapper.vis.cli",  # vis, view
    "icmapper.formats.cli",  # export
)

BENCH_MOVED = (
    "icmapper bench: the benchmarks are not part of the installed package; from a checkout of the "
    "repository run `python -m benchmarks geometry|render|eval|networks|mapper [options]` "
    "(see BENCHMARKS.md)"
)


def build_parser() -> argparse.ArgumentParser:
    from icmapper import __version__

    parser = argparse.ArgumentParser(
        prog="icmapper",
        description="Online vectorised HD-map construction (IC-Mapper).",
    )
    parser.add_argument("--version", action="version", version=f"icmapper {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # the feature is not part of this build yet
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    if (sys.argv[1:] if argv is None else argv)[:1] == ["bench"]:
        print(f"error: {BENCH_MOVED}", file=sys.stderr)
        return 2
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"icmapper {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
