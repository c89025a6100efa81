"""Vectorisation of the dense segmentation (icmapper.models.vectorise): rasterised ground truth
comes back as the same instances; the detector's segmentation instances; GT ids of detections."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch
from icmapper.models.segmentation import rasterise
from icmapper.models.vectorise import VectoriseParams, resample_polyline, vectorise
from icmapper.training.objectives import gt_ids_of

HX, HY = 30.0, 15.0


def _chamfer(a: np.ndarray, b: np.ndarray) -> float:
    d = np.linalg.norm(a[:, None] - b[None], axis=-1)
    return 0.5 * float(d.min(0).mean() + d.min(1).mean())


def _dense(line: np.ndarray, closed: bool = False) -> np.ndarray:
    return resample_polyline(line, 200, closed)


def _scene() -> tuple[torch.Tensor, torch.Tensor]:
    """Two dividers 3.5 m apart, a curved boundary, a 4 x 8 m crossing: (G, P, 2), (G,)."""
    x = np.linspace(-25, 25, 20)
    div1 = np.stack([x, np.full(20, 1.75)], -1)
    div2 = np.stack([x, np.full(20, -1.75)], -1)
    bound = np.stack([x, 8.0 + 0.002 * x**2], -1)
    rect = np.array([[10, -6], [14, -6], [14, 2], [10, 2]], np.float64)
    cross = resample_polyline(rect, 20, closed=True)
    pts = np.stack([cross, div1, div2, bound]).astype(np.float32)
    return torch.from_numpy(pts), torch.tensor([0, 1, 1, 2])


def test_rasterised_truth_comes_back() -> None:
    pts, cls = _scene()
    # targets on a 0.3 m grid, as the upsampled head gives them (line radius 0.225 m)
    mask = rasterise(pts, cls, 200, 100, HX, HY, line_radius=0.225).numpy()
    prob = 0.05 + 0.9 * mask
    inst = vectorise(prob, HX, HY, VectoriseParams(upsample=1, shrink=0.225))
    assert sorted(inst.classes.tolist()) == [0, 1, 1, 2]
    assert inst.points.shape == (4, 20, 2) and inst.points.dtype == np.float32
    assert np.all((inst.scores > 0.9) & (inst.scores <= 1.0))
    for g in range(4):
        k = int(cls[g])
        closed = k == 0
        best = min(
            _chamfer(
                _dense(inst.points[i], closed), _dense(pts[g].numpy().astype(np.float64), closed)
            )  # fmt: skip
            for i in np.flatnonzero(inst.classes == k)
        )
        assert best < 0.3, (g, best)


def test_upsampled_coarse_head() -> None:
    """The shipped setting: a 1.2 m grid upsampled 4x still places lines within half a cell."""
    pts, cls = _scene()
    mask = rasterise(pts, cls, 50, 25, HX, HY).numpy()
    inst = vectorise(0.05 + 0.9 * mask, HX, HY)
    for g in (1, 2, 3):
        k = int(cls[g])
        best = min(_chamfer(_dense(inst.points[i]), _dense(pts[g].numpy().astype(np.float64)))
                   for i in np.flatnonzero(inst.classes == k))  # fmt: skip
        assert best < 0.6, (g, best)


def _rect(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], np.float64)


def _crossing_iou(inst_pts: np.ndarray, truth: list[np.ndarray]) -> list[float]:
    """For each true crossing, the best shapely IoU with a vectorised crossing."""
    from shapely.geometry import Polygon

    preds = [Polygon(q) for q in inst_pts]
    out = []
    for t in truth:
        g = Polygon(t)
        out.append(max((g.intersection(q).area / g.union(q).area for q in preds), default=0.0))
    return out


@pytest.mark.parametrize(
    "truth",
    [
        # the four arms of an intersection, touching at its corners: one ring-shaped mask
        [_rect(6, 10, -6, 6), _rect(-10, -6, -6, 6), _rect(-6, 6, 6, 10), _rect(-6, 6, -10, -6)],
        # two crossings meeting at a corner: an L-shaped mask
        [_rect(-4, 0, -12, 4), _rect(0, 14, 4, 8)],
    ],
    ids=["ring", "L"],
)
def test_touching_crossings_are_split(truth: list[np.ndarray]) -> None:
    """Crossings whose masks touch come back one rectangle each (shapely IoU), where the plain
    rectangle of the joined mask would cover them all."""
    pts = np.stack([resample_polyline(t, 20, closed=True) for t in truth])
    mask = rasterise(
        torch.from_numpy(pts), torch.zeros(len(truth), dtype=torch.long), 50, 25, HX, HY
    )
    prob = 0.05 + 0.9 * mask.numpy()
    inst = vectorise(prob, HX, HY)
    cross = inst.points[inst.classes == 0]
    assert len(cross) == len(truth)
    assert min(_crossing_iou(cross, truth)) > 0.45
    joined = vectorise(prob, HX, HY, VectoriseParams(rectangularity=0.0))
    assert (joined.classes == 0).sum() == 1  # without the split: one rectangle over them all
    assert max(_crossing_iou(joined.points[joined.classes == 0], truth)) < 0.4


def test_rectangular_crossing_is_not_split() -> None:
    """A single tilted crossing fills its rectangle: it stays one instance."""
    c, s = np.cos(0.5), np.sin(0.5)
    rect = _rect(-7, 7, -2, 2) @ np.array([[c, s], [-s, c]])
    pts = resample_polyline(rect, 20, closed=True)[None]
    mask = rasterise(torch.from_numpy(pts), torch.zeros(1, dtype=torch.long), 50, 25, HX, HY)
    inst = vectorise(0.05 + 0.9 * mask.numpy(), HX, HY)
    assert (inst.classes == 0).sum() == 1
    assert _crossing_iou(inst.points[inst.classes == 0], [rect])[0] > 0.7


def test_small_crossing_components_are_dropped() -> None:
    """A crossing mask smaller than ``min_area`` is dropped, a real one beside it kept."""
    prob = np.full((3, 200, 100), 0.05)  # a 0.3 m grid over 60 x 30 m
    prob[0, 20:30, 20:70] = 0.95  # 3 x 15 m: a crossing
    prob[0, 150:157, 40:47] = 0.95  # 2.1 x 2.1 m = 4.4 m^2: a fragment
    inst = vectorise(prob, HX, HY, VectoriseParams(upsample=1, min_area=6.0))
    assert (inst.classes == 0).sum() == 1 and inst.points[0, :, 0].max() < -20
    loose = vectorise(prob, HX, HY, VectoriseParams(upsample=1))  # the default, 2 m^2
    assert (loose.classes == 0).sum() == 2


def test_skewed_crossing_keeps_its_shape() -> None:
    """A crossing cut obliquely across a road (a parallelogram) comes back as its convex hull,
    closer to it than the rectangle around it."""
    skew = np.array([[-8, -2], [4, -2], [8, 2], [-4, 2]], np.float64)
    pts = resample_polyline(skew, 20, closed=True)[None]
    mask = rasterise(torch.from_numpy(pts), torch.zeros(1, dtype=torch.long), 50, 25, HX, HY)
    prob = 0.05 + 0.9 * mask.numpy()
    hull = vectorise(prob, HX, HY)
    rect = vectorise(prob, HX, HY, VectoriseParams(hull_simplify=0.0))
    iou_hull = _crossing_iou(hull.points[hull.classes == 0], [skew])[0]
    iou_rect = _crossing_iou(rect.points[rect.classes == 0], [skew])[0]
    assert iou_hull > 0.75 and iou_hull > iou_rect + 0.05, (iou_hull, iou_rect)


def test_empty_and_bad_input() -> None:
    empty = vectorise(np.zeros((3, 50, 25)), HX, HY)
    assert len(empty) == 0 and empty.points.shape == (0, 20, 2)
    bad = np.zeros((3, 50, 25))
    bad[1, 3, 3] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        vectorise(bad, HX, HY)
    with pytest.raises(ValueError, match=r"\(K, X, Y\)"):
        vectorise(np.zeros((50, 25)), HX, HY)


# One bad setting each; the error must name it.
BAD_PARAMS: dict[str, Any] = {
    "threshold": 1.5,
    "rectangularity": 1.5,
    "corner_tolerance": -1.0,
    "ridge_threshold": 0.0,
    "ridge_sigma": 0.0,
    "ridge_curvature": -0.1,
    "ridge_classes": (0,),  # crossings are no lines
    "bend": 181.0,
    "band": -1.0,
    "subcell": (0,),  # crossings are no lines
}


@pytest.mark.parametrize("name", list(BAD_PARAMS))
def test_bad_params_named(name: str) -> None:
    with pytest.raises(ValueError, match=name):
        VectoriseParams(**{name: BAD_PARAMS[name]})


def _parallel_dividers(half_gap: float, width: float) -> np.ndarray:
    """Probabilities (3, 50, 25) of two dividers along x at y = +-half_gap (Gaussian profile of
    std ``width`` m, peak 0.95), tapering out beyond |x| = 20 m."""
    xs = (np.arange(50) + 0.5) * 2 * HX / 50 - HX
    ys = (np.arange(25) + 0.5) * 2 * HY / 25 - HY
    taper = 1 / (1 + np.exp((np.abs(xs) - 20) / 1.5))  # (50,)
    prob = np.zeros((3, 50, 25))
    for y0 in (-half_gap, half_gap):
        line = 0.95 * np.exp(-((ys[None, :] - y0) ** 2) / (2 * width**2)) * taper[:, None]
        prob[1] = np.maximum(prob[1], line)
    return prob


def test_neighbouring_dividers_stay_apart() -> None:
    """Two dividers 3 m apart whose probabilities stay above 0.5 between them (0.49 only at the
    very middle of the BEV cells): the ridge gives both, full length; the plain threshold's
    skeleton of the merged blob gave a line between them and stubs."""
    prob = _parallel_dividers(1.5, 1.3)
    assert prob[1, 25, 12] > 0.45  # the valley between them
    got = vectorise(prob, HX, HY)
    assert len(got) == 2 and set(got.classes.tolist()) == {1}
    side = sorted(float(p[:, 1].mean()) for p in got.points)
    assert side[0] == pytest.approx(-1.5, abs=0.5) and side[1] == pytest.approx(1.5, abs=0.5)
    for p in got.points:
        assert np.ptp(p[:, 0]) > 30.0  # the whole line
        assert np.abs(p[:, 1] - p[:, 1].mean()).max() < 0.5  # straight
    plain = vectorise(prob, HX, HY, VectoriseParams(ridge_classes=(), band=0.0))
    assert sum(np.ptp(p[:, 0]) > 30.0 for p in plain.points) < 2
    # the band rule (on for lines that are no ridge class) draws the blob's shrunk outline: both
    # lines whole, though farther out than the ridge's (the blob's edges less the line radius)
    banded = vectorise(prob, HX, HY, VectoriseParams(ridge_classes=()))
    assert sum(np.ptp(p[:, 0]) > 30.0 for p in banded.points) == 2
    # lines well apart come out the same way with either rule
    far = _parallel_dividers(4.0, 0.8)
    for prm in (VectoriseParams(), VectoriseParams(ridge_classes=())):
        v = vectorise(far, HX, HY, prm)
        assert sorted(round(float(p[:, 1].mean())) for p in v.points) == [-4, 4]


def test_resample_polyline() -> None:
    line = np.array([[0.0, 0.0], [10.0, 0.0]])
    out = resample_polyline(line, 11, closed=False)
    np.testing.assert_allclose(out[:, 0], np.arange(11.0), atol=1e-5)
    ring = resample_polyline(np.array([[0.0, 0], [4, 0], [4, 4], [0, 4]]), 8, closed=True)
    np.testing.assert_allclose(np.linalg.norm(np.diff(ring, axis=0), axis=1), 2.0, atol=1e-5)
    assert resample_polyline(np.zeros((3, 2)), 5, closed=False).shape == (5, 2)


def test_gt_ids_of() -> None:
    pts, cls = _scene()
    gt = {"ids": torch.tensor([7, 8, 9, 10]), "classes": cls, "points": pts}
    det = torch.stack([pts[2] + 0.3, pts[1], pts[3] + 5.0])  # divider 9, divider 8, far boundary
    ids = gt_ids_of(det, torch.tensor([1, 1, 2]), gt)
    assert ids.tolist() == [9, 8, -1]
    # a detection of the wrong class never takes the id
    assert gt_ids_of(pts[:1], torch.tensor([1]), gt).tolist() == [-1]
    assert gt_ids_of(pts[:0], torch.tensor([], dtype=torch.int64), gt).shape == (0,)


class _TruthSeg(torch.nn.Module):
    """A segmentation head that returns given logits (K, X, Y) whatever the BEV."""

    def __init__(self) -> None:
        super().__init__()
        self.logits = torch.zeros(1)

    def forward(self, bev: torch.Tensor) -> torch.Tensor:
        return self.logits[None].expand(bev.shape[0], -1, -1, -1)


def test_network_detector_takes_segmentation_instances() -> None:
    """With ``model.instances = "segmentation"`` the streaming detector returns the vectorised
    masks (here the rasterised truth), in ego metres, with one BEV embedding per instance."""
    from icmapper.data.gt import sequence_gt
    from icmapper.data.sources import open_source
    from icmapper.data.types import PerceptionRange
    from icmapper.mapping.network_source import NetworkDetector
    from icmapper.models.config import ModelConfig
    from icmapper.models.detector import MapDetector

    torch.manual_seed(0)
    cfg = ModelConfig(
        backbone_widths=(8, 16), backbone_depths=(1, 1), channels=16, num_queries=8,
        num_layers=1, topk=3, seg_head=True, instances="segmentation",
    )  # fmt: skip
    rng = PerceptionRange.from_name("60x30")
    det = MapDetector(cfg, rng)
    det.seg = _TruthSeg()
    (seq,) = open_source("sim:val:1", image_size=(32, 64))
    gts = sequence_gt(seq, rng)
    source = NetworkDetector(det)
    for i in (0, 1):
        g = gts[i]
        mask = rasterise(torch.as_tensor(g.points), torch.as_tensor(g.classes), 50, 25, HX, HY)
        det.seg.logits = (mask * 2 - 1) * 6.0  # sure inside, sure outside
        out = source.detect(seq.frame(i))
        assert out.queries is not None and out.queries.shape == (len(out), 16)
        assert np.all(np.diff(out.scores) <= 0)
        for k in (1, 2):
            truth = [
                _dense(line.astype(np.float64))
                for line in np.asarray(g.points)[np.asarray(g.classes) == k]
            ]
            found = [_dense(c.astype(np.float64)) for c in out.points[out.classes == k]]
            assert truth and found
            every_truth = np.concatenate(truth)
            every_found = np.concatenate(found)
            # precision: each detected line lies on the truth (within one 1.2 m cell)
            for c in found:
                d = np.linalg.norm(c[:, None] - every_truth[None], axis=-1).min(1)
                assert d.mean() < 1.0
            # recall: most of the true lines are covered by a detection
            d = np.linalg.norm(every_truth[:, None] - every_found[None], axis=-1).min(1)
            assert (d < 1.5).mean() > 0.8
    with pytest.raises(ValueError, match="needs model.seg_head"):
        ModelConfig(instances="segmentation")
    with pytest.raises(ValueError, match="model.instances"):
        ModelConfig(instances="pixels")


def test_segmentation_streaming_skips_the_decoder_with_the_same_bev() -> None:
    """In segmentation mode the streaming detector runs only the encoder (``encode_stream``): its
    BEV memory is the one the full forward carries frame to frame, its instances those of that BEV,
    and its state (no propagated queries) saves and restores."""
    from icmapper.data.sources import open_source
    from icmapper.data.types import PerceptionRange
    from icmapper.mapping.network_source import NetworkDetector
    from icmapper.models.config import ModelConfig
    from icmapper.models.detector import MapDetector

    torch.manual_seed(0)
    cfg = ModelConfig(
        backbone_widths=(8, 16), backbone_depths=(1, 1), channels=16, num_queries=8,
        num_layers=1, topk=3, seg_head=True, instances="segmentation",
    )  # fmt: skip
    det = MapDetector(cfg, PerceptionRange.from_name("60x30")).eval()
    with torch.no_grad():  # a head that fires on the BEV, so that instances exist
        det.seg.net[-1].bias.fill_(0.0)
    (seq,) = open_source("sim:val:1", image_size=(32, 64))
    source = NetworkDetector(det)
    state = prev_pose = None
    seen = 0
    for i in range(3):
        frame = seq.frame(i)
        pose = np.asarray(frame.pose, np.float64)
        with torch.no_grad():
            images = torch.as_tensor(np.asarray(frame.images))[None]
            intr = torch.as_tensor(frame.rig.intrinsics, dtype=torch.float32)[None]
            c2e = torch.as_tensor(frame.rig.cam_to_ego, dtype=torch.float32)[None]
            motion = None
            if prev_pose is not None:
                m = np.linalg.inv(pose) @ prev_pose
                motion = torch.as_tensor(m, dtype=torch.float32)[None]
            out, state = det(images, intr, c2e, state, motion)  # the full forward
            want, _ = det.segment_instances(out.bev)
        prev_pose = pose
        got = source.detect(frame)
        assert torch.equal(source._state.bev, out.bev)
        assert source._state.queries.shape == (1, 0, 16)
        order = np.argsort(-want.scores, kind="stable")
        np.testing.assert_array_equal(got.classes, want.classes[order])
        np.testing.assert_array_equal(got.points, want.points[order])
        seen += len(got)
    assert seen > 0
    saved = source.state_dict()
    again = NetworkDetector(det)
    again.load_state_dict(saved)
    frame = seq.frame(3)
    a, b = source.detect(frame), again.detect(frame)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.queries, b.queries)


def test_stage2_matches_segmentation_instances_to_the_truth() -> None:
    """Stage 2 (fusion) of a segmentation-instance network takes the vectorised instances that lie
    on a ground-truth instance, with that instance's id and class."""
    from icmapper.data.datasets import SequenceDataset
    from icmapper.data.sources import open_source
    from icmapper.models.network import ICMapperNet
    from icmapper.training.config import config_from_dict
    from icmapper.training.objectives import Stage2Objective, prepare_gt

    cfg = config_from_dict({
        "model": {"backbone_widths": [8, 16], "backbone_depths": [1, 1], "channels": 16,
                  "num_queries": 8, "num_layers": 1, "topk": 3, "seg_head": True,
                  "instances": "segmentation"},
        "data": {"image_size": [32, 64]},
    })  # fmt: skip
    torch.manual_seed(0)
    net = ICMapperNet(cfg.model, cfg.perception_range)
    net.detector.seg = _TruthSeg()
    objective = Stage2Objective(net, cfg)
    seqs = list(open_source("sim:val:1", image_size=(32, 64)))
    item = SequenceDataset(seqs, cfg.perception_range)[0]
    g = item["gt"][3]
    mask = rasterise(g["points"], g["classes"], 50, 25, HX, HY)
    net.detector.seg.logits = (mask * 2 - 1) * 6.0
    with torch.no_grad():
        out, _ = net.detector(item["images"][None, 3], item["intrinsics"][None, 3],
                              item["cam_to_ego"][None, 3])  # fmt: skip
    gt = prepare_gt(g, net.detector, torch.device("cpu"))
    cls, pts, ids = objective.matched(out, 0, gt)
    assert len(ids) >= 3 and len(set(ids)) == len(ids) and pts.shape == (len(ids), 20, 2)
    truth_cls = dict(zip(g["ids"].tolist(), g["classes"].tolist(), strict=True))
    assert all(truth_cls[i] == int(c) for i, c in zip(ids, cls.tolist(), strict=True))


