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


def test_view_transformer_under_autocast() -> None:
    """Mixed precision (``amp``; bfloat16 autocast, here on the CPU) runs the sparse path and stays
    close to float32: the attention logits are written back in the logits' own dtype."""
    torch.manual_seed(0)
    vt = ViewTransformer(16, 24, 20, 10, RANGE_60x30.half_x, RANGE_60x30.half_y, (-1.0, 0.5), 6)
    k, e = default_rig(6, (64, 176))
    intr, c2e = torch.from_numpy(k)[None], torch.from_numpy(e)[None]  # (1, Ncam, 3|4, 3|4)
    feats = torch.randn(1, 6, 16, 8, 22)  # (B, Ncam, C, h, w)
    with torch.no_grad():
        ref = vt(feats, intr, c2e, (64, 176))
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out = vt(feats, intr, c2e, (64, 176))  # (B, C, X, Y)
    assert out.shape == ref.shape and torch.isfinite(out).all()
    assert float((out.float() - ref).abs().mean()) < 0.05 * float(ref.abs().mean())


def test_train_step_benchmark_runs(capsys) -> None:
    from benchmarks.train_step import main

    assert main(["--steps", "1", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    assert "speed-up" in out and float(out.split("difference ")[1].split(")")[0]) < 1e-3


def test_model_camera_math_lands_on_painted_markings() -> None:
    """Issue 13's geometry diagnostic: ground-truth dividers projected with the view transformer's
    own math (``ViewTransformer.project`` + grid_sample's pixel convention) onto rendered images
    read paint; the same points moved 1 m sideways read asphalt."""
    import dataclasses

    import numpy as np
    from icmapper.data import MapClass, xy_yaw_to_pose
    from icmapper.data.sim import Renderer, generate_city, nuscenes_rig
    from icmapper.data.sim.geometry import arc_length, resample_by_length

    world = generate_city(10_011)  # the city of the renderer's own paint test
    quiet = dataclasses.replace(world, lanes={})  # no driving vehicles
    size = (128, 352)
    rig = nuscenes_rig(size)
    renderer = Renderer(quiet, rig, seed=2)
    vt = ViewTransformer(3, 8, 4, 2, 30.0, 15.0, (0.0,), rig.num_cameras)
    intr = torch.as_tensor(rig.intrinsics, dtype=torch.float32)[None]  # (1, Ncam, 3, 3)
    c2e = torch.as_tensor(rig.cam_to_ego, dtype=torch.float32)[None]  # (1, Ncam, 4, 4)
    dividers = [
        m
        for m in world.instances
        if m.cls == MapClass.DIVIDER
        and m.style.startswith(("solid", "double"))
        and arc_length(m.points)[-1] > 30.0
    ]
    checked = 0
    for m in dividers[:4]:
        p0, p1 = resample_by_length(m.points, np.array([2.0, 3.0]))
        t = (p1 - p0) / np.linalg.norm(p1 - p0)
        nrm = np.array([-t[1], t[0]])
        ego_xy = p0 - 1.6 * nrm  # in the lane right of the divider, facing along it
        pose = xy_yaw_to_pose(*ego_xy, float(np.arctan2(t[1], t[0])))
        img = torch.as_tensor(renderer.render(pose, frame_seed=0)).float().mean(1)  # (C, H, W)
        along = resample_by_length(m.points, np.linspace(10.0, 20.0, 40))  # (40, 2) world
        reads = []
        for pts in (along, along - 1.0 * nrm):  # the divider, asphalt 1 m to its right
            rel = pts - ego_xy
            ego = np.stack([rel @ t, rel @ nrm], axis=1)  # (40, 2) ego frame
            pillars = torch.zeros(len(ego), 1, 4)  # (N, Z=1, 4) homogeneous ground points
            pillars[:, 0, :2] = torch.as_tensor(ego, dtype=torch.float32)
            pillars[:, 0, 3] = 1.0
            vt.pillars = pillars
            grid, valid = vt.project(intr, c2e, size)  # (1, Ncam, N, 1, 2), (1, Ncam, N, 1)
            # brightest of +-2 pixel columns: double lines leave a gap on their centreline
            shifts = torch.tensor([[2.0 * du / size[1], 0.0] for du in range(-2, 3)])  # (5, 2)
            sampled = torch.stack(
                [F.grid_sample(img[:, None], grid[0] + d, align_corners=False) for d in shifts]
            ).amax(0)  # (Ncam, 1, N, 1) grey values at the projections
            v = sampled[:, 0, :, 0][valid[0, :, :, 0]]  # (k,) valid projections only
            reads.append(v)
        paint, asphalt = reads
        if len(paint) < 10 or len(asphalt) < 10:
            continue
        assert float(paint.median()) > float(asphalt.median()) + 25.0
        checked += 1
    assert checked >= 1
