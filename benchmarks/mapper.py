"""Per-frame latency of the online mapper by stage (`python -m benchmarks mapper`).

Runs the full IC-Mapper pipeline (detector, association, tracking, sampling, fusion, merge) over
synthetic validation sequences with the shipped checkpoint (or a freshly initialised network of a
config when no checkpoint is given: the timings do not depend on the weights) and prints the mean
time of every stage and the share of the frame spent outside the networks.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from icmapper.checkpoints import DEFAULT_CHECKPOINT
from icmapper.mapping.mapper import NETWORK_STAGES, STAGES, Mapper


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks mapper", description=__doc__)
    p.add_argument("--checkpoint", default=None, help="training checkpoint (default: shipped)")
    p.add_argument("--config", default="configs/small.toml", help="config without a checkpoint")
    p.add_argument("--source", default="sim:val:2")
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args(argv)

    import torch
    from icmapper.data.sources import open_source

    torch.set_num_threads(args.threads)
    ckpt = args.checkpoint
    if ckpt is None and DEFAULT_CHECKPOINT.is_file():
        ckpt = str(DEFAULT_CHECKPOINT)
    if ckpt is None:
        ckpt = _fresh_checkpoint(args.config)
        print(f"(no checkpoint: timing a freshly initialised network of {args.config})")
    mapper = Mapper.from_checkpoint(ckpt)
    from icmapper.models.network import checkpoint_settings

    seqs = open_source(args.source, image_size=checkpoint_settings(ckpt)[1])
    totals = dict.fromkeys(STAGES, 0.0)
    frames = 0
    render = 0.0
    wall = time.perf_counter()
    for seq in seqs:
        mapper.reset()
        for i in range(len(seq)):
            t0 = time.perf_counter()
            frame = seq.frame(i)
            render += time.perf_counter() - t0
            mapper.step(frame)
        for k, v in mapper.stats.seconds.items():
            totals[k] += v
        frames += mapper.stats.frames
    wall = time.perf_counter() - wall - render
    step_total = sum(totals.values())
    print(f"source {args.source}: {frames} frames, {args.threads} thread(s), checkpoint {ckpt}")
    print(f"{'stage':<12} {'ms/frame':>9} {'share':>7}")
    for k in STAGES:
        print(f"{k:<12} {1e3 * totals[k] / frames:9.2f} {totals[k] / step_total:7.1%}")
    outside = sum(v for k, v in totals.items() if k not in NETWORK_STAGES)
    print(
        f"{'total':<12} {1e3 * step_total / frames:9.2f}   "
        f"(wall {1e3 * wall / frames:.2f} ms/frame)"
    )
    print(f"outside the networks: {outside / step_total:.1%} of the frame (target <= 10%)")
    print(f"(image rendering, not part of the mapper: {1e3 * render / frames:.2f} ms/frame)")
    return 0


def _fresh_checkpoint(config: str) -> str:
    import tempfile

    from icmapper.models.checkpoint import save_checkpoint
    from icmapper.models.network import ICMapperNet
    from icmapper.training.config import config_to_dict, load_config

    cfg = load_config(config)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    path = Path(tempfile.mkdtemp()) / "fresh.pt"
    save_checkpoint(
        path, model=net.state_dict(), optimizer=None, stage=1, step=0, config=config_to_dict(cfg)
    )
    return str(path)
