"""Training throughput of the former and the current training step in one run. Former: the view
transformer's dense form (every (camera, BEV cell, height) sample through ``grid_sample`` and the
value projection), a channels-first backbone and the segmentation targets rasterised one instance
at a time against every BEV cell. Current: image features projected once per pixel, the valid
samples' weighted sums as one sparse matrix product (``models.bev.weighted_sample_sum``) whose
geometry is kept while the cameras repeat (``ViewTransformer.geometry``; the batch's fixed rig,
as every clip of the synthetic training drives has), channels-last convolutions, and targets
rasterised for all instances at once over the cells of their boxes.

``python -m benchmarks train-step [--config configs/small.toml] [--steps 5] [--rounds 3]
[--threads 1] [--amp-cpu] [--seg-only]``

``--seg-only``: the current step is ``stage1.decoder = false``'s (the encoder and the
segmentation head on the segmentation loss alone; the set decoder, query propagation and
stage-1 association, which segmentation-instance inference does not run, are not trained). With
``--amp-cpu`` as well it is the step the shipped checkpoint's stage 1 trained with (its README).

``--amp-cpu``: the current step's forward runs under CPU bf16 autocast, as ``amp_cpu = true``
trains (the former step stays float32); its numbers differ from float32's in rounding, so the
BEV check below is made in float32 either way.

Both forms run the same network weights on the same stage-1 batch; passes alternate (old, new,
old, new, ...) so that a slow spell of a shared machine hits both. Prints training frames/s of
each form (a frame = one camera set of one clip step), the ratio, and checks that one forward of
each gives the same BEV (max abs difference).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import statistics
import time
from pathlib import Path
from typing import Any

import icmapper.training.objectives as objectives
import torch
import torch.nn.functional as F
from icmapper.models.bev import ViewTransformer, bev_cell_centres
from icmapper.models.detector import MapDetector
from icmapper.models.network import ICMapperNet
from icmapper.models.segmentation import CROSSING, rasterise, target_line_radius
from icmapper.testing.clips import SyntheticClips, collate_clips
from icmapper.training.config import load_config
from icmapper.training.objectives import Stage1Objective


def dense_forward(
    vt: ViewTransformer,
    feats: torch.Tensor,
    intrinsics: torch.Tensor,
    cam_to_ego: torch.Tensor,
    image_size: tuple[int, int],
) -> torch.Tensor:
    """The former ``ViewTransformer.forward`` (the reference): every sample through grid_sample,
    then the value projection. Same inputs and output as the module's forward."""
    b, ncam, c_img, fh, fw = feats.shape
    grid, valid = vt.project(intrinsics, cam_to_ego, image_size)
    n, z = grid.shape[2], grid.shape[3]
    sampled = F.grid_sample(
        feats.reshape(b * ncam, c_img, fh, fw),
        grid.reshape(b * ncam, n, z, 2).to(feats.dtype),
        mode="bilinear",
        padding_mode="zeros",
        align_corners=False,
    )  # (B*Ncam, C_img, N, Z)
    sampled = sampled.reshape(b, ncam, c_img, n, z).permute(0, 3, 1, 4, 2)  # (B,N,Ncam,Z,Ci)
    value = vt.value(sampled)  # (B, N, Ncam, Z, C)
    q = vt.query  # (N, C)
    logits = vt.query_logits(q).reshape(1, n, ncam, z) + vt.feat_logits(value).squeeze(-1)
    mask = valid.permute(0, 2, 1, 3)  # (B, N, Ncam, Z)
    logits = logits.masked_fill(~mask, -1e4).reshape(b, n, ncam * z)  # (B, N, Ncam*Z)
    weights = torch.softmax(logits.float(), dim=-1).to(value.dtype)
    weights = weights * mask.reshape(b, n, -1).to(value.dtype)  # cells seen by no camera -> 0
    agg = torch.einsum("bnk,bnkc->bnc", weights, value.reshape(b, n, ncam * z, -1))  # (B, N, C)
    x = vt.norm1(q[None] + vt.proj(agg))  # (B, N, C)
    x = vt.norm2(x + vt.ffn(x))  # (B, N, C)
    return x.transpose(1, 2).reshape(b, -1, vt.bev_x, vt.bev_y)  # (B, C, X, Y)


