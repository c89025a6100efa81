"""The whole pipeline at paper scale (`python -m benchmarks pipeline`).

Builds the ``Mapper`` with freshly initialised weights of ``configs/paper.toml`` (27.6 M parameters,
6 cameras x 480x800, BEV 100x50; the timings do not depend on the weights) on ``--device``, and runs
``--frames`` frames of one synthetic drive through ``Mapper.step``.

Fresh weights segment nothing, so the later stages would see no instances. The segmentation head
therefore still runs (its cost counts), but its output is **replaced by the frame's rasterised
ground truth** (``icmapper.models.segmentation.rasterise`` of ``data.gt.frame_gt``, as logits of
+-20): a realistic mask, so the vectoriser, association, tracking, fusion and merge see real
instances. The rasterisation is done before the step and is not timed. The association and
fusion networks keep their fresh weights: whether their scores link detections into tracks (and so
whether fusion and merge have work) depends on the weights' seed; with ``--seed 0`` (the default)
they do on ``sim:test:1`` (the printout counts the map's inserts and merges).

Prints ms/frame of the mapper's stages (``stats.seconds``), with the vectoriser taken out of the
detector stage as ``benchmarks mapper`` does (``detector`` is then the networks: encoder,
segmentation head and instance embeddings), and frames/s end to end (the sum of the stages; image
rendering, not part of the mapper, is printed apart). On the CPU a paper-scale frame takes seconds:
keep ``--frames`` small there.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import torch
from icmapper.mapping.mapper import STAGES, Mapper

from benchmarks.mapper import _time_vectoriser, fresh_checkpoint, print_stages

#: Logit magnitude of the ground-truth masks (sigmoid(20) = 1 - 2e-9).
GT_LOGIT = 20.0


class GroundTruthSeg(torch.nn.Module):
    """Wraps the detector's segmentation head: runs it, then returns ``target`` (1, K, X, Y)
    logits in its place (set per frame by the benchmark)."""

    def __init__(self, head: torch.nn.Module) -> None:
        super().__init__()
        self.head = head
        self.target: torch.Tensor | None = None

    def forward(self, bev: torch.Tensor) -> torch.Tensor:
        out = self.head(bev)
        if self.target is None:
            return out
        return self.target.to(device=out.device, dtype=out.dtype).expand_as(out)


def gt_logits(seq: Any, i: int, model: Any, rng: Any) -> torch.Tensor:
    """(1, K, X, Y) logits of frame i's rasterised ground truth (+-GT_LOGIT)."""
    from icmapper.data.gt import frame_gt
    from icmapper.models.segmentation import rasterise

    g = frame_gt(seq.world, seq.poses[i], rng)
    mask = rasterise(
        torch.as_tensor(g.points), torch.as_tensor(g.classes), model.bev_x, model.bev_y,
        rng.half_x, rng.half_y, model.num_classes,
    )  # fmt: skip
    return ((2 * mask - 1) * GT_LOGIT)[None]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks pipeline", description=__doc__)
    p.add_argument("--config", default="configs/paper.toml")
    p.add_argument("--source", default="sim:test:1", help="the drive (its first sequence)")
    p.add_argument("--frames", type=int, default=3, help="frames to time (after one warm-up)")
    p.add_argument("--device", default="cpu", help="cpu | cuda")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--seed", type=int, default=0, help="of the fresh weights")
    args = p.parse_args(argv)

    from icmapper.data.sources import open_source
    from icmapper.models.network import checkpoint_settings

    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    with fresh_checkpoint(args.config) as ckpt:  # removed once read
        mapper = Mapper.from_checkpoint(ckpt, device=args.device)
        rng, image_size = checkpoint_settings(ckpt)
    det = mapper.source.detector  # type: ignore[attr-defined]
    if det.seg is None:
        raise SystemExit(f"{args.config} has no segmentation head (model.seg_head)")
    seg = GroundTruthSeg(det.seg)
    det.seg = seg
    vectoriser = _time_vectoriser()
    seq = open_source(args.source, image_size=image_size)[0]
    n = min(args.frames + 1, len(seq))  # frame 0 warms up (allocations, the first memory)
    mapper.reset()
    render = 0.0
    instances = 0
    totals = dict.fromkeys(STAGES, 0.0)
    vec0 = 0.0
    for i in range(n):
        t0 = time.perf_counter()
        frame = seq.frame(i)
        if i > 0:
            render += time.perf_counter() - t0
        seg.target = gt_logits(seq, i, det.cfg, rng)
        res = mapper.step(frame)
        if i == 0:  # drop the warm-up frame
            totals = {k: -v for k, v in mapper.stats.seconds.items()}
            vec0 = vectoriser[0]
        else:
            instances += len(res.detections.classes)
    frames = n - 1
    if frames < 1:
        raise SystemExit("--frames must be >= 1 (and the drive longer than one frame)")
    for k, v in mapper.stats.seconds.items():
        totals[k] += v
    step_total = sum(totals.values())
    m = det.cfg
    print(
        f"pipeline {args.config}: {m.num_cameras} cams x {image_size[0]}x{image_size[1]}, "
        f"BEV {m.bev_x}x{m.bev_y}x{m.channels}, fresh weights; segmentation output replaced by "
        f"the rasterised ground truth"
    )
    print(
        f"source {args.source}: {frames} frames timed (after 1 warm-up), device {args.device}, "
        f"{torch.get_num_threads()} thread(s), {instances / frames:.1f} detections/frame"
    )
    outside = print_stages(totals, vectoriser[0] - vec0, frames)
    st = mapper.stats
    print(
        f"map: {st.inserted} instances inserted, {st.merged} merges, {st.absorbed} absorbed "
        f"(all frames; fresh association and fusion weights)"
    )
    print(f"end to end: {frames / step_total:.2f} frames/s (Mapper.step)")
    print(f"outside the networks: {outside / step_total:.1%} of the frame")
    print(f"(image rendering, not part of the mapper: {1e3 * render / frames:.2f} ms/frame)")
    return 0
