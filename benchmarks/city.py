"""City run wall time: the same drives of one synthetic city mapped and merged in-process and on
Ray with 1 and 2 workers (local instance), in one run.

``python -m benchmarks city [--drives 16] [--workers 1 2] [--method post-track]
[--detections oracle:low | learned [--checkpoint PATH]]``

Oracle detections (no network; about 0.4 s of work per drive) by default; ``--detections
learned`` maps with the learned detector of ``--checkpoint`` (default: the shipped
``icmapper.checkpoints.DEFAULT_CHECKPOINT``; images rendered per frame, seconds of work per drive,
the network loaded once per Ray worker), at the checkpoint's image size, on the CPU. Each setting
runs in its own temporary city folder; prints the wall time of each and the speed-up over
in-process, and checks that every setting gives the same city map (native bytes). Ray's start-up
is part of each Ray setting's time (as a user sees it).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    from icmapper._icmap import GlobalMap
    from icmapper.city.drives import CitySettings
    from icmapper.city.run import build_city
    from icmapper.mapping.config import MapperConfig

    ap = argparse.ArgumentParser(prog="python -m benchmarks city", description=__doc__)
    ap.add_argument("--drives", type=int, default=16)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--method", default="icmapper")
    ap.add_argument("--city", default="val:0", help="SPLIT:INDEX of the synthetic city")
    ap.add_argument(
        "--detections", default="oracle:low", help="oracle:PRESET (default oracle:low) or learned"
    )
    ap.add_argument(
        "--checkpoint", default=None, help="learned detector (default: the shipped checkpoint)"
    )
    args = ap.parse_args(argv)
    spec = f"sim-city:{args.city}:{args.drives}"
    if args.detections == "learned":
        from icmapper.checkpoints import DEFAULT_CHECKPOINT
        from icmapper.models.network import checkpoint_settings

        ckpt = str(args.checkpoint or DEFAULT_CHECKPOINT)
        config = MapperConfig.for_checkpoint(ckpt)  # as `icmapper map --city` maps
        settings = CitySettings(
            args.method, "learned", ckpt, config.to_dict(), checkpoint_settings(ckpt)[1]
        )
    elif args.detections.startswith("oracle"):
        settings = CitySettings(
            args.method, args.detections, None, MapperConfig().to_dict(), (32, 88)
        )
    else:
        ap.error(f"--detections must be oracle[:PRESET] or learned, got {args.detections!r}")
    results: dict[str, tuple[float, bytes]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for workers in [0, *args.workers]:
            name = "in-process" if workers == 0 else f"ray x{workers}"
            city = Path(tmp) / name.replace(" ", "")
            t0 = time.perf_counter()
            m = build_city(city, [spec], settings, "60x30", workers=workers, pictures=False,
                           log=lambda *_: None)  # fmt: skip
            dt = time.perf_counter() - t0
            ok = len(m.ok_drives())
            results[name] = (dt, GlobalMap.load(str(city / "city.icmap")).to_bytes())
            print(
                f"{name:>11}: {dt:7.1f} s  ({ok}/{len(m.drives)} drives, {args.method}, "
                f"{settings.detections})"
            )
    base = results["in-process"][0]
    for name, (dt, data) in results.items():
        same = data == results["in-process"][1]
        print(f"{name:>11}: speed-up {base / dt:4.2f}x  same city map: {same}")
    return 0
