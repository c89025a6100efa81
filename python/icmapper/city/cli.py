"""`icmapper map --city CITY --source SPEC [--source SPEC ...]`: a city run (see city.run), and
`icmapper eval CITY` for one (city.evaluate)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from icmapper.city.manifest import MODES


def add_city_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("city runs (docs/mapping.md, 'City maps')")
    g.add_argument(
        "--city",
        metavar="CITY_DIR",
        help="map every drive of the sources into one city map in this folder (created, or "
        "extended with drives it does not hold yet)",
    )
    g.add_argument(
        "--city-mode",
        choices=(*MODES, "update"),
        default="merge",
        help="merge: drives mapped alone then merged by the engine (parallel with --workers); "
        "continue: one mapper continues the city map drive after drive; update: drives after "
        "the map was made: what changed is detected and the city map updated (changes.geojson)",
    )
    g.add_argument(
        "--workers",
        type=int,
        default=0,
        help="Ray workers for the drives (0: in-process, one drive after another)",
    )
    g.add_argument("--ray-address", default=None, help="join this Ray cluster (default: local)")


def workers_note(workers: int, city: bool) -> str | None:
    """What to say about ``--workers`` when it cannot take effect (None when it does): outside a
    city run it has no drives to spread; without Ray the drives run in-process."""
    from icmapper.city.ray_backend import INSTALL_HINT, ray_available

    if not workers:
        return None
    if not city:
        hint = "" if ray_available() else f" ({INSTALL_HINT})"
        return (
            f"note: --workers {workers} spreads the drives of a city run (--city) over Ray "
            f"workers; this run maps in-process{hint}"
        )
    if not ray_available():
        return f"note: {INSTALL_HINT}; mapping the drives in-process, one after another"
    return None


def cmd_city(args: argparse.Namespace, config: Any, image_size: tuple[int, int]) -> int:
    from icmapper.city.drives import CitySettings
    from icmapper.city.evaluate import city_table, evaluate_city
    from icmapper.city.run import build_city
    from icmapper.mapping.run import DetectionInput

    if args.city_mode == "update":
        return cmd_update(args, image_size)
    if args.detections.startswith("file:") and len(args.source) != 1:
        raise ValueError("a city run from a prediction file takes one --source")
    note = workers_note(args.workers, city=True)
    if note is not None:
        print(note, file=sys.stderr)
        args.workers = 0
    inp = DetectionInput.parse(args.detections, args.checkpoint, args.device, args.seed)
    settings = CitySettings(
        args.method, args.detections, args.checkpoint, config.to_dict(), image_size,
        args.seed, args.device,
    )  # fmt: skip
    manifest = build_city(
        Path(args.city),
        args.source,
        settings,
        inp.perception_range().name,
        mode=args.city_mode,
        workers=args.workers,
        ray_address=args.ray_address,
        progress=not args.no_progress,
    )
    ok = len(manifest.ok_drives())
    print(f"wrote {args.city}: city map of {ok} drive(s) ({len(manifest.drives) - ok} failed)")
    if ok:
        print(city_table(evaluate_city(args.city)), end="")
    return 0


def cmd_update(args: argparse.Namespace, image_size: tuple[int, int]) -> int:
    from icmapper.city.update_run import changes_table, update_city

    result = update_city(
        Path(args.city), args.source, args.detections, args.checkpoint, args.device,
        args.seed, image_size, progress=not args.no_progress,
    )  # fmt: skip
    print(changes_table(result), end="")
    print(f"wrote {result.folder} and {Path(args.city) / 'changes.geojson'}")
    return 0