def test_order_branch_walks_from_the_lowest_end() -> None:
    """A branch's cells come back in path order from its lowest end, whatever order they are
    given in; edge neighbours are taken before diagonal ones; a closed loop starts at its lowest
    cell. (The reference's walk; the engine's ``branches::order_branch`` pins the same cases in
    its Rust unit test.)"""
    from icmapper.testing.vectorise_reference import _order_branch

    path = np.array([[3, 1], [3, 2], [4, 3], [5, 3], [6, 4], [6, 5]])  # (L, 2) diagonal steps
    rng = np.random.default_rng(0)
    for _ in range(5):
        got = _order_branch(path[rng.permutation(len(path))])
        assert np.array_equal(got, path)
    corner = np.array([[0, 0], [0, 1], [1, 1], [1, 2]])  # (1, 1) is an edge neighbour of (0, 1)
    assert np.array_equal(_order_branch(corner[::-1]), corner)
    ring = np.array([[0, 1], [1, 0], [1, 2], [2, 1]])  # every cell has two neighbours
    assert np.array_equal(_order_branch(ring), [[0, 1], [1, 0], [2, 1], [1, 2]])
    assert np.array_equal(_order_branch(np.array([[7, 7]])), [[7, 7]])


def _lines_prob(lines: list[np.ndarray], cls: int) -> np.ndarray:
    """Probabilities (3, 200, 100) on the 0.3 m grid with the polylines ``lines`` (each (n, 2))
    of class ``cls`` drawn at the targets' line radius."""
    pts = torch.from_numpy(np.stack([resample_polyline(ln, 20, False) for ln in lines]))
    mask = rasterise(pts, torch.full((len(lines),), cls), 200, 100, HX, HY, line_radius=0.225)
    return 0.05 + 0.9 * mask.numpy()


