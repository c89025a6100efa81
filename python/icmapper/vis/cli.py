"""`icmapper vis` (per-frame pictures and a video of a run) and `icmapper view` (the interactive
HTML viewer of a run folder or a map file). Both only read: the run folder, its source (images and
ground truth, recomputed) and the map files."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from icmapper.cliargs import add_size_option
from icmapper.vis.replay import PICTURE_IMAGE_SIZE

#: Camera thumbnail size (H, W) in the viewer.
THUMB_SIZE = (64, 176)


def _size(text: list[int] | tuple[int, int]) -> tuple[int, int]:
    h, w = (int(v) for v in text)
    if h < 16 or w < 16:
        raise ValueError(f"--image-size must be at least 16 16, got {h} {w}")
    return h, w


def _frames(args: argparse.Namespace, n: int, name: str) -> list[int]:
    from icmapper.cliargs import check_frame

    if not args.frame:
        return list(range(n))
    return [check_frame(f, n, what=f"sequence {name}") for f in args.frame]


def cmd_vis(args: argparse.Namespace) -> int:
    from icmapper.cliargs import output_file, output_folder
    from icmapper.progress import progress
    from icmapper.vis.frame import frame_picture, overview_bounds, write_png
    from icmapper.vis.replay import open_replay
    from icmapper.vis.video import write_video

    if args.video:
        output_file(args.video, "--video")
    if args.out:
        output_folder(args.out, "--out")
    replay = open_replay(
        args.run, args.sequence, _size(args.image_size), with_source=not args.no_source
    )
    frames = _frames(args, len(replay), replay.name)
    bounds = overview_bounds(replay)
    out_dir = Path(args.out) if args.out else replay.run.path / "vis" / replay.name
    written: list[Path] = []
    pngs = not args.video or bool(args.frame)

    def pictures() -> Any:
        bar = progress(len(frames), f"pictures {replay.name}", unit="frame")
        for t in frames:
            img = frame_picture(replay, t, bounds)
            if pngs:
                written.append(write_png(img, out_dir / f"frame_{t:04d}.png"))
            bar.update(1)
            yield img
        bar.close()

    if args.video:
        path = write_video(pictures(), args.video, fps=args.fps)
        print(f"wrote {path} ({len(frames)} frames at {args.fps:g} fps)")
    else:
        for _ in pictures():
            pass
    if written:
        where = written[0] if len(written) == 1 else f"{len(written)} pictures in {out_dir}"
        print(f"wrote {where}")
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from icmapper.city.manifest import is_city_run
    from icmapper.cliargs import output_file
    from icmapper.vis.replay import load_map_items, open_replay
    from icmapper.vis.viewer import city_viewer_data, map_viewer_data, viewer_data, write_viewer

    if args.out:
        output_file(args.out, "--out")
    path = Path(args.path)
    if path.is_file() and path.suffix == ".icmap":
        data = map_viewer_data(load_map_items(path), f"map {path.name}")
        out = Path(args.out) if args.out else path.with_suffix(".html")
    elif path.is_dir() and is_city_run(path):  # the city map, its drives, the city's GT
        data = city_viewer_data(path, with_source=not args.no_source)
        out = Path(args.out) if args.out else path / "view-city.html"
    elif path.is_dir() and (path / "run.json").is_file():
        replay = open_replay(
            path,
            args.sequence,
            _size(args.thumb_size),
            with_source=not args.no_source,
            render=not args.no_thumbnails,
        )
        data = viewer_data(replay, thumbnails=not args.no_thumbnails)
        out = Path(args.out) if args.out else path / f"view-{replay.name}.html"
    elif path.is_dir():
        raise ValueError(
            f"{path} is not a run folder (no run.json in it) nor a city run (no city.json)"
        )
    else:
        raise ValueError(f"{path}: expected a run folder or a .icmap map file (or a city folder)")
    write_viewer(data, out)
    size = out.stat().st_size / 1e6
    print(f"wrote {out} ({len(data['map']['id'])} map instances, {size:.1f} MB, works offline)")
    return 0


def register(subparsers: Any) -> None:
    """Adds the `vis` and `view` sub-commands."""
    p = subparsers.add_parser(
        "vis",
        help="per-frame pictures (cameras with predictions, BEV, map so far) and a video of a run",
        description="Draws frames of one sequence of a run folder: the camera images with the "
        "frame's predictions projected through the cameras' geometry (class colours, track ids), "
        "a BEV panel with ground truth, the map so far and the predictions, and an overview of "
        "the drive. Images and ground truth are recomputed from the run's source spec. Without "
        "--frame every frame is drawn; --video writes them as an MP4 (imageio-ffmpeg) or a GIF.",
    )
    p.add_argument("run", metavar="RUN_DIR", help="a run folder (icmapper map / compare)")
    p.add_argument("--sequence", help="sequence name or position in the run (default: first)")
    p.add_argument(
        "--frame",
        type=int,
        action="append",
        metavar="N",
        help="frame to draw, 0 to the length - 1 (repeatable)",
    )
    p.add_argument("--out", help="folder of the PNGs (default RUN_DIR/vis/SEQUENCE)")
    p.add_argument(
        "--video",
        metavar="PATH",
        help="write a video (.mp4, or .gif) of the frames; its folder must exist",
    )
    p.add_argument("--fps", type=float, default=2.0, help="video frames per second (default 2)")
    add_size_option(p, "--image-size", PICTURE_IMAGE_SIZE, "camera image size in the picture")
    p.add_argument("--no-source", action="store_true", help="do not open the source: no "
                   "images or ground truth, predictions and map only")  # fmt: skip
    p.set_defaults(func=cmd_vis)

    v = subparsers.add_parser(
        "view",
        help="write an interactive, self-contained HTML viewer of a run or a map file",
        description="Writes one HTML file (data and code inline, no network) to scrub through a "
        "run: pan and zoom the global map, toggle classes, ground truth and predictions, move the "
        "time slider, click an instance for its id, class, observations, first/last frame and "
        "Chamfer distance to the nearest ground truth; per-class CD and GAP. A city run folder "
        "(icmapper map --city) gives the city map with the city's ground truth and a drive "
        "selector (each drive's frames and predictions). A .icmap file alone gives the map with "
        "its bookkeeping frames.",
    )
    v.add_argument(
        "path",
        metavar="RUN_DIR|CITY_DIR|MAP.icmap",
        help="a run folder, a city run folder or a native map file",
    )
    v.add_argument("--sequence", help="sequence name or position in the run (default: first)")
    v.add_argument(
        "--out",
        help="HTML path, in an existing folder (default RUN_DIR/view-SEQUENCE.html, "
        "CITY_DIR/view-city.html, MAP.html)",
    )
    v.add_argument("--no-thumbnails", action="store_true", help="leave out the camera images")
    add_size_option(v, "--thumb-size", THUMB_SIZE, "camera thumbnail size")
    v.add_argument("--no-source", action="store_true", help="do not open the source: no "
                   "images, ground truth or metrics")  # fmt: skip
    v.set_defaults(func=cmd_view)
