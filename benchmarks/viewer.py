"""Frame time of the HTML map viewer on large maps (``python -m benchmarks viewer``): prints
measured numbers (never asserts).

For each map size (default 10^4 and 10^5 instances, a third of each class, first frames spread
over 200 frames) the viewer page (``icmapper.vis.viewer.write_viewer``) is loaded in headless
Chromium (the system's, driven by Playwright, as ``tests/test_vis_viewer.py`` does;
``ICMAPPER_CHROMIUM=PATH`` picks another build) and ``icmapperViewer.measure(n)`` animates ``n``
frames, each panning, zooming and moving the time slider: the median and 95th percentile of the
intervals between animation frames (requestAnimationFrame caps them at the display's 16.7 ms)
and the mean JavaScript time per draw, with the whole map in view and zoomed in 8x, and the time
until the page is ready.
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


def find_chromium() -> str | None:
    """The Chromium executable to drive: ``ICMAPPER_CHROMIUM`` when set, else ``chromium`` or
    ``chromium-browser`` on the PATH; None when there is none."""
    return os.environ.get("ICMAPPER_CHROMIUM") or next(
        (p for n in ("chromium", "chromium-browser") if (p := shutil.which(n))), None
    )


def big_map(n: int, frames: int, seed: int = 0) -> list[Any]:
    """n map items (``icmapper.vis.replay.MapItem``; a third of each class) scattered over a
    square of side 40 sqrt(n) m: crossings as 8 x 4 m ellipses of 12 points, polylines of 30-80
    points 1 m apart with a gentle wiggle; first frames uniform over ``frames``."""
    from icmapper.vis.replay import MapItem

    rng = np.random.default_rng(seed)
    side = float(np.sqrt(n)) * 40.0
    items = []
    for i in range(n):
        c = i % 3
        x0, y0 = rng.uniform(0.0, side, 2)
        if c == 0:
            a = np.linspace(0.0, 2 * np.pi, 13)[:-1]  # (12,)
            pts = np.stack([x0 + 4 * np.cos(a), y0 + 2 * np.sin(a)], 1)  # (12, 2)
        else:
            s = np.arange(int(rng.integers(30, 80)), dtype=np.float64)  # (m,)
            h = rng.uniform(0, 2 * np.pi)
            pts = np.stack([x0 + s * np.cos(h) + 2 * np.sin(s / 15),
                            y0 + s * np.sin(h) + 2 * np.cos(s / 13)], 1)  # fmt: skip
        first = int(rng.integers(0, frames))
        items.append(MapItem(i, c, pts, c == 0, first, min(frames - 1, first + 5), 3))
    return items


def _measure(browser: Any, path: Path, n_frames: int) -> dict[str, Any]:
    """Loads the page and animates it: ready time (s), the frame statistics of the whole map
    and zoomed in 8x, and the page's console errors."""
    page = browser.new_page(viewport={"width": 1280, "height": 820})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    t0 = time.perf_counter()
    page.goto(path.as_uri())
    page.wait_for_function("window.icmapperViewer && window.icmapperViewer.ready", timeout=300_000)
    ready = time.perf_counter() - t0
    whole = page.evaluate(f"icmapperViewer.measure({n_frames})")
    page.evaluate("icmapperViewer.zoom(8)")
    zoomed = page.evaluate(f"icmapperViewer.measure({n_frames})")
    page.close()
    return {"ready_s": ready, "whole": whole, "zoomed": zoomed, "errors": errors}


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks viewer [--sizes 10000 100000] [--frames 60]``."""
    ap = argparse.ArgumentParser(prog="python -m benchmarks viewer", description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--frames", type=int, default=60, help="animation frames measured per view")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    exe = find_chromium()
    if exe is None:
        print("no chromium executable (apt-get install chromium, or set ICMAPPER_CHROMIUM)")
        return 1
    from icmapper.vis.viewer import map_viewer_data, write_viewer
    from playwright.sync_api import sync_playwright

    print(f"headless {exe}, {os.cpu_count()} CPUs; {args.frames} animation frames per view, each "
          "panning, zooming and moving the slider; frame interval ms (median / p95) and mean "
          "JavaScript ms per draw")  # fmt: skip
    print(f"{'instances':>10} {'page MB':>8} {'ready s':>8} {'whole map':>22} {'zoomed 8x':>22}")
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--no-sandbox"])
        for n in args.sizes:
            items = big_map(n, 200, args.seed)
            path = write_viewer(map_viewer_data(items, f"{n} instances"), Path(tmp) / f"{n}.html")
            r = _measure(browser, path, args.frames)

            def cell(m: dict[str, float]) -> str:
                return f"{m['medianMs']:.1f} / {m['p95Ms']:.1f} / {m['meanDrawMs']:.1f}"

            print(
                f"{n:>10} {path.stat().st_size / 2**20:8.1f} {r['ready_s']:8.2f} "
                f"{cell(r['whole']):>22} {cell(r['zoomed']):>22}",
                flush=True,
            )
            if r["errors"]:
                print(f"  page errors: {r['errors'][:3]}")
        browser.close()
    return 0
