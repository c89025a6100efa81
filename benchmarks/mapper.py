"""Per-frame latency of the online mapper by stage (`python -m benchmarks mapper`).

Runs the full IC-Mapper pipeline (detector, association, tracking, sampling, fusion, merge) over
synthetic validation sequences with the shipped checkpoint (or a freshly initialised network of a
config when no checkpoint is given: the timings do not depend on the weights) and prints the mean
time of every stage and the share of the frame spent outside the networks; the check of each
finished map against its drive (``mapping.verify``, as ``map_sequence`` runs it) is a stage of
its own, per frame of the drive.

The mapper times the detector as one stage; with ``model.instances = "segmentation"`` (the
shipped checkpoint) that stage includes the vectoriser that turns the masks into instances, which
is not the network. This benchmark times the vectoriser on its own (it wraps the ``vectorise`` the
detector calls: ``icmapper.models.vectorise.vectorise``, the engine's ``_icmap.vectorise``) and
reports it as a stage of its own, outside the networks, taken out of the detector's time.
``--vectoriser reference`` runs the former Python vectoriser
(``icmapper.testing.vectorise_reference``) in its place, for the share it took.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from icmapper.checkpoints import DEFAULT_CHECKPOINT
from icmapper.mapping.mapper import NETWORK_STAGES, STAGES, Mapper
from icmapper.mapping.verify import check


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks mapper", description=__doc__)
    p.add_argument("--checkpoint", default=None, help="training checkpoint (default: shipped)")
    p.add_argument("--config", default="configs/small.toml", help="config without a checkpoint")
    p.add_argument("--source", default="sim:val:2")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument(
        "--vectoriser",
        choices=("engine", "reference"),
        default="engine",
        help="the runtime's (the engine's) or the former Python one",
    )
    args = p.parse_args(argv)

    import torch
    from icmapper.data.sources import open_source

    torch.set_num_threads(args.threads)
    ckpt = args.checkpoint
    if ckpt is None and DEFAULT_CHECKPOINT.is_file():
        ckpt = str(DEFAULT_CHECKPOINT)
    from icmapper.models.network import checkpoint_settings

    label = ckpt  # what the report names: a fresh checkpoint's temporary file is gone by then
    with ExitStack() as stack:  # a fresh checkpoint's temporary folder goes once read
        if ckpt is None:
            ckpt = stack.enter_context(fresh_checkpoint(args.config))
            label = f"fresh weights of {args.config}"
            print(f"(no checkpoint: timing a freshly initialised network of {args.config})")
        mapper = Mapper.from_checkpoint(ckpt)
        image_size = checkpoint_settings(ckpt)[1]
    vectoriser = _time_vectoriser(reference=args.vectoriser == "reference")
    seqs = open_source(args.source, image_size=image_size)
    totals = dict.fromkeys(STAGES, 0.0)
    frames = 0
    render = 0.0
    wall = time.perf_counter()
    totals[VERIFY] = 0.0
    for seq in seqs:
        mapper.reset()
        seen = []  # per frame: (pose, detections), what the finished map is checked against
        for i in range(len(seq)):
            t0 = time.perf_counter()
            frame = seq.frame(i)
            render += time.perf_counter() - t0
            seen.append((frame.pose, mapper.step(frame).detections))
        t0 = time.perf_counter()
        if mapper.config.verify:  # what map_sequence does with the finished map
            gmap = mapper.finish()
            check(gmap, seen, mapper.config, mapper.rng).apply(gmap)
        totals[VERIFY] += time.perf_counter() - t0
        for k, v in mapper.stats.seconds.items():
            totals[k] += v
        frames += mapper.stats.frames
    wall = time.perf_counter() - wall - render
    step_total = sum(totals.values())
    print(
        f"source {args.source}: {frames} frames, {args.threads} thread(s), checkpoint {label}, "
        f"vectoriser {args.vectoriser}"
    )
    outside = print_stages(totals, vectoriser[0], frames)
    print(f"{'':<12} (wall {1e3 * wall / frames:.2f} ms/frame)")
    print(
        f"outside the networks: {outside / step_total:.1%} of the frame, the vectoriser "
        f"included (target <= 10%)"
    )
    print(f"(image rendering, not part of the mapper: {1e3 * render / frames:.2f} ms/frame)")
    return 0


#: The name of the vectoriser's stage in the printout.
VECTORISER = "vectorise"
#: The finished map's check against the drive (``mapping.verify``), per frame of the drive.
VERIFY = "verify"


def print_stages(totals: dict[str, float], vectorise_s: float, frames: int) -> float:
    """Prints ms/frame and the share of each mapper stage, the vectoriser (``vectorise_s``
    seconds, timed inside the "detector" stage) as its own stage, then the total; returns the
    time outside the networks (seconds). totals: stage -> seconds over ``frames`` frames."""
    step_total = sum(totals.values())
    stages = {"detector": totals["detector"] - vectorise_s, VECTORISER: vectorise_s}
    stages.update((k, totals[k]) for k in STAGES if k != "detector")
    stages.update((k, v) for k, v in totals.items() if k not in stages and k != "detector")
    print(f"{'stage':<12} {'ms/frame':>9} {'share':>7}")
    for k, v in stages.items():
        print(f"{k:<12} {1e3 * v / frames:9.2f} {v / step_total:7.1%}")
    print(f"{'total':<12} {1e3 * step_total / frames:9.2f}")
    return sum(v for k, v in stages.items() if k not in NETWORK_STAGES)


def _time_vectoriser(reference: bool = False) -> list[float]:
    """Wraps ``icmapper.models.detector.vectorise`` (the masks -> instances step the detector
    calls in segmentation mode) with a timer; returns a one-element list that accumulates its
    seconds. Nothing else changes: the wrapper returns what the vectoriser returns (with
    ``reference``, what the former Python vectoriser returns: the same instances)."""
    import icmapper.models.detector as detector

    spent = [0.0]
    inner = detector.vectorise
    if reference:
        from icmapper.testing.vectorise_reference import vectorise_reference

        inner = vectorise_reference

    def timed(*args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            spent[0] += time.perf_counter() - t0

    detector.vectorise = timed  # type: ignore[assignment]
    return spent


@contextmanager
def fresh_checkpoint(config: str) -> Iterator[str]:
    """A checkpoint of a freshly initialised network of ``config`` (its path), in a temporary
    folder that is removed on leaving the context (a paper-scale one is about 100 MB)."""
    import tempfile

    from icmapper.models.checkpoint import save_checkpoint
    from icmapper.models.network import ICMapperNet
    from icmapper.training.config import config_to_dict, load_config

    cfg = load_config(config)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    with tempfile.TemporaryDirectory(prefix="icmapper-fresh-") as folder:
        path = Path(folder) / "fresh.pt"
        weights, settings = net.state_dict(), config_to_dict(cfg)
        save_checkpoint(path, model=weights, optimizer=None, stage=1, step=0, config=settings)
        yield str(path)