@pytest.mark.parametrize("cls", [1, 2])
def test_a_line_goes_on_through_a_junction_and_spurs_are_dropped(cls: int) -> None:
    """A kerb or lane line with a 3 m spur at its middle, and two lines crossing: joined through
    their junctions (one instance per line), the spur dropped; cut at the junctions without."""
    main = np.array([[-20.0, 0.0], [20.0, 0.0]])
    spur = np.array([[0.0, 0.0], [0.0, 3.0]])
    prob = _lines_prob([main, spur], cls)
    joined = vectorise(prob, HX, HY, VectoriseParams(upsample=1))
    (one,) = [p for c, p in zip(joined.classes, joined.points, strict=True) if c == cls]
    assert _chamfer(_dense(one.astype(np.float64)), _dense(main)) < 0.2
    cut = vectorise(prob, HX, HY, VectoriseParams(upsample=1, through=0.0, spur=0.0))
    assert int((cut.classes == cls).sum()) == 3  # two halves and the spur
    # a line across another (an X) stays two lines
    other = np.array([[-8.0, -8.0], [8.0, 8.0]])
    cross = vectorise(_lines_prob([main, other], cls), HX, HY, VectoriseParams(upsample=1))
    got = [
        p.astype(np.float64) for c, p in zip(cross.classes, cross.points, strict=True) if c == cls
    ]
    assert len(got) == 2
    for truth in (main, other):
        assert min(_chamfer(_dense(g), _dense(truth)) for g in got) < 0.3


