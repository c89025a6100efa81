"""The `icmapper` command line: a thin dispatcher.

Each feature module owns its sub-commands through a ``register(subparsers)`` function that adds
parsers whose ``func`` attribute runs the command; this module only wires them together.
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
    "icmapper.bench",  # bench geometry | render | eval | mapper
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="icmapper",
        description="Online vectorised HD-map construction (IC-Mapper).",
    )
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
