"""Benchmark of the networks: training steps/s and per-frame inference latency per module.

``python -m benchmarks networks [--config configs/small.toml] [--steps 10] [--frames 10]``
Prints measured numbers (random images of the config's size; no dataset needed).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch
from icmapper.models.network import ICMapperNet
from icmapper.testing.clips import SyntheticClips, collate_clips
from icmapper.training.config import TrainConfig, load_config
from icmapper.training.objectives import Stage1Objective, prev_to_cur


def _time(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time of ``fn`` in milliseconds (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times)


def bench_training(cfg: TrainConfig, steps: int) -> float:
    """Stage-1 training steps per second at the config's batch size and clip length."""
    torch.manual_seed(cfg.seed)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    obj = Stage1Objective(net, cfg).train()
    opt = torch.optim.AdamW([p for p in obj.parameters() if p.requires_grad], lr=1e-4)
    ds = SyntheticClips(
        cfg.stage1.batch_size, cfg.data.clip_len, cfg.perception_range, cfg.data.image_size,
        cfg.model.num_cameras, seed=0, num_points=cfg.model.num_points,
    )  # fmt: skip
    batch = collate_clips([ds[i] for i in range(len(ds))])

    def step() -> None:
        loss = obj(batch)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()

    step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - t0)


@torch.no_grad()
def bench_inference(cfg: TrainConfig, repeats: int) -> dict[str, float]:
    """Per-frame latency (ms, batch 1) of each module on a streaming frame (with state)."""
    torch.manual_seed(cfg.seed)
    net = ICMapperNet(cfg.model, cfg.perception_range).eval()
    det = net.detector
    ds = SyntheticClips(1, 2, cfg.perception_range, cfg.data.image_size, cfg.model.num_cameras)
    b = collate_clips([ds[0]])
    img, k, e = b["images"][:, 1], b["intrinsics"][:, 1], b["cam_to_ego"][:, 1]
    motion = prev_to_cur(b["poses"], 1)
    _, state = det(b["images"][:, 0], k, e)
    size = (int(img.shape[-2]), int(img.shape[-1]))
    feats = det.image_features(img)
    bev = det.view(feats, k, e, size)
    fused_bev = det.memory(bev, state.bev, torch.linalg.inv(motion))
    q, p = det.propagation(state.queries, state.points, motion)
    n_trk = n_det = cfg.model.topk
    qd, pd = torch.rand(n_det, cfg.model.channels), torch.rand(n_det, cfg.model.num_points, 2)
    pts_m = torch.rand(n_det, cfg.model.num_points, 2) * 20 - 10
    cls = torch.zeros(n_det, dtype=torch.int64)
    has = torch.ones(n_det, dtype=torch.bool)
    out = {
        "backbone (all cameras)": _time(lambda: det.image_features(img), repeats),
        "view transformer": _time(lambda: det.view(feats, k, e, size), repeats),
        "temporal memory (warp + GRU)": _time(
            lambda: det.memory(bev, state.bev, torch.linalg.inv(motion)), repeats
        ),
        "propagation (U_MLP)": _time(
            lambda: det.propagation(state.queries, state.points, motion), repeats
        ),
        "decoder": _time(lambda: det.decoder(fused_bev, q, p), repeats),
        f"association ({n_det}x{n_trk})": _time(
            lambda: net.association.scores(qd, pd, qd, pd), repeats
        ),
        f"fusion ({n_det} instances)": _time(lambda: net.fusion(pts_m, cls, pts_m, has), repeats),
        "detector total (one frame)": _time(lambda: det(img, k, e, state, motion), repeats),
    }
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks networks", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--config", type=Path, default=Path("configs/small.toml"))
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    cfg = load_config(args.config)
    m, d = cfg.model, cfg.data
    print(
        f"config {args.config}: {m.num_cameras} cams x {d.image_size[0]}x{d.image_size[1]}, "
        f"BEV {m.bev_x}x{m.bev_y}x{m.channels}, {m.num_queries} queries, {m.num_layers} layers; "
        f"torch {torch.__version__}, {torch.get_num_threads()} threads"
    )
    sps = bench_training(cfg, args.steps)
    print(
        f"stage-1 training: {sps:.2f} steps/s ({1e3 / sps:.0f} ms/step) at batch "
        f"{cfg.stage1.batch_size} x clip {d.clip_len}"
    )
    for name, ms in bench_inference(cfg, args.frames).items():
        print(f"  inference {name:32s} {ms:8.2f} ms/frame")
    return 0