def test_a_long_branch_at_a_junction_is_kept() -> None:
    """A T of two kerbs: the through kerb joined, the 10 m stem kept as its own instance."""
    main = np.array([[-20.0, 0.0], [20.0, 0.0]])
    stem = np.array([[0.0, 0.0], [0.0, -10.0]])
    inst = vectorise(_lines_prob([main, stem], 2), HX, HY, VectoriseParams(upsample=1))
    got = [p.astype(np.float64) for c, p in zip(inst.classes, inst.points, strict=True) if c == 2]
    assert len(got) == 2
    assert min(_chamfer(_dense(g), _dense(main)) for g in got) < 0.2
    assert min(_chamfer(_dense(g), _dense(stem)) for g in got) < 0.5


@pytest.mark.parametrize("cls", [1, 2])
def test_a_lane_line_is_cut_where_it_bends_sharply(cls: int) -> None:
    """An L (20 m along the lanes, then 8 m across them): a lane line (a ridge class) becomes two
    lines, one on each leg; a kerb, which turns at corners, stays one; with ``bend = 0`` the lane
    line stays one too. A gently curving lane line (30 m radius) is never cut."""
    leg, across = np.array([[-10.0, -4.0], [10.0, -4.0]]), np.array([[10.0, -4.0], [10.0, 4.0]])
    prob = _lines_prob([np.concatenate([leg, across[1:]])], cls)
    inst = vectorise(prob, HX, HY, VectoriseParams(upsample=1))
    got = [p.astype(np.float64) for c, p in zip(inst.classes, inst.points, strict=True) if c == cls]
    if cls == 1:
        assert len(got) == 2
        for truth in (leg, across):
            assert min(_chamfer(_dense(g), _dense(truth)) for g in got) < 0.3
        whole = vectorise(prob, HX, HY, VectoriseParams(upsample=1, bend=0.0))
        assert int((whole.classes == cls).sum()) == 1
    else:
        assert len(got) == 1
    t = np.linspace(0.0, 0.8, 40)
    arc = np.stack([30 * np.sin(t) - 12, 30 * (1 - np.cos(t)) - 8], 1)  # (40, 2), 24 m
    curved = vectorise(_lines_prob([arc], 1), HX, HY, VectoriseParams(upsample=1))
    assert int((curved.classes == 1).sum()) == 1


