"""Why is the detector weak? Two upper bounds, measured with the project's own detection eval, and
what the fusion does to the detections.

``perfect-bev``: the decoder (same ``MapDecoder``, matcher and loss as the detector) fed a perfect
BEV: the rasterised ground truth (``models.segmentation.rasterise``) lifted to the BEV channels by
two convolutions. What it reaches bounds what any view transformer could give this decoder.

``seg-iou``: the intersection over union per class of a checkpoint's dense BEV segmentation head
(``model.seg_head``) on the validation drives: how much of the map the BEV features hold, read by
a dense head instead of the set decoder.

``fusion-gain``: does the spatial fusion move a detection towards the truth? Over the mapper's run
on the drives, each detection the fusion changed (it had a history in the map) is compared with
the nearest same-class ground-truth instance of its frame (symmetric Chamfer of densely resampled
points) before and after fusion; detections farther than ``gate`` from every truth (false
detections) are left out.

``python -m icmapper.training.diagnostics perfect-bev --config configs/small.toml --steps 3000``
``python -m icmapper.training.diagnostics seg-iou CHECKPOINT --source sim:val:4``
``python -m icmapper.training.diagnostics fusion-gain CHECKPOINT --source sim:val:4``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from icmapper.data.types import CLASS_NAMES, NUM_INSTANCE_POINTS, PerceptionRange
from icmapper.models.config import ModelConfig
from icmapper.models.decoder import MapDecoder
from icmapper.models.losses import DetectionCriterion, repeat_targets
from icmapper.models.segmentation import configured_line_radius, rasterise


class PerfectBev(nn.Module):
    """forward(masks (B, K, X, Y)) -> DecoderOutput: rasterised GT -> BEV (B, C, X, Y) ->
    the detector's decoder."""

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        c = cfg.channels
        self.lift = nn.Sequential(
            nn.Conv2d(cfg.num_classes, c, 3, padding=1), nn.ReLU(),
            nn.Conv2d(c, c, 3, padding=1), nn.GroupNorm(1, c),
        )  # fmt: skip
        self.pos = nn.Parameter(torch.randn(1, c, cfg.bev_x, cfg.bev_y) * 0.02)  # (1, C, X, Y)
        self.decoder = MapDecoder(
            c, cfg.num_queries, cfg.num_layers, cfg.num_points, cfg.num_classes, cfg.heads,
            cfg.shared_reg, cfg.aux_queries, cfg.point_refine, (cfg.bev_x, cfg.bev_y),
        )  # fmt: skip

    def forward(self, masks: torch.Tensor):  # noqa: ANN201 - DecoderOutput
        return self.decoder(self.lift(masks) + self.pos)


def _frames(spec: str, rng: PerceptionRange, seed: int) -> list[list]:
    """Per-sequence lists of FrameGT of a source (no images)."""
    from icmapper.data.gt import sequence_gt
    from icmapper.data.sources import open_source

    return [sequence_gt(s, rng) for s in open_source(spec, seed=seed, render=False)]


def _points(g: object) -> torch.Tensor:
    """(G, P, 2) float32 ego-frame points of a FrameGT (also when it holds no instance)."""
    pts = np.asarray(g.points, np.float32)  # type: ignore[attr-defined]
    return torch.as_tensor(pts.reshape(-1, NUM_INSTANCE_POINTS, 2))


def _masks(frames: list, cfg: ModelConfig, rng: PerceptionRange) -> torch.Tensor:
    """(B, K, X, Y) rasterised GT of FrameGTs."""
    return torch.stack([
        rasterise(_points(g),
                  torch.as_tensor(np.asarray(g.classes, np.int64)), cfg.bev_x, cfg.bev_y,
                  rng.half_x, rng.half_y, cfg.num_classes,
                  configured_line_radius(cfg, rng.half_x, rng.half_y))
        for g in frames
    ])  # fmt: skip


def _targets(frames: list, rng: PerceptionRange) -> list[dict]:
    half = torch.tensor([rng.half_x, rng.half_y])
    out = []
    for g in frames:
        pts = _points(g)
        out.append({"classes": torch.as_tensor(np.asarray(g.classes, np.int64)),
                    "points01": (pts / half + 1) / 2, "ids": torch.as_tensor(g.ids)})  # fmt: skip
    return out