def former_rasterise(
    points: torch.Tensor,
    classes: torch.Tensor,
    bev_x: int,
    bev_y: int,
    half_x: float,
    half_y: float,
    num_classes: int = 3,
    line_radius: float | None = None,
) -> torch.Tensor:
    """The former ``models.segmentation.rasterise`` (the reference): one instance at a time, each
    against every BEV cell. Same inputs and output."""
    radius = line_radius
    if radius is None:
        radius = target_line_radius(bev_x, bev_y, half_x, half_y)
    centres = bev_cell_centres(bev_x, bev_y, half_x, half_y).reshape(-1, 2)  # (N, 2)
    out = torch.zeros(num_classes, bev_x * bev_y)
    for line, k in zip(points.float(), classes.tolist(), strict=True):  # (P, 2), class
        closed = k == CROSSING
        a, b = (line, line.roll(-1, 0)) if closed else (line[:-1], line[1:])  # (S, 2) segments
        ab = b - a
        t = ((centres[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1).clamp(min=1e-12)  # (N, S)
        near = centres[:, None] - (a + t.clamp(0, 1)[..., None] * ab)  # (N, S, 2)
        hit = near.norm(dim=-1).min(dim=1).values <= radius  # (N,)
        if closed:
            ya, yb = a[:, 1], b[:, 1]  # (S,)
            py, px = centres[:, 1:2], centres[:, 0:1]  # (N, 1)
            dy = torch.where(yb == ya, torch.ones_like(yb), yb - ya)
            x_at = a[:, 0] + (py - ya) / dy * (b[:, 0] - a[:, 0])  # (N, S)
            hit = hit | ((((ya > py) != (yb > py)) & (px < x_at)).sum(-1) % 2 == 1)
        out[k] = torch.maximum(out[k], hit.float())
    return out.reshape(num_classes, bev_x, bev_y)


def contiguous_image_features(det: MapDetector, images: torch.Tensor) -> torch.Tensor:
    """The former ``MapDetector.image_features``: the backbone in the default (channels-first)
    memory format."""
    b, n = images.shape[:2]
    x = images.flatten(0, 1)  # (B*N, 3, H, W)
    x = x.float() / 255.0 if x.dtype == torch.uint8 else x.float()
    f = det.backbone((x - det.pix_mean) / det.pix_std)  # (B*N, C, h, w)
    return f.reshape(b, n, *f.shape[1:])


def use_former_step(det: MapDetector, former: bool) -> None:
    """Switches the detector between the former step (dense view transformer, channels-first
    backbone, targets rasterised one instance at a time) and the current one; the weights are
    shared."""
    vt = det.view
    if former:
        vt.forward = lambda *a: dense_forward(vt, *a)  # type: ignore[method-assign]
        det.image_features = lambda im: contiguous_image_features(det, im)  # type: ignore[method-assign]
        det.backbone.to(memory_format=torch.contiguous_format)
        objectives.rasterise = former_rasterise  # type: ignore[assignment]
    else:
        vt.__dict__.pop("forward", None)
        det.__dict__.pop("image_features", None)
        det.backbone.to(memory_format=torch.channels_last)
        objectives.rasterise = rasterise


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks train-step", description=__doc__)
    ap.add_argument("--config", type=Path, default=Path("configs/small.toml"))
    ap.add_argument("--steps", type=int, default=5, help="training steps per pass")
    ap.add_argument("--rounds", type=int, default=3, help="alternating (old, new) pass pairs")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--amp-cpu", action="store_true", help="current step under CPU bf16 autocast")
    ap.add_argument("--seg-only", action="store_true", help="current step: stage1.decoder = false")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    cfg = load_config(args.config)
    torch.manual_seed(cfg.seed)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    obj = Stage1Objective(net, cfg).train()
    current = obj
    if args.seg_only:  # the same weights, the segmentation-only objective
        seg = dataclasses.replace(cfg, stage1=dataclasses.replace(cfg.stage1, decoder=False))
        current = Stage1Objective(net, seg).train()
    opt = torch.optim.SGD([p for p in obj.parameters() if p.requires_grad], lr=0.0)  # no drift
    ds = SyntheticClips(
        cfg.stage1.batch_size, cfg.data.clip_len, cfg.perception_range, cfg.data.image_size,
        cfg.model.num_cameras, seed=0, num_points=cfg.model.num_points,
    )  # fmt: skip
    batch: dict[str, Any] = collate_clips([ds[i] for i in range(len(ds))])
    det = net.detector
    frames = cfg.stage1.batch_size * cfg.data.clip_len * args.steps

    def run(former: bool) -> float:
        use_former_step(det, former)
        bf16 = args.amp_cpu and not former
        t0 = time.perf_counter()
        try:
            for _ in range(args.steps):
                autocast = torch.autocast("cpu", dtype=torch.bfloat16)
                with autocast if bf16 else contextlib.nullcontext():
                    loss = (obj if former else current)(batch)["loss"]
                opt.zero_grad()
                loss.backward()
                opt.step()
        finally:  # the module-level switch of the objectives never outlives the run
            use_former_step(det, False)
        return frames / (time.perf_counter() - t0)

    run(True), run(False)  # warm-up
    old, new = [], []
    for _ in range(args.rounds):
        old.append(run(True))
        new.append(run(False))
    with torch.no_grad():
        img = batch["images"][:, 0]  # (B, Ncam, 3, H, W) first clip step
        size = (int(img.shape[-2]), int(img.shape[-1]))
        cams = (batch["intrinsics"][:, 0], batch["cam_to_ego"][:, 0], size)
        use_former_step(det, True)
        try:
            ref = det.view(det.image_features(img), *cams)  # (B, C, X, Y)
        finally:
            use_former_step(det, False)
        diff = float((det.view(det.image_features(img), *cams) - ref).abs().max())
        r = cfg.perception_range
        gts = [objectives.prepare_gt(g[0], det, img.device) for g in batch["gt"]]
        grid = (det.cfg.bev_x, det.cfg.bev_y, r.half_x, r.half_y)
        same = all(
            torch.equal(
                rasterise(g["points"], g["classes"], *grid),
                former_rasterise(g["points"], g["classes"], *grid),
            )
            for g in gts
        )
    o, n = statistics.median(old), statistics.median(new)
    print(f"config {args.config}, {args.threads} thread(s), {frames} frames per pass")
    print(f"former step : {o:7.2f} training frames/s  (passes: {[round(v, 2) for v in old]})")
    what = "current step" + (", segmentation only" if args.seg_only else "")
    what += ", bf16 autocast" if args.amp_cpu else ""
    print(f"{what}: {n:7.2f} training frames/s  (passes: {[round(v, 2) for v in new]})")
    print(f"speed-up {n / o:.2f}x   (BEV max abs difference {diff:.2e}, "
          f"segmentation targets {'identical' if same else 'DIFFERENT'})")  # fmt: skip
    return 0
