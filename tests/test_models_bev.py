"""The view transformer's sparse path (features projected once per pixel, only valid samples
gathered) against the dense reference it replaced (grid_sample of every (camera, cell, height)
sample, then the value projection), values and gradients; bilinear_gather against grid_sample."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from icmapper.data.types import RANGE_60x30
from icmapper.models.bev import ViewTransformer, bilinear_gather
from icmapper.testing.clips import default_rig

from benchmarks.train_step import dense_forward


def test_bilinear_gather_matches_grid_sample() -> None:
    g = torch.Generator().manual_seed(0)
    maps = torch.randn(3, 5, 7, 11, generator=g)  # (M, C, h, w)
    grid = torch.rand(200, 2, generator=g) * 2.4 - 1.2  # (V, 2), some outside [-1, 1]
    which = torch.randint(0, 3, (200,), generator=g)
    got = bilinear_gather(maps, which, grid)  # (V, C)
    ref = F.grid_sample(maps[which], grid[:, None, None, :], align_corners=False)[:, :, 0, 0]
    torch.testing.assert_close(got, ref, atol=1e-5, rtol=1e-5)


def test_sparse_view_transformer_equals_dense_reference() -> None:
    torch.manual_seed(0)
    vt = ViewTransformer(16, 24, 20, 10, RANGE_60x30.half_x, RANGE_60x30.half_y, (-1.0, 0.5), 6)
    k, e = default_rig(6, (64, 176))
    intr = torch.from_numpy(k)[None].repeat(2, 1, 1, 1)  # (B, Ncam, 3, 3)
    c2e = torch.from_numpy(e)[None].repeat(2, 1, 1, 1)  # (B, Ncam, 4, 4)
    feats = torch.randn(2, 6, 16, 8, 22, requires_grad=True)  # (B, Ncam, C, h, w)
    _, valid = vt.project(intr, c2e, (64, 176))
    assert 0 < valid.float().mean() < 0.5  # most (camera, cell, height) samples are invalid
    out = vt(feats, intr, c2e, (64, 176))  # (B, C, X, Y)
    ref = dense_forward(vt, feats, intr, c2e, (64, 176))
    torch.testing.assert_close(out, ref, atol=2e-5, rtol=1e-4)
    grads = torch.autograd.grad(out.square().sum(), [feats, vt.value.weight, vt.query])
    grads_ref = torch.autograd.grad(ref.square().sum(), [feats, vt.value.weight, vt.query])
    for a, r in zip(grads, grads_ref, strict=True):
        torch.testing.assert_close(a, r, atol=1e-4, rtol=1e-3)


def test_train_step_benchmark_runs(capsys) -> None:
    from benchmarks.train_step import main

    assert main(["--steps", "1", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert "speed-up" in out and float(out.split("difference ")[1].split(")")[0]) < 1e-3
