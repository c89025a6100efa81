"""The view transformer's sparse path (features projected once per pixel, the valid samples'
weighted sums one sparse matrix product) against the dense reference it replaced (grid_sample of
every (camera, cell, height) sample, then the value projection), values and gradients;
bilinear_corners against grid_sample; weighted_sample_sum against gather-and-add and finite
differences; the batched rasterisation against the former per-instance loop."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from icmapper.data.types import RANGE_60x30
from icmapper.models.bev import ViewTransformer, bilinear_corners
from icmapper.testing.clips import default_rig

from benchmarks.train_step import dense_forward


def test_bilinear_corners_match_grid_sample() -> None:
    g = torch.Generator().manual_seed(0)
    maps = torch.randn(3, 5, 7, 11, generator=g)  # (M, C, h, w)
    grid = torch.rand(200, 2, generator=g) * 2.4 - 1.2  # (V, 2), some outside [-1, 1]
    which = torch.randint(0, 3, (200,), generator=g)
    idx, bw = bilinear_corners(grid, which, 7, 11)  # (V, 4) each
    flat = maps.permute(0, 2, 3, 1).reshape(-1, 5)  # (M*h*w, C)
    got = (flat[idx] * bw[..., None]).sum(1)  # (V, C)
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


def test_view_transformer_keeps_the_geometry_of_the_same_cameras() -> None:
    """The samples' geometry is kept while the same cameras come again and made anew for other
    cameras or another feature size; a change of the caller's tensors in place is seen (the
    kept cameras are copies). Every output equals the dense reference."""
    torch.manual_seed(0)
    vt = ViewTransformer(16, 24, 20, 10, RANGE_60x30.half_x, RANGE_60x30.half_y, (-1.0, 0.5), 6)
    k, e = default_rig(6, (64, 176))
    intr = torch.from_numpy(k)[None].repeat(2, 1, 1, 1)  # (B, Ncam, 3, 3)
    c2e = torch.from_numpy(e)[None].repeat(2, 1, 1, 1)  # (B, Ncam, 4, 4)
    feats = torch.randn(2, 6, 16, 8, 22)  # (B, Ncam, C, h, w)

    def check(f: torch.Tensor) -> None:
        with torch.no_grad():
            out = vt(f, intr, c2e, (64, 176))
            torch.testing.assert_close(out, dense_forward(vt, f, intr, c2e, (64, 176)),
                                       atol=2e-5, rtol=1e-4)  # fmt: skip

    check(feats)
    first = vt._geometry
    check(feats + 1.0)  # other images, the same cameras: kept
    assert vt._geometry is first
    c2e[1, 0, 0, 3] += 0.5  # the caller moves a camera in place: made anew
    check(feats)
    assert vt._geometry is not first
    second = vt._geometry
    check(torch.randn(2, 6, 16, 4, 11))  # another feature size: made anew
    assert vt._geometry is not second and vt._geometry.cameras.feat_size == (4, 11)
    intr, c2e = intr[:1], c2e[:1]  # another batch size
    check(feats[:1])
    assert vt._geometry.ib.max() == 0
    # one made under inference mode is not kept for a step with gradients (it could not be saved
    # for the backward); the other way round it is
    with torch.inference_mode():
        vt._geometry = None
        vt(feats[:1], intr, c2e, (64, 176))
    f = feats[:1].clone().requires_grad_()
    vt(f, intr, c2e, (64, 176)).square().sum().backward()
    assert f.grad is not None and not vt._geometry.idx.is_inference()
    kept = vt._geometry
    with torch.inference_mode():
        vt(feats[:1], intr, c2e, (64, 176))
    assert vt._geometry is kept


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
        vt._geometry = None  # made anew under autocast
        with torch.autocast("cpu", dtype=torch.bfloat16):
            out = vt(feats, intr, c2e, (64, 176))  # (B, C, X, Y)
    assert out.shape == ref.shape and torch.isfinite(out).all()
    assert float((out.float() - ref).abs().mean()) < 0.05 * float(ref.abs().mean())
    # the samples' geometry is float32 under autocast too (it is kept for later frames, which
    # may run without autocast): the same corners and weights as without autocast
    kept = vt._geometry
    vt._geometry = None
    with torch.no_grad():
        vt(feats, intr, c2e, (64, 176))
    assert torch.equal(kept.idx, vt._geometry.idx) and torch.equal(kept.bw, vt._geometry.bw)


def test_train_step_benchmark_runs(capsys) -> None:
    from benchmarks.train_step import main

    for extra in ([], ["--amp-cpu"], ["--seg-only"]):  # the BEV check: float32, the full step's
        assert main(["--steps", "1", "--rounds", "1", *extra]) == 0
        out = capsys.readouterr().out
        assert "speed-up" in out and float(out.split("difference ")[1].split(",")[0]) < 1e-3
        assert "segmentation targets identical" in out


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


def test_rasterise_equals_the_former_per_instance_form() -> None:
    """The batched rasterisation (all instances at once, cells of their boxes only) gives exactly
    the masks of the former loop over instances against every cell, degenerate lines included."""
    from icmapper.models.segmentation import rasterise

    from benchmarks.train_step import former_rasterise

    g = torch.Generator().manual_seed(0)
    for trial in range(40):
        n = int(torch.randint(0, 12, (1,), generator=g))
        pts = torch.randn(n, 20, 2, generator=g).cumsum(1) * 3  # (G, P, 2) random walks
        pts = pts + torch.randn(n, 1, 2, generator=g) * 15
        if trial % 5 == 0 and n:
            pts[0] = pts[0, :1]  # every point the same
        cls = torch.randint(0, 3, (n,), generator=g)  # crossings (0) closed
        got = rasterise(pts, cls, 50, 25, 30.0, 15.0, 3)  # (K, X, Y)
        assert torch.equal(got, former_rasterise(pts, cls, 50, 25, 30.0, 15.0, 3))
    assert got.sum() > 0


def test_weighted_sample_sum_values_and_gradients() -> None:
    """The sparse weighted sum against the plain gather-and-add, and its gradients by finite
    differences (float64), with several samples of one row on the same pixel and rows with
    no sample."""
    from icmapper.models.bev import sample_pattern, weighted_sample_sum

    g = torch.Generator().manual_seed(1)
    maps = torch.randn(2, 3, 4, 5, generator=g, dtype=torch.float64)  # (M, C, h, w)
    flat = maps.permute(0, 2, 3, 1).reshape(-1, 3).requires_grad_()  # (M*h*w, C)
    grid = torch.rand(30, 2, generator=g, dtype=torch.float64) * 2.4 - 1.2  # (V, 2)
    grid[1] = grid[0]  # two samples of row 0 on the same pixels
    which = torch.randint(0, 2, (30,), generator=g)
    rows = torch.sort(torch.randint(0, 12, (30,), generator=g)).values  # (V,) sorted
    rows[:2] = 0
    idx, bw = bilinear_corners(grid, which, 4, 5)  # (V, 4)
    w = torch.rand(30, generator=g, dtype=torch.float64, requires_grad=True)
    got = weighted_sample_sum(flat, w, rows, idx, bw.double(), 16)  # (16, C)
    samples = (flat[idx] * bw.double()[..., None]).sum(1)  # (V, C)
    ref = torch.zeros(16, 3, dtype=torch.float64).index_add(0, rows, w[:, None] * samples)
    torch.testing.assert_close(got, ref)
    assert torch.equal(got[12:], torch.zeros(4, 3, dtype=torch.float64))  # rows with no sample
    assert torch.autograd.gradcheck(
        lambda f, ww: weighted_sample_sum(f, ww, rows, idx, bw.double(), 16), (flat, w)
    )
    empty = torch.zeros(0, dtype=torch.long)
    none = weighted_sample_sum(flat, w[:0], empty, idx[:0], bw[:0].double(), 16)
    assert torch.equal(none, torch.zeros(16, 3, dtype=torch.float64))
    # a pattern made beforehand (as the view transformer keeps it) gives the same, and the
    # gradients through its transpose agree too; one made for another matrix is refused
    pattern = sample_pattern(rows, idx, 16, flat.shape[0])
    kept = weighted_sample_sum(flat, w, rows, idx, bw.double(), 16, pattern)
    assert torch.equal(kept, got)
    g_kept = torch.autograd.grad(kept.square().sum(), [flat, w])
    g_got = torch.autograd.grad(got.square().sum(), [flat, w])
    for a, r in zip(g_kept, g_got, strict=True):
        torch.testing.assert_close(a, r)
    with pytest.raises(ValueError, match="pattern is for 16 rows"):
        weighted_sample_sum(flat, w, rows, idx, bw.double(), 17, pattern)


def test_view_transformer_with_no_valid_sample() -> None:
    """Cameras that see no BEV cell (here lifted 1 km up, looking at the sky's horizon): the
    sparse sum is empty and every cell keeps its query alone, with gradients for the weights."""
    torch.manual_seed(0)
    vt = ViewTransformer(16, 24, 20, 10, RANGE_60x30.half_x, RANGE_60x30.half_y, (-1.0, 0.5), 6)
    k, e = default_rig(6, (64, 176))
    e = e.copy()
    e[:, 2, 3] += 1000.0  # every camera 1 km above the ground
    intr, c2e = torch.from_numpy(k)[None], torch.from_numpy(e)[None]  # (1, Ncam, 3|4, 3|4)
    _, valid = vt.project(intr, c2e, (64, 176))
    assert not bool(valid.any())
    feats = torch.randn(1, 6, 16, 8, 22, requires_grad=True)  # (B, Ncam, C, h, w)
    out = vt(feats, intr, c2e, (64, 176))  # (B, C, X, Y)
    ref = dense_forward(vt, feats, intr, c2e, (64, 176))
    torch.testing.assert_close(out, ref, atol=2e-5, rtol=1e-4)
    out.square().sum().backward()
    assert vt.query.grad is not None and torch.isfinite(vt.query.grad).all()
