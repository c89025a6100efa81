"""What the finished map's check (``MapperConfig.verify``, ``mapping.verify``) takes off a drive's
map, drawn: IC-Mapper (shipped checkpoint) maps each drive of a source without the check, the
check's verdict on that map is computed, and the drive where it changes most (or ``--drive``) is
drawn over its ground truth (faint): instances kept (class colours), removed (red, thick), ends
cut off (magenta, thick), the ego path dashed.

    .venv/bin/python scripts/plot_verify.py --source sim:val:12 --out docs/verify.png

Uses ``scripts/map_experiment.py``'s BEV cache (the encoder runs once per frame and checkpoint).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from icmapper.checkpoints import DEFAULT_CHECKPOINT
    from icmapper.data import gt as gt_mod
    from icmapper.data.sources import open_source
    from icmapper.mapping.mapper import Mapper
    from icmapper.mapping.verify import check
    from icmapper.models.network import checkpoint_settings
    from icmapper.models.vectorise import VectoriseParams
    from map_experiment import CachedBev, bev_cache_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", default="sim:val:12")
    ap.add_argument("--drive", default=None, help="the drive to draw (default: most changed)")
    ap.add_argument("--checkpoint", default=str(DEFAULT_CHECKPOINT))
    ap.add_argument("--cache", default="/tmp/icmapper-bev-cache")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)

    image_size = checkpoint_settings(a.checkpoint)[1]
    seqs = open_source(a.source, image_size=image_size)
    if a.drive is not None:
        seqs = [s for s in seqs if s.name == a.drive]
        if not seqs:
            raise SystemExit(f"{a.source} has no drive {a.drive!r}")
    mapper = Mapper.from_checkpoint(a.checkpoint)
    config = mapper.config  # the shipped settings, the check's included
    cache = bev_cache_dir(a.cache, mapper.source.detector, image_size, a.source)
    src = CachedBev(mapper.source, cache, VectoriseParams())
    mapper.source = src
    best = None
    for seq in seqs:
        cached = src.load(seq.name)
        mapper.reset()
        seen = []  # per frame: (pose, detections)
        for i in range(len(seq)):
            frame = seq.frame(i, with_images=not cached)
            seen.append((np.asarray(frame.pose, np.float64), mapper.step(frame).detections))
        if not cached:
            src.save(seq.name)
        gmap = mapper.finish()
        verdict = check(gmap, seen, replace(config, verify=True), mapper.rng)
        n_removed, n_cut = len(verdict.removed), len(verdict.trimmed)
        print(f"{seq.name}: {n_removed} removed, {n_cut} cut", file=sys.stderr)
        if best is None or n_removed + n_cut > best[0]:
            best = (n_removed + n_cut, seq, type(gmap).from_bytes(gmap.to_bytes()), verdict)
    assert best is not None
    _, seq, gmap, verdict = best
    draw(gmap, verdict, gt_mod.global_gt(seq, mapper.rng), seq.poses, Path(a.out), seq.name)
    print(f"wrote {a.out} ({seq.name})")
    return 0


def draw(gmap, verdict, gt, poses, out: Path, name: str) -> str:  # noqa: ANN001 - plain data
    """Writes the picture (module docstring) to ``out``; returns its title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from icmapper.mapping.plot import CLASS_COLOURS, save_figure

    xy = np.concatenate([np.asarray(g.points) for g in gt] + [np.asarray(poses)[:, :2, 3]])
    w, h = np.ptp(xy, axis=0) + 20.0  # metres, with a margin
    fig, ax = plt.subplots(figsize=(12, 7) if w >= h else (8, 10))
    for g in gt:
        p = np.asarray(g.points)
        p = np.vstack([p, p[:1]]) if g.closed else p
        ax.plot(p[:, 0], p[:, 1], color="0.85", lw=4, solid_capstyle="round", zorder=1)
    for i in gmap.ids().tolist():
        cls, pts = gmap.get(int(i))
        pts = np.asarray(pts)
        closed = int(cls) == 0
        if i in verdict.removed:
            p = np.vstack([pts, pts[:1]]) if closed else pts
            ax.plot(p[:, 0], p[:, 1], color="red", lw=2.2, zorder=3)
            continue
        a, b = verdict.trimmed.get(int(i), (0, len(pts)))
        for lo, hi in ((0, a + 1), (b - 1, len(pts))):
            if hi - lo >= 2:
                ax.plot(pts[lo:hi, 0], pts[lo:hi, 1], color="magenta", lw=2.2, zorder=3)
        p = np.vstack([pts, pts[:1]]) if closed else pts[a:b]
        ax.plot(p[:, 0], p[:, 1], color=CLASS_COLOURS[int(cls)], lw=1.2, zorder=2)
    traj = np.asarray(poses)[:, :2, 3]
    ax.plot(traj[:, 0], traj[:, 1], color="0.5", lw=0.8, ls="--", zorder=2)
    handles = [plt.Line2D([], [], color="0.85", lw=4, label="ground truth")]
    handles += [
        plt.Line2D([], [], color=c, label=f"kept {n}")
        for c, n in zip(CLASS_COLOURS, ("crossing", "divider", "boundary"), strict=True)
    ]
    handles += [
        plt.Line2D([], [], color="red", lw=2.2, label="removed: in view, not detected"),
        plt.Line2D([], [], color="magenta", lw=2.2, label="end cut: in view, not detected"),
        plt.Line2D([], [], color="0.5", ls="--", label="ego path"),
    ]
    ax.legend(handles=handles, loc="best", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("world x (m)")
    ax.set_ylabel("world y (m)")
    title = (
        f"IC-Mapper on {name}: the finished map checked against the drive's own detections\n"
        f"({len(verdict.removed)} instances removed, {len(verdict.trimmed)} with ends cut)"
    )
    ax.set_title(title)
    fig.tight_layout()
    save_figure(fig, out)
    return title


if __name__ == "__main__":
    sys.exit(main())
