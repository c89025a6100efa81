"""`icmapper eval RUN_DIR [RUN_DIR ...]`: prints Tables 1-3 for runs, optionally writes JSON."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

from icmapper.atomic import atomic_open
from icmapper.eval.tracking import DEFAULT_SCORE_THRESHOLD


def _clean(x: Any) -> Any:
    """NaN / inf -> None / "inf" so the JSON is standard."""
    if isinstance(x, float):
        if math.isnan(x):
            return None
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return x
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x


def write_json(path: str | os.PathLike, results: list[dict]) -> None:
    """Writes {"format": "icmapper-eval", "version": 1, "runs": [...]} atomically."""
    path = Path(path)
    payload = {"format": "icmapper-eval", "version": 1, "runs": _clean(results)}
    with atomic_open(path) as fh:
        json.dump(payload, fh, indent=1)


def run(args: argparse.Namespace) -> int:
    from icmapper.city.manifest import is_city_run
    from icmapper.cliargs import output_file
    from icmapper.eval.evaluate import evaluate_predictions, evaluate_run
    from icmapper.eval.report import markdown
    from icmapper.eval.untracked import note

    if args.json:
        output_file(args.json, "--json")  # before the work, not after it
    mt = args.cmap in ("maptracker", "both")
    results = []
    for d in args.runs:
        if is_city_run(d):  # a city run: the city map against the cross-drive ground truth
            from icmapper.city.evaluate import city_table, evaluate_city

            city = evaluate_city(d)
            print(city_table(city))
            results.extend(city["drives"])
            continue
        if d.startswith("file:"):
            if not args.source:
                raise ValueError(f"{d}: evaluating a prediction file needs --source SPEC")
            r = evaluate_predictions(d, args.source, args.score_threshold, maptracker=mt)
            if (line := note(r)) is not None:
                print(line, file=sys.stderr)
        else:
            r = evaluate_run(d, score_threshold=args.score_threshold, maptracker=mt)
        results.append(r)
    print(markdown(results, cmap=args.cmap), end="")
    if args.json:
        write_json(args.json, results)
    return 0


def register(subparsers: Any) -> None:
    """Adds the `eval` sub-command."""
    p = subparsers.add_parser(
        "eval",
        help="evaluate run folders (detection AP, C-mAP, tracking, global map)",
        description="Evaluates run folders against ground truth recomputed from their source and "
        "prints markdown tables (one row per run); see docs/eval.md.",
    )
    p.add_argument(
        "runs",
        nargs="+",
        metavar="RUN_DIR",
        help="run folder(s), or prediction files as file:PATH[:FORMAT][:RANGE] (with --source)",
    )
    p.add_argument("--source", help="the source spec prediction files are evaluated on")
    p.add_argument(
        "--cmap",
        choices=("icmapper", "maptracker", "both"),
        default="icmapper",
        help="C-mAP definition in Table 1: icmapper's (the method's track ids, default), "
        "MapTracker's (ids re-derived from the predictions, score > 0.4; docs/eval.md) or both",
    )
    p.add_argument(
        "--json", metavar="PATH", help="also write the numbers as JSON (in an existing folder)"
    )
    p.add_argument(
        "--score-threshold",
        type=float,
        default=DEFAULT_SCORE_THRESHOLD,
        help=f"tracking uses predictions with score >= this (default {DEFAULT_SCORE_THRESHOLD})",
    )
    p.set_defaults(func=run)
