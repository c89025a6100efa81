"""Shapes at every module boundary, camera geometry, BEV warping, pass-through of fusion."""

from __future__ import annotations

import math

import pytest
import torch
from icmapper.data.types import RANGE_60x30
from icmapper.models.association import AssociationHead
from icmapper.models.backbone import ResNetBackbone
from icmapper.models.bev import TemporalMemory, ViewTransformer, warp_bev
from icmapper.models.config import ModelConfig
from icmapper.models.decoder import MapDecoder
from icmapper.models.detector import MapDetector
from icmapper.models.fusion import FusionModule
from icmapper.models.propagation import QueryPropagation
from icmapper.testing.clips import default_rig

HX, HY = RANGE_60x30.half_x, RANGE_60x30.half_y
MODEL = ModelConfig(
    backbone_widths=(8, 16),
    backbone_depths=(1, 1),
    channels=32,
    bev_x=20,
    bev_y=10,
    num_queries=12,
    num_layers=2,
    topk=4,
)


def _rig(b: int, c: int, size: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    k, e = default_rig(c, size)
    return torch.from_numpy(k)[None].repeat(b, 1, 1, 1), torch.from_numpy(e)[None].repeat(
        b, 1, 1, 1
    )


def test_backbone_shape() -> None:
    bb = ResNetBackbone((8, 16, 32), (1, 2, 1), 24)
    assert bb(torch.rand(2, 3, 64, 176)).shape == (2, 24, 8, 22)
    with pytest.raises(ValueError):
        ResNetBackbone((8,), (1,), 8)


def test_view_transformer_projection_and_shape() -> None:
    vt = ViewTransformer(16, 32, 20, 10, HX, HY, (0.0, 1.0), 6)
    k, e = _rig(1, 6, (64, 176))
    grid, valid = vt.project(k, e, (64, 176))
    assert grid.shape == (1, 6, 200, 2, 2) and valid.shape == (1, 6, 200, 2)
    # a ground point straight ahead at the camera's height would be at the image centre; points
    # ahead on the ground are below the centre in the front camera, and never in the rear one
    centres = vt.pillars[:, 0, :2]
    ahead = torch.nonzero((centres[:, 1].abs() < 1.0) & (centres[:, 0] > 10)).flatten()
    assert valid[0, 0, ahead, 0].all()
    assert (grid[0, 0, ahead, 0, 1] > 0).all()  # below the horizon
    assert not valid[0, 3, ahead, 0].any()  # camera 3 looks backwards
    out = vt(torch.rand(1, 6, 16, 8, 22), k, e, (64, 176))
    assert out.shape == (1, 32, 20, 10)
    with pytest.raises(ValueError, match="cameras"):
        vt(torch.rand(1, 5, 16, 8, 22), k[:, :5], e[:, :5], (64, 176))


def test_warp_bev_identity_and_shift() -> None:
    bev = torch.rand(2, 4, 20, 10)
    eye = torch.eye(4).repeat(2, 1, 1)
    assert torch.allclose(warp_bev(bev, eye, HX, HY), bev, atol=1e-5)
    shift = eye.clone()
    shift[:, 0, 3] = 2 * HX / 20  # current cell i sees previous cell i + 1
    warped = warp_bev(bev, shift, HX, HY)
    assert torch.allclose(warped[:, :, :-1], bev[:, :, 1:], atol=1e-5)
    assert torch.all(warped[:, :, -1].abs() <= bev[:, :, -1].abs().max())
    mem = TemporalMemory(4, HX, HY)
    assert mem(bev, bev, eye).shape == bev.shape and mem(bev, None, None).shape == bev.shape


def test_decoder_and_propagation_shapes() -> None:
    dec = MapDecoder(32, 12, 2, 20, 3, 4, shared_reg=False)
    out = dec(torch.rand(2, 32, 20, 10))
    assert len(out.logits) == 2 and out.logits[0].shape == (2, 12, 3)
    assert out.points[-1].shape == (2, 12, 20, 2) and out.queries.shape == (2, 12, 32)
    assert (out.points[-1] >= 0).all() and (out.points[-1] <= 1).all()
    prop = QueryPropagation(32, HX, HY)
    motion = torch.eye(4).repeat(2, 1, 1)
    motion[:, 0, 3] = -3.0  # moved 3 m forward: old points are 3 m further back
    pts = torch.full((2, 4, 20, 2), 0.5)
    q, p = prop(out.queries[:, :4], pts, motion)
    assert q.shape == (2, 4, 32) and p.shape == (2, 4, 20, 2)
    assert torch.allclose(p[..., 0], torch.full_like(p[..., 0], 0.5 - 3.0 / (2 * HX)))
    out2 = dec(torch.rand(2, 32, 20, 10), q, p)
    assert out2.points[0].shape == (2, 12, 20, 2)
    with pytest.raises(ValueError):
        dec(torch.rand(2, 32, 20, 10), torch.rand(2, 13, 32), torch.rand(2, 13, 20, 2))


def test_detector_streaming_state() -> None:
    det = MapDetector(MODEL)
    k, e = _rig(2, 6, (32, 88))
    img = torch.randint(0, 256, (2, 6, 3, 32, 88), dtype=torch.uint8)
    out, st = det(img, k, e)
    assert out.num_propagated == 0 and out.trans_points is None
    assert st.bev.shape == (2, 32, 20, 10) and st.queries.shape == (2, 4, 32)
    assert st.points.shape == (2, 4, 20, 2) and st.src_index.shape == (2, 4)
    out2, _ = det(img, k, e, st, torch.eye(4).repeat(2, 1, 1))
    assert out2.num_propagated == 4 and out2.trans_points.shape == (2, 4, 20, 2)
    assert out2.scores().shape == (2, 12) and out2.classes().shape == (2, 12)
    m = det.to_metres(out2.points[-1])
    assert m[..., 0].abs().max() <= HX and m[..., 1].abs().max() <= HY
    assert torch.allclose(det.to_unit(m), out2.points[-1], atol=1e-6)
    with pytest.raises(ValueError, match="prev_to_cur"):
        det(img, k, e, st, None)
    with pytest.raises(ValueError, match="images"):
        det(img[:, :, :2], k, e)


def test_association_shapes_and_pairwise() -> None:
    head = AssociationHead(16, 20)
    qd, qt = torch.rand(5, 16), torch.rand(3, 16)
    pd, pt = torch.rand(5, 20, 2), torch.rand(3, 20, 2)
    s = head.scores(qd, pd, qt, pt)
    assert s.shape == (5, 3) and (s >= 0).all() and (s <= 1).all()
    assert head(qd[None], pd[None], qt[None], pt[None]).shape == (1, 5, 3)
    perm = torch.tensor([2, 0, 1])  # scores are per pair: permuting tracks permutes columns
    assert torch.allclose(head.scores(qd, pd, qt[perm], pt[perm]), s[:, perm], atol=1e-6)


def test_fusion_pass_through_and_shapes() -> None:
    fus = FusionModule(16, 20, HX, HY, num_layers=3)
    det = torch.rand(4, 20, 2) * 10
    hist = torch.rand(4, 20, 2) * 10
    has = torch.tensor([True, False, True, False])
    with torch.no_grad():
        for p in fus.reg.parameters():  # make the head move points
            p.add_(0.1)
    outs = fus(det, torch.tensor([0, 1, 2, 1]), hist, has)
    assert len(outs) == 3 and all(o.shape == (4, 20, 2) for o in outs)
    assert torch.equal(outs[-1][~has], det[~has])
    assert not torch.allclose(outs[-1][has], det[has])
    with pytest.raises(ValueError):
        fus(torch.rand(4, 19, 2), torch.zeros(4, dtype=torch.int64), hist, has)
    assert math.isfinite(float(outs[-1].detach().sum()))


def test_one_to_many_queries_train_only_and_isolated() -> None:
    """The one-to-many queries run in training only, in their own attention group: the main
    queries' outputs are the same with and without them (same weights)."""
    from icmapper.models.decoder import MapDecoder

    torch.manual_seed(0)
    plain = MapDecoder(32, 6, 2, num_points=20, heads=4)
    hybrid = MapDecoder(32, 6, 2, num_points=20, heads=4, aux_queries=4)
    state = plain.state_dict()
    with torch.no_grad():
        for name, p in hybrid.named_parameters():
            src = state[name]
            p.copy_(torch.cat([src, p[src.shape[0] :]]) if name in ("query", "ref") else src)
    bev = torch.randn(2, 32, 10, 8)
    prop_q, prop_p = torch.randn(2, 2, 32), torch.rand(2, 2, 20, 2)
    plain.train(), hybrid.train()
    a, b = plain(bev, prop_q, prop_p), hybrid(bev, prop_q, prop_p)
    assert b.aux_logits is not None and b.aux_points is not None and a.aux_logits is None
    assert b.aux_logits[-1].shape == (2, 4, 3) and b.aux_points[-1].shape == (2, 4, 20, 2)
    for x, y in zip(a.logits + a.points, b.logits + b.points, strict=True):
        assert torch.allclose(x, y, atol=1e-5)
    hybrid.eval()
    c = hybrid(bev, prop_q, prop_p)
    assert c.aux_logits is None and c.logits[-1].shape == (2, 6, 3)


def test_point_refinement_moves_points_by_their_own_evidence() -> None:
    """With ``point_refine`` each point gets a correction from the BEV around it: the layer
    samples a 3x3 neighbourhood, and the gradient of one point's feature reaches the BEV only
    near that point."""
    from icmapper.models.decoder import MapDecoder

    torch.manual_seed(0)
    dec = MapDecoder(16, 4, 2, num_points=20, heads=4, point_refine=True, grid=(10, 8))
    assert dec.layers[0].neighbourhood.shape == (9, 2)
    bev = torch.randn(1, 16, 10, 8, requires_grad=True)
    out = dec(bev)
    assert out.points[-1].shape == (1, 4, 20, 2)
    # one point of one query of the first layer: its point-head correction reads the BEV near it
    feats = dec.layers[0](dec.query[None, :4], dec.point_embed(torch.sigmoid(dec.ref[None, :4])
                          .flatten(2)), bev, torch.sigmoid(dec.ref[None, :4]))[1]  # fmt: skip
    assert feats.shape == (1, 4, 20, 16)
    (grad,) = torch.autograd.grad(feats[0, 0, 0].sum(), bev)
    touched = (grad.abs().sum(1)[0] > 0).nonzero()  # (n, 2) BEV cells
    assert 0 < len(touched) <= 16  # the 3x3 cells around the point (bilinear: up to 4x4)
    plain = MapDecoder(16, 4, 2, num_points=20, heads=4)
    assert sum(p.numel() for p in dec.parameters()) > sum(p.numel() for p in plain.parameters())