def test_a_band_of_two_kerbs_is_drawn_round_its_nose() -> None:
    """A median island on 1.2 m cells: its two kerbs one band of boundary probability 4 cells (4.8
    m) wide from ego x = 0 to the front edge. The skeleton runs down its middle; with the band rule
    the boundary is its outline shrunk by the line radius (0.9 m): one line up one side, round the
    nose and back, both ends at the front edge, about 3 m apart. A kerb one cell wide stays its
    skeleton."""
    prob = np.zeros((3, 50, 25), np.float32)
    prob[2, 25:, 10:14] = 0.95  # x in [0, 30] m, y in [-3, 1.8] m
    prob[2, :, 20] = 0.95  # a single kerb along y = 9 m
    on = vectorise(prob, HX, HY)
    off = vectorise(prob, HX, HY, VectoriseParams(band=0.0))
    lines_on = [p.astype(np.float64) for c, p in zip(on.classes, on.points, strict=True) if c == 2]
    lines_off = [
        p.astype(np.float64) for c, p in zip(off.classes, off.points, strict=True) if c == 2
    ]
    kerb_on = [p for p in lines_on if p[:, 1].mean() > 6]
    kerb_off = [p for p in lines_off if p[:, 1].mean() > 6]
    np.testing.assert_array_equal(kerb_on, kerb_off)  # the single kerb untouched
    (mid,) = [p for p in lines_off if p[:, 1].mean() < 6]
    assert np.abs(mid[:, 1] - mid[:, 1].mean()).max() < 0.5  # one line down the middle
    (u,) = [p for p in lines_on if p[:, 1].mean() < 6]
    assert u[0, 0] > 27 and u[-1, 0] > 27  # both ends at the front edge
    assert 2.0 < abs(u[0, 1] - u[-1, 1]) < 4.0  # one on either side
    assert u[:, 0].min() < 3.0  # round the nose
    # a huge or infinite band (no band at all) keeps the skeleton, in bounded time and memory
    for huge in (1e6, float("inf")):
        big = vectorise(prob, HX, HY, VectoriseParams(band=huge))
        np.testing.assert_array_equal(big.points, off.points)


def test_through_and_spur_are_checked() -> None:
    with pytest.raises(ValueError, match="through"):
        VectoriseParams(through=-1.0)
    with pytest.raises(ValueError, match="spur"):
        VectoriseParams(spur=float("nan"))


def test_crossing_shrink_follows_the_grid() -> None:
    """Unset, ``shrink`` is the targets' line radius on the probabilities' grid
    (``segmentation.target_line_radius``): 0.9 m on the shipped 1.2 m cells, 0.45 m on 0.6 m
    cells; a set value is kept."""
    from icmapper.models.segmentation import target_line_radius

    p = VectoriseParams()
    assert p.shrink is None
    assert p.for_grid(50, 25, 30.0, 15.0).shrink == pytest.approx(0.9)
    assert p.for_grid(100, 50, 30.0, 15.0).shrink == pytest.approx(0.45)
    assert target_line_radius(100, 50, 30.0, 15.0) == pytest.approx(0.45)
    assert VectoriseParams(shrink=0.2).for_grid(100, 50, 30.0, 15.0).shrink == 0.2
    with pytest.raises(ValueError, match="shrink"):
        VectoriseParams(shrink=-1.0)