def perfect_bev(config: Path, steps: int, train_spec: str, val_spec: str, batch: int,
                log: bool = True, overrides: dict | None = None) -> dict:  # fmt: skip
    """Trains ``PerfectBev`` for ``steps`` and returns the detection result on ``val_spec``
    (``overrides``: config values as for ``icmapper train --set``; with ``model.aux_queries`` the
    one-to-many loss of ``stage1`` is added as in stage-1 training)."""
    from icmapper.eval.evaluate import evaluate
    from icmapper.eval.runfmt import FramePredictions
    from icmapper.training.config import load_config

    cfg = load_config(config, overrides)
    rng = cfg.perception_range
    torch.manual_seed(cfg.seed)
    train = [g for seq in _frames(train_spec, rng, cfg.seed) for g in seq]
    net = PerfectBev(cfg.model)
    crit = DetectionCriterion(cfg.model.num_classes, cfg.stage1.cls_weight, cfg.stage1.pts_weight)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.stage1.lr, weight_decay=0.01)
    gen = np.random.default_rng(cfg.seed)
    t0 = time.perf_counter()
    for step in range(steps):
        pick = [train[i] for i in gen.integers(len(train), size=batch)]
        out = net(_masks(pick, cfg.model, rng))
        targets = _targets(pick, rng)
        loss, _ = crit(out.logits, out.points, targets)
        if out.aux_logits is not None and out.aux_points is not None:
            rep = [repeat_targets(t, cfg.stage1.one_to_many_repeats) for t in targets]
            loss = (
                loss + cfg.stage1.one_to_many_weight * crit(out.aux_logits, out.aux_points, rep)[0]
            )
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), cfg.stage1.grad_clip)
        opt.step()
        if log and (step + 1) % 200 == 0:
            print(f"step {step + 1}: det loss {float(loss.detach()):.3f} "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)  # fmt: skip
    net.eval()
    val = _frames(val_spec, rng, cfg.seed)
    half = np.array([rng.half_x, rng.half_y], np.float32)
    preds = []
    with torch.no_grad():
        for seq in val:
            out = net(_masks(seq, cfg.model, rng))
            prob = out.logits[-1].sigmoid()  # (T, Q, K)
            pts = (out.points[-1].numpy() * 2 - 1) * half  # (T, Q, P, 2) metres
            q = prob.shape[1]
            preds.append([
                FramePredictions(t, np.eye(4), prob[t].argmax(-1).numpy().astype(np.int64),
                                 prob[t].max(-1).values.numpy().astype(np.float64),
                                 pts[t].astype(np.float32), np.arange(q, dtype=np.int64))
                for t in range(len(seq))
            ])  # fmt: skip
    return evaluate(preds, val, range_name=rng.name)["detection"]


def seg_iou(checkpoint: Path, spec: str) -> dict[str, float]:
    """IoU (%) per class of a checkpoint's segmentation head (threshold 0.5) on ``spec``."""
    from icmapper.data.datasets import SequenceDataset
    from icmapper.data.sources import open_source
    from icmapper.models.network import load_network
    from icmapper.training.bevcache import stream_bev

    loaded = load_network(checkpoint)
    det, cfg, rng = loaded.net.detector, loaded.model, loaded.rng
    if det.seg is None:
        raise ValueError(f"checkpoint {checkpoint} has no segmentation head (model.seg_head)")
    ds = SequenceDataset(open_source(spec, image_size=loaded.image_size), rng)
    inter = np.zeros(cfg.num_classes)
    union = np.zeros(cfg.num_classes)
    with torch.no_grad():
        for i in range(len(ds)):
            item = ds[i]
            for t, bev in enumerate(stream_bev(det, item)):
                pred = (det.seg(bev)[0] > 0).numpy()  # (K, X, Y)
                g = item["gt"][t]
                tgt = rasterise(g["points"], g["classes"], cfg.bev_x, cfg.bev_y, rng.half_x,
                                rng.half_y, cfg.num_classes,
                                configured_line_radius(cfg, rng.half_x, rng.half_y),
                                ).numpy() > 0.5  # fmt: skip
                inter += (pred & tgt).reshape(cfg.num_classes, -1).sum(1)
                union += (pred | tgt).reshape(cfg.num_classes, -1).sum(1)
    return {n: 100 * float(inter[k] / max(union[k], 1)) for k, n in enumerate(CLASS_NAMES)}


