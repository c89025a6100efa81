"""`icmapper map` and `icmapper compare`: run mapping methods over a source and write run folders,
global maps (native file, GeoJSON, PNG beside the ground truth) and paper-style tables."""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Any

from icmapper.checkpoints import DEFAULT_CHECKPOINT
from icmapper.mapping.run import METHODS


def _source_tag(spec: str) -> str:
    kind = spec.split(":", 1)[0]
    rest = spec.split(":", 1)[1] if ":" in spec else ""
    if kind in ("av2", "nuscenes", "av2-drives"):
        rest = Path(rest.split(":")[0]).name or "data"
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", f"{kind}-{rest}").strip("-")


def _open(spec: str, image_size: tuple[int, int], seed: int, render: bool) -> list[Any]:
    from icmapper.data.sources import open_source

    return open_source(spec, image_size=image_size, seed=seed, render=render)


def _image_size(args: argparse.Namespace) -> tuple[int, int]:
    if args.image_size:
        return tuple(args.image_size)  # type: ignore[return-value]
    if args.detections == "learned" and args.checkpoint:
        from icmapper.training.checkpoint import load_checkpoint
        from icmapper.training.config import config_from_dict

        cfg = config_from_dict(load_checkpoint(args.checkpoint)["config"])
        return tuple(cfg.data.image_size)  # type: ignore[return-value]
    return (64, 176)


def run_methods(
    methods: list[str],
    source: str,
    out: Path,
    detections: str,
    checkpoint: str | None,
    image_size: tuple[int, int],
    seed: int = 0,
    device: str = "cpu",
    progress: bool = True,
    pictures: bool = True,
) -> list[Path]:
    """Runs ``methods`` on the sequences of ``source``; one run folder per method under ``out``.
    Returns the run folders."""
    from tqdm import tqdm

    from icmapper.data import gt as gt_mod
    from icmapper.eval.runfmt import RunWriter
    from icmapper.mapping.plot import plot_global_maps
    from icmapper.mapping.run import DetectorSpec, map_sequence, method_factory
    from icmapper.training.config import config_from_dict  # noqa: F401  (fail early if torch missing)

    spec = DetectorSpec.parse(detections, checkpoint, device, seed)
    rng = _range_of(spec)
    seqs = _open(source, image_size, seed, render=spec.needs_images)
    if not seqs:
        raise ValueError(f"source {source!r} has no sequences")
    factories = {m: method_factory(m, spec, rng) for m in methods}
    out.mkdir(parents=True, exist_ok=True)
    run_dirs = []
    writers = {}
    for m in methods:
        d = out / m
        if (d / "run.json").exists():
            raise FileExistsError(f"{d} already holds a run; choose another --out or remove it")
        writers[m] = RunWriter(d, m, source, rng)
        run_dirs.append(d)
    total = sum(len(s) for s in seqs) * len(methods)
    bar = tqdm(total=total, desc=f"mapping {source}", unit="frame", disable=not progress)
    timings: dict[str, float] = {m: 0.0 for m in methods}
    for seq in seqs:
        records = None
        for m in methods:
            method, recorder = factories[m](seq, records)
            bar.set_postfix_str(f"{seq.name} {m}")
            t0 = time.perf_counter()
            frames, gmap = map_sequence(method, seq, spec.needs_images, bar)
            timings[m] += time.perf_counter() - t0
            if recorder is not None and records is None:
                records = recorder.records
            writers[m].add_sequence(seq.name, frames, gmap)
            gmap.to_geojson(str(out / m / f"{seq.name}.geojson"))
            if pictures:
                plot_global_maps(
                    gmap,
                    gt_mod.global_gt(seq, rng),
                    seq.poses,
                    out / m / f"{seq.name}.png",
                    title=f"{m} on {seq.name}",
                )
    bar.close()
    for m in methods:
        writers[m].close()
        n = sum(len(s) for s in seqs)
        (out / m / "timing.json").write_text(
            json.dumps({"frames": n, "seconds": timings[m], "ms_per_frame": 1e3 * timings[m] / n})
        )
    return run_dirs


