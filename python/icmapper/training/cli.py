"""``icmapper train --config PATH [--set TABLE.KEY=VALUE ...] [--stage 1|2] [--resume] [--out DIR]
[--max-steps N]``.

``--set`` overrides one config value (repeatable), e.g. ``--set data.image_size=[64,176]
--set model.channels=32 --set data.source="nuscenes:/data/nuscenes:train"``; values are TOML.

Runs under torchrun for DDP (``torchrun --nproc_per_node N -m icmapper train ...``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from icmapper.training.config import TrainConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the ``train`` command."""
    p = subparsers.add_parser("train", help="train the networks (stage 1 or 2)")
    p.add_argument("--config", required=True, type=Path, help="TOML config (configs/small.toml)")
    p.add_argument(
        "--set",
        action="append",
        metavar="TABLE.KEY=VALUE",
        help="override a config value (repeatable; TOML value), e.g. data.image_size=[64,176]",
    )
    p.add_argument("--stage", type=int, choices=(1, 2), default=1)
    p.add_argument("--resume", action="store_true", help="continue OUT/stage{n}.pt")
    p.add_argument("--out", type=Path, default=Path("runs/train"), help="output folder")
    p.add_argument("--max-steps", type=int, default=None, help="stop after N steps in all")
    p.add_argument(
        "--init",
        type=Path,
        default=None,
        help="stage 2: stage-1 checkpoint (or a trained one, with stage2.fresh_fusion: its "
        "fusion starts afresh); stage 1: weights to fine-tune (or, with "
        "stage1.freeze_encoder, the encoder); a checkpoint of another BEV grid is resampled "
        "to this config's (models.checkpoint.regrid_state)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--fill-cache",
        metavar="I/N",
        default=None,
        help="only render the frames of data.source into data.cache_dir (shard I of N, e.g. "
        "0/2 and 1/2 in two processes) and exit; interruptible, a later call goes on",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from icmapper.training.config import load_config
    from icmapper.training.distributed import cleanup, init_distributed
    from icmapper.training.loop import train

    if args.max_steps is not None and args.max_steps < 0:
        raise ValueError("--max-steps must be >= 0")
    from icmapper.settings import parse_assignments

    cfg = load_config(args.config, parse_assignments(args.set or []))
    if args.fill_cache is not None:
        return fill_cache(cfg, args.fill_cache)
    info = init_distributed()
    try:
        result = train(
            cfg,
            args.stage,
            args.out,
            resume=args.resume,
            max_steps=args.max_steps,
            init=args.init,
            progress=not args.no_progress,
        )
    finally:
        cleanup()
    print(f"rank {info.rank}/{info.world_size}: parameter digest {result['param_digest']}")
    if info.is_main:
        print(f"stage {args.stage}: {result['step']} steps; checkpoint {result['checkpoint']}")
        if result["losses"]:
            print("last losses: " + ", ".join(f"{k}={v:.4f}" for k, v in result["losses"].items()))
    return 0


def fill_cache(cfg: TrainConfig, shard_spec: str) -> int:
    """``--fill-cache I/N``: renders data.source's frames into data.cache_dir."""
    from icmapper.data.datasets import ImageCache
    from icmapper.training.loop import training_sequences

    try:
        shard, num = (int(v) for v in shard_spec.split("/"))
    except ValueError:
        raise ValueError(f"--fill-cache must be I/N (e.g. 0/2), got {shard_spec!r}") from None
    if not cfg.data.cache_dir:
        raise ValueError("--fill-cache needs data.cache_dir in the config (or --set)")
    seqs = training_sequences(cfg)
    n = ImageCache(cfg.data.cache_dir).fill(seqs, shard, num, log=print)
    print(f"cache {cfg.data.cache_dir}: {n} frames rendered (shard {shard}/{num})")
    return 0