def _nearest_chamfer(points: np.ndarray, truths: np.ndarray, closed: bool) -> float:
    """Symmetric Chamfer (m) of an instance (P, 2) to the nearest of truths (G, P', 2), both
    resampled to 100 points along the line (the ring for closed instances)."""
    from icmapper.geom import cloud_chamfer
    from icmapper.models.vectorise import resample_polyline

    a = resample_polyline(np.asarray(points, np.float64), 100, closed)  # (100, 2)
    return min(
        cloud_chamfer(a, resample_polyline(np.asarray(t, np.float64), 100, closed)) for t in truths
    )


def fusion_gain(
    checkpoint: Path, spec: str, gate: float = 1.5, variant: str = "full"
) -> dict[str, dict[str, float]]:
    """Per class: ``n`` detections the fusion changed that lie within ``gate`` m of a truth, and
    their mean Chamfer to it before (``raw``) and after (``fused``) fusion, over the mapper
    (``Mapper.from_checkpoint(checkpoint, variant=variant)``) run on ``spec``."""
    from icmapper.data.gt import sequence_gt
    from icmapper.data.sources import open_source
    from icmapper.mapping.mapper import Mapper
    from icmapper.models.network import checkpoint_settings

    mapper = Mapper.from_checkpoint(checkpoint, variant=variant)
    size = checkpoint_settings(checkpoint)[1]  # the image size, without building a second network
    errors: dict[int, list[tuple[float, float]]] = {k: [] for k in range(len(CLASS_NAMES))}
    for seq in open_source(spec, image_size=size):
        mapper.reset()
        truth = sequence_gt(seq, mapper.rng)
        for i in range(len(seq)):
            step = mapper.step(seq.frame(i))
            det, g = step.detections, truth[i]
            for j in range(len(det)):
                k = int(det.classes[j])
                same = g.points[g.classes == k]  # (G, P, 2)
                changed = not np.array_equal(step.points[j], det.points[j])
                if not len(same) or not (changed or variant != "full"):
                    continue
                closed = k == 0
                raw = _nearest_chamfer(det.points[j], same, closed)
                if raw <= gate:
                    errors[k].append((raw, _nearest_chamfer(step.points[j], same, closed)))
    out = {}
    for k, name in enumerate(CLASS_NAMES):
        e = np.asarray(errors[k], np.float64).reshape(-1, 2)
        mean = e.mean(0) if len(e) else np.full(2, np.nan)
        out[name] = {"n": float(len(e)), "raw": float(mean[0]), "fused": float(mean[1])}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m icmapper.training.diagnostics",
                                 description=__doc__)  # fmt: skip
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("perfect-bev", help="the decoder on a rasterised-GT BEV")
    p.add_argument("--config", type=Path, default=Path("configs/small.toml"))
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch", type=int, default=6)
    p.add_argument("--train", default="sim:train:128")
    p.add_argument("--val", default="sim:val:4")
    p.add_argument("--set", action="append", metavar="TABLE.KEY=VALUE", help="config override")
    s = sub.add_parser("seg-iou", help="IoU of a checkpoint's segmentation head")
    s.add_argument("checkpoint", type=Path)
    s.add_argument("--source", default="sim:val:4")
    f = sub.add_parser("fusion-gain", help="detections before and after fusion, against the truth")
    f.add_argument("checkpoint", type=Path)
    f.add_argument("--source", default="sim:val:4")
    f.add_argument("--gate", type=float, default=1.5)
    args = ap.parse_args(argv)
    if args.what == "perfect-bev":
        from icmapper.settings import parse_assignments

        over = parse_assignments(args.set or [])
        det = perfect_bev(args.config, args.steps, args.train, args.val, args.batch, True, over)
        print(json.dumps({k: det[k] for k in ("AP", "AP_class", "mAP")}, indent=1))
    elif args.what == "fusion-gain":
        print(json.dumps(fusion_gain(args.checkpoint, args.source, args.gate), indent=1))
    else:
        print(json.dumps(seg_iou(args.checkpoint, args.source), indent=1))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
