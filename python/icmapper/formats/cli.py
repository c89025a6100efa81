"""`icmapper export RUN_DIR --format FORMAT --out PATH`: a run's per-frame predictions as a
prediction file other tools read (docs/eval.md, "Prediction files")."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any


def run(args: argparse.Namespace) -> int:
    from icmapper.cliargs import output_file
    from icmapper.formats.export import export_run

    out = Path(args.out) if args.out else Path(args.run_dir) / f"predictions.{args.format}.json"
    if args.out:
        output_file(out, "--out")
    path = export_run(args.run_dir, out, args.format)
    print(f"wrote {path}")
    return 0


def register(subparsers: Any) -> None:
    """Adds the `export` sub-command."""
    from icmapper.formats import formats, formats_help

    writable = [n for n, f in formats().items() if f.write is not None]
    p = subparsers.add_parser(
        "export",
        help="write a run's per-frame predictions as a prediction file (icmapper, StreamMapNet)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Writes the per-frame predictions of a run folder (icmapper map / compare) "
        "in a prediction file format; frames are named by the source's tokens (docs/eval.md).",
        epilog="formats it writes (--format):\n"
        + formats_help(writable=True)
        + "\n\nread only (input of `map --detections file:PATH:FORMAT` and `eval`):\n"
        + formats_help(writable=False),
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run folder")
    p.add_argument("--format", default="icmapper", choices=writable)
    p.add_argument("--out", help="output file (default RUN_DIR/predictions.FORMAT.json)")
    p.set_defaults(func=run)