def _range_of(spec: Any) -> Any:
    from icmapper.data.types import RANGE_60x30

    if spec.checkpoint:
        from icmapper.training.checkpoint import load_checkpoint
        from icmapper.training.config import config_from_dict

        return config_from_dict(load_checkpoint(spec.checkpoint)["config"]).perception_range
    return RANGE_60x30


def cmd_map(args: argparse.Namespace) -> int:
    run_methods(
        [args.method],
        args.source,
        Path(args.out),
        args.detections,
        args.checkpoint,
        _image_size(args),
        args.seed,
        args.device,
        not args.no_progress,
    )
    print(f"wrote {Path(args.out) / args.method}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from icmapper.eval.cli import write_json
    from icmapper.eval.evaluate import evaluate_run
    from icmapper.eval.report import markdown

    methods = args.methods.split(",") if args.methods else list(_default_methods(args))
    out = Path(args.out)
    report = []
    all_results = []
    for source in args.source:
        sub = out / _source_tag(source)
        dirs = run_methods(
            methods,
            source,
            sub,
            args.detections,
            args.checkpoint,
            _image_size(args),
            args.seed,
            args.device,
            not args.no_progress,
        )
        seqs = _open(source, _image_size(args), args.seed, render=False)
        results = []
        for d in dirs:
            r = evaluate_run(d, sources=seqs)
            r["method"] = d.name
            timing = json.loads((d / "timing.json").read_text())
            r["ms_per_frame"] = timing["ms_per_frame"]
            results.append(r)
        text = f"## {source}\n\n{markdown(results)}"
        print(text)
        report.append(text)
        write_json(sub / "results.json", results)
        all_results.extend({**r, "source": source} for r in results)
    tmp = out / "report.md.tmp"
    tmp.write_text(f"# icmapper compare ({args.detections} detections)\n\n" + "\n".join(report))
    os.replace(tmp, out / "report.md")
    write_json(out / "results.json", all_results)
    print(f"wrote {out / 'report.md'}", file=sys.stderr)
    return 0


def _default_methods(args: argparse.Namespace) -> tuple[str, ...]:
    if args.detections == "learned":
        return METHODS
    return ("icmapper", "post-track", "vma", "cluster-fit", "polymerge")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--detections",
        default="learned",
        help="'learned' (the checkpoint's detector) or 'oracle[:none|low|medium|high]' (noisy GT)",
    )
    p.add_argument(
        "--checkpoint",
        default=str(DEFAULT_CHECKPOINT) if DEFAULT_CHECKPOINT.is_file() else None,
        help="training checkpoint (default: the shipped checkpoints/small.pt)",
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--image-size", type=int, nargs=2, metavar=("H", "W"))
    p.add_argument("--no-progress", action="store_true")


def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "map",
        help="build global maps of a source's sequences with one method",
        description="Runs one mapping method over sim:SPLIT[:N] | av2:PATH | nuscenes:PATH and "
        "writes a run folder (docs/eval.md), the global maps (.icmap, .geojson) and PNGs.",
    )
    p.add_argument("--source", required=True)
    p.add_argument("--method", default="icmapper", choices=METHODS)
    _common(p)
    p.set_defaults(func=cmd_map)

    c = subparsers.add_parser(
        "compare",
        help="run IC-Mapper and the baselines on the same sequences and print the tables",
        description="Runs every method on the same sequences of each --source, evaluates them "
        "and prints detection, tracking and mapping tables (also OUT/report.md, results.json).",
    )
    c.add_argument("--source", action="append", required=True, help="repeatable")
    c.add_argument("--methods", help=f"comma-separated subset of {','.join(METHODS)}")
    _common(c)
    c.set_defaults(func=cmd_compare)
