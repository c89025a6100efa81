"""`icmapper map` and `icmapper compare`: run mapping methods over a source and write run folders,
global maps (native file, GeoJSON, PNG beside the ground truth) and paper-style tables."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from icmapper.atomic import write_text_atomic
from icmapper.cliargs import add_size_option
from icmapper.data.sources import resolve_spec, source_tag

if TYPE_CHECKING:
    from icmapper.mapping.config import MapperConfig

from icmapper.checkpoints import DEFAULT_CHECKPOINT


def _open(spec: str, image_size: tuple[int, int], seed: int, render: bool) -> list[Any]:
    from icmapper.data.sources import open_source

    return open_source(spec, image_size=image_size, seed=seed, render=render)


def _image_size(args: argparse.Namespace) -> tuple[int, int]:
    if args.image_size:
        return tuple(args.image_size)  # type: ignore[return-value]
    if args.detections == "learned" and args.checkpoint:
        from icmapper.models.network import checkpoint_settings

        return checkpoint_settings(args.checkpoint)[1]
    return (64, 176)


def mapper_config(args: argparse.Namespace) -> MapperConfig:
    """The run's ``MapperConfig``: the defaults (with the learned detector, its checkpoint's
    detection threshold and ``[mapper]`` settings), then the named flags, then ``--set NAME=VALUE``
    items."""
    from icmapper.mapping.config import CLI_FLAGS, MapperConfig
    from icmapper.settings import parse_assignments

    base = MapperConfig()
    if args.detections == "learned" and args.checkpoint:
        base = MapperConfig.for_checkpoint(args.checkpoint)
    table: dict[str, Any] = {
        name: getattr(args, name) for name in CLI_FLAGS if getattr(args, name) is not None
    }
    table.update(parse_assignments(args.set or []))
    return MapperConfig.from_dict(table, base)


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
    config: MapperConfig | None = None,
) -> list[Path]:
    """Runs ``methods`` on the sequences of ``source``, all under one ``config``; one run folder
    per method under ``out`` (with the config it ran with: ``mapper_config.json``). Returns the
    run folders."""
    from icmapper.data import gt as gt_mod
    from icmapper.eval.runfmt import RunWriter
    from icmapper.georef import write_map_geojsons
    from icmapper.mapping.config import MapperConfig
    from icmapper.mapping.plot import plot_global_maps
    from icmapper.mapping.run import DetectionInput, map_sequence, method_factory
    from icmapper.progress import progress as progress_bar

    inp = DetectionInput.parse(detections, checkpoint, device, seed)
    rng = range_of_detections(inp)
    seqs = _open(source, image_size, seed, render=inp.needs_images)
    if not seqs:
        raise ValueError(f"source {source!r} has no sequences")
    inp.match(source, seqs)  # a prediction file's frames against the source's
    factories = {m: method_factory(m, inp, rng, config) for m in methods}
    run_dirs = [out / m for m in methods]
    for d in run_dirs:
        if (d / "run.json").exists():
            raise FileExistsError(f"{d} already holds a run; choose another --out or remove it")
    inp.note_image_domain(seqs)
    stored = resolve_spec(source)  # run.json names the data from any working folder
    writers = {m: RunWriter(d, m, stored, rng) for m, d in zip(methods, run_dirs, strict=True)}
    total = sum(len(s) for s in seqs) * len(methods)
    bar = progress_bar(total, f"mapping {source}", unit="frame", enabled=progress)
    timings: dict[str, float] = {m: 0.0 for m in methods}
    for seq in seqs:
        records = None
        for m in methods:
            method, recorder = factories[m](seq, records)
            bar.set_postfix_str(f"{seq.name} {m}")
            t0 = time.perf_counter()
            frames, gmap = map_sequence(method, seq, inp.needs_images, bar)
            timings[m] += time.perf_counter() - t0
            if recorder is not None and records is None:
                records = recorder.records
            writers[m].add_sequence(seq.name, frames, gmap)
            write_map_geojsons(gmap, out / m / seq.name, seq.world.geo)  # local (+ WGS84)
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
        used = config if config is not None else MapperConfig()
        write_text_atomic(out / m / "mapper_config.json", json.dumps(used.to_dict(), indent=1))
        n = sum(len(s) for s in seqs)
        (out / m / "timing.json").write_text(
            json.dumps({"frames": n, "seconds": timings[m], "ms_per_frame": 1e3 * timings[m] / n})
        )
    return run_dirs


def range_of_detections(inp: Any) -> Any:
    """The perception range of a run (``DetectionInput.perception_range``)."""
    return inp.perception_range()


def _run_methods_of(
    args: argparse.Namespace, methods: list[str], source: str, out: Path, config: MapperConfig
) -> list[Path]:
    """``run_methods`` with the detections, checkpoint, image size, seed, device and progress
    that `map` and `compare` take from their common options."""
    return run_methods(
        methods,
        source,
        out,
        args.detections,
        args.checkpoint,
        _image_size(args),
        args.seed,
        args.device,
        not args.no_progress,
        config=config,
    )


def cmd_map(args: argparse.Namespace) -> int:
    from icmapper.city.cli import workers_note
    from icmapper.cliargs import output_folder

    if args.city:
        output_folder(args.city, "--city")
        from icmapper.city.cli import cmd_city

        return cmd_city(args, mapper_config(args), _image_size(args))
    if len(args.source) != 1:
        raise ValueError("map takes one --source (several only with --city)")
    note = workers_note(args.workers, city=False)
    if note is not None:
        print(note, file=sys.stderr)
    if not args.out:
        raise ValueError("map needs --out (or --city for a city run)")
    output_folder(args.out, "--out")
    _run_methods_of(args, [args.method], args.source[0], Path(args.out), mapper_config(args))
    print(f"wrote {Path(args.out) / args.method}")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from icmapper.cliargs import output_folder
    from icmapper.eval.cli import write_json
    from icmapper.eval.evaluate import evaluate_run
    from icmapper.eval.report import markdown
    from icmapper.mapping.methods import method

    methods = args.methods.split(",") if args.methods else list(_default_methods(args))
    for m in methods:
        method(m)  # ValueError naming the known methods
    config = mapper_config(args)
    out = output_folder(args.out, "--out")
    report = []
    all_results = []
    for source in args.source:
        sub = out / source_tag(source)
        dirs = _run_methods_of(args, methods, source, sub, config)
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
    title = f"# icmapper compare ({args.detections} detections)\n\n"
    write_text_atomic(out / "report.md", title + "\n".join(report))
    write_json(out / "results.json", all_results)
    print(f"wrote {out / 'report.md'}", file=sys.stderr)
    return 0


def _default_methods(args: argparse.Namespace) -> tuple[str, ...]:
    """Every registered method; without the learned detector, those distinct without it."""
    from icmapper.mapping.methods import methods

    learned = args.detections == "learned"
    return tuple(n for n, info in methods().items() if learned or info.distinct_without_learned)


def _common(p: argparse.ArgumentParser, required_out: bool = True) -> None:
    p.add_argument(
        "--detections",
        default="learned",
        help="'learned' (the checkpoint's detector), 'oracle[:none|low|medium|high]' (noisy GT) "
        "or 'file:PATH[:FORMAT][:RANGE]' (a prediction file; formats below, docs/eval.md)",
    )
    p.add_argument(
        "--checkpoint",
        default=str(DEFAULT_CHECKPOINT) if DEFAULT_CHECKPOINT.is_file() else None,
        help="training checkpoint (default: icmapper.checkpoints.DEFAULT_CHECKPOINT)",
    )
    p.add_argument("--out", required=required_out, help="output folder")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the synthetic drives' rendering and of the oracle's noise (default 0)",
    )
    p.add_argument(
        "--device", default="cpu", help="torch device of the learned networks (cpu, cuda, ...)"
    )
    add_size_option(
        p,
        "--image-size",
        None,
        "camera image size (default: the checkpoint's with --detections learned, else 64 176)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar or lines")
    from icmapper.mapping.config import CLI_FLAGS, MapperConfig

    helps = MapperConfig.help()
    kinds = {f.name: f.type for f in fields(MapperConfig)}
    g = p.add_argument_group("mapping settings (icmapper.mapping.config.MapperConfig)")
    for name in CLI_FLAGS:
        typ = {"int": int, "float": float}[str(kinds[name])]
        g.add_argument("--" + name.replace("_", "-"), dest=name, type=typ, help=helps[name])
    g.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help="any MapperConfig setting (repeatable): "
        + "; ".join(f"{n}: {h}" for n, h in helps.items() if n not in CLI_FLAGS),
    )


def register(subparsers: Any) -> None:
    from icmapper.data.sources import sources_help
    from icmapper.formats import formats_help
    from icmapper.mapping.methods import methods

    epilog = (
        "sources:\n"
        + sources_help()
        + "\n\nmethods:\n"
        + "\n".join(f"  {n:<24} {i.help}" for n, i in methods().items())
        + "\n\nprediction file formats (--detections file:PATH[:FORMAT]):\n"
        + formats_help()
    )

    def add_parser(name: str, summary: str, description: str) -> argparse.ArgumentParser:
        """A sub-command that lists the sources, methods and formats after its options."""
        return subparsers.add_parser(
            name,
            help=summary,
            formatter_class=argparse.RawDescriptionHelpFormatter,
            epilog=epilog,
            description=description,
        )

    p = add_parser(
        "map",
        "build global maps of a source's sequences with one method",
        "Runs one mapping method over sim:SPLIT[:N] | av2:PATH | nuscenes:PATH and writes a run "
        "folder (docs/eval.md), the global maps (.icmap, .geojson) and PNGs.",
    )
    known = methods()
    p.add_argument(
        "--source",
        action="append",
        required=True,
        help="a source spec (listed below); repeatable with --city",
    )
    p.add_argument(
        "--method",
        default="icmapper",
        choices=list(known),
        metavar="METHOD",
        help="the mapping method (default icmapper; the methods are listed below)",
    )
    _common(p, required_out=False)
    from icmapper.city.cli import add_city_arguments

    add_city_arguments(p)
    p.set_defaults(func=cmd_map)

    c = add_parser(
        "compare",
        "run IC-Mapper and the baselines on the same sequences and print the tables",
        "Runs every method on the same sequences of each --source, evaluates them and prints "
        "detection, tracking and mapping tables (also OUT/report.md, results.json).",
    )
    c.add_argument("--source", action="append", required=True, help="repeatable")
    c.add_argument("--methods", help=f"comma-separated subset of {','.join(known)}")
    _common(c)
    c.set_defaults(func=cmd_compare)
