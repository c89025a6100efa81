"""`icmapper scenes ...`: look at data. `scenes preview` writes the preview PNG of one frame of a
synthetic city's drive (`--city`, `--drive`) or of any sequence a source spec names (`--source
SPEC --sequence I`, e.g. `--source av2:LOG_DIR`)."""

from __future__ import annotations

import argparse

from icmapper.cliargs import add_size_option
from icmapper.data.sources import SOURCE_KINDS
from icmapper.data.types import PerceptionRange


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `scenes` command and its `preview` sub-command."""
    scenes = subparsers.add_parser("scenes", help="inspect data sources (preview pictures)")
    sub = scenes.add_subparsers(dest="scenes_command", metavar="SUBCOMMAND")
    p = sub.add_parser(
        "preview", help="write the six cameras and the BEV ground truth of one frame to a PNG"
    )
    p.add_argument(
        "--source",
        default=None,
        metavar="SPEC",
        help="a source spec (default: the synthetic city --city, drive --drive); kinds: "
        + ", ".join(k.usage for k in SOURCE_KINDS.values()),
    )
    p.add_argument("--sequence", type=int, default=0, help="with --source: which sequence")
    p.add_argument("--city", type=int, default=10_003, help="city seed (val: 10000-10099)")
    p.add_argument("--drive", type=int, default=0, help="drive seed")
    p.add_argument("--frame", type=int, default=10, help="frame index (0 to the length - 1)")
    p.add_argument("--range", default="60x30", help="BEV perception range, e.g. 60x30 or 100x50")
    add_size_option(p, "--image-size", (128, 352), None)
    p.add_argument("--out", required=True, help="output PNG path (in an existing folder)")
    p.set_defaults(func=_preview)
    scenes.set_defaults(func=lambda args: (scenes.print_help(), 2)[1])


def _preview(args: argparse.Namespace) -> int:
    from icmapper.cliargs import check_frame, output_file
    from icmapper.data.preview import preview_png

    out_path = output_file(args.out, "--out")
    size = (int(args.image_size[0]), int(args.image_size[1]))
    if args.source is None:
        from icmapper.data.sim import sim_sequence

        seq = sim_sequence(args.city, args.drive, image_size=size)
    else:
        from icmapper.data.sources import open_source

        seqs = open_source(args.source, image_size=size)
        if not 0 <= args.sequence < len(seqs):
            raise ValueError(
                f"--sequence {args.sequence}: {args.source} has {len(seqs)} sequence(s)"
            )
        seq = seqs[args.sequence]
    check_frame(args.frame, len(seq), what=f"sequence {seq.name}")
    out = preview_png(seq, args.frame, out_path, PerceptionRange.from_name(args.range))
    print(f"wrote {out} ({seq.name}, frame {args.frame} of {len(seq)})")
    return 0
