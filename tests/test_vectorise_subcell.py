"""Lines placed between the BEV cells (icmapper.models.subcell, VectoriseParams.subcell): a line
drawn through cell centres moves across to the ridge of its probabilities, by at most MAX_SHIFT,
and nothing else moves."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from icmapper.data.types import PerceptionRange
from icmapper.models.config import ModelConfig
from icmapper.models.detector import MapDetector
from icmapper.models.subcell import MAX_SHIFT, subcell_lines
from icmapper.models.vectorise import VectoriseParams, vectorise

HX, HY = 30.0, 15.0
CELL = 2 * HY / 25  # 1.2 m


def _ridge(cls: int, y0: float, slope: float = 0.0) -> np.ndarray:
    """Probabilities (3, 50, 25) on 1.2 m cells (centres at y = 0, +-1.2, ...): class ``cls`` a
    Gaussian ridge along y = y0 + slope * x (std 1 m, peak 0.95, about as wide as the network's
    lines), the other classes empty."""
    xs = (np.arange(50) + 0.5) * 2 * HX / 50 - HX
    ys = (np.arange(25) + 0.5) * 2 * HY / 25 - HY
    prob = np.zeros((3, 50, 25))
    centre = y0 + slope * xs[:, None]  # (50, 1)
    prob[cls] = 0.95 * np.exp(-((ys[None, :] - centre) ** 2) / (2 * 1.0**2))
    return prob


def _line(y: float, slope: float = 0.0) -> np.ndarray:
    x = np.linspace(-20.0, 20.0, 20)
    return np.stack([x, y + slope * x], -1)[None].astype(np.float32)  # (1, 20, 2)


@pytest.mark.parametrize("cls", [1, 2])
@pytest.mark.parametrize("y0", [0.3, -0.5])
def test_a_line_off_the_ridge_moves_towards_it(cls: int, y0: float) -> None:
    # drawn through the cell centres at y = 0, the ridge between them: the line comes at least
    # two thirds of the way (cubic splines through 1.2 m samples draw the peak a little towards
    # the nearer centre), never past it
    out = subcell_lines(np.array([cls]), _line(0.0), _ridge(cls, y0), HX, HY, (1, 2))
    moved = out[0, :, 1]  # (P,)
    assert np.all(np.abs(moved - y0) <= abs(y0) / 3) and np.all(moved / y0 <= 1.0)
    assert np.allclose(out[0, :, 0], np.linspace(-20, 20, 20), atol=1e-4)  # across only


def test_a_slanted_line_moves_along_its_normal() -> None:
    slope = 0.2
    prob = _ridge(1, 0.4, slope)  # the ridge 0.4 m above the drawn line, vertically
    out = subcell_lines(np.array([1]), _line(0.0, slope), prob, HX, HY, (1,))
    gap = np.abs(out[0, :, 1] - (0.4 + slope * out[0, :, 0]))  # (P,) vertical distance left
    assert gap.mean() < 0.4 / 2
    step = out[0] - _line(0.0, slope)[0]  # (P, 2) every move is across the line
    assert np.abs(step @ np.array([1.0, slope]) / np.hypot(1.0, slope)).max() < 1e-3


def test_other_classes_far_ridges_and_flat_fields_stay() -> None:
    lines = np.concatenate([_line(0.0), _line(0.0)])  # (2, 20, 2)
    classes = np.array([0, 2])
    prob = _ridge(0, 0.4) + _ridge(2, 0.4)
    out = subcell_lines(classes, lines, prob, HX, HY, (1,))  # boundaries not chosen
    assert np.array_equal(out, lines)
    out = subcell_lines(np.array([1]), _line(0.0), _ridge(1, 3.6), HX, HY, (1,))  # 3.6 m away
    assert np.array_equal(out, _line(0.0))  # no peak inside the search: no move
    out = subcell_lines(np.array([1]), _line(0.0), np.zeros((3, 50, 25)), HX, HY, (1,))
    assert np.array_equal(out, _line(0.0))


def test_a_move_is_bounded() -> None:
    # a ridge 1.1 m off: the search (0.9 m) ends on the rising slope, no peak inside it; at 0.85 m
    # the move stops at MAX_SHIFT
    for y0 in (0.85, 1.1):
        out = subcell_lines(np.array([1]), _line(0.0), _ridge(1, y0), HX, HY, (1,))
        assert np.abs(out[0, :, 1]).max() <= MAX_SHIFT + 1e-6


def test_the_vectoriser_applies_it_to_the_chosen_classes() -> None:
    y0 = 0.3  # between the upsampled grid's cell centres (0.15, 0.45 m)
    prob = _ridge(2, y0)
    plain = vectorise(prob, HX, HY)
    fine = vectorise(prob, HX, HY, VectoriseParams(subcell=[2]))  # a list, as TOML gives it
    assert len(plain) == len(fine) == 1
    assert np.array_equal(plain.classes, fine.classes) and np.array_equal(plain.scores, fine.scores)
    mid = slice(5, 15)  # away from the line's ends
    before = np.abs(plain.points[0, mid, 1] - y0).mean()
    after = np.abs(fine.points[0, mid, 1] - y0).mean()
    assert after < before and after < 0.1


def test_bad_shapes_are_named() -> None:
    with pytest.raises(ValueError, match="subcell_lines"):
        subcell_lines(np.array([1, 1]), _line(0.0), _ridge(1, 0.0), HX, HY, (1,))


class _FixedSeg(torch.nn.Module):
    """A segmentation head that returns given logits (K, X, Y) whatever the BEV."""

    def __init__(self, logits: torch.Tensor) -> None:
        super().__init__()
        self.logits = logits

    def forward(self, bev: torch.Tensor) -> torch.Tensor:
        return self.logits[None].expand(bev.shape[0], -1, -1, -1)


def _detector(subcell: tuple[int, ...]) -> MapDetector:
    torch.manual_seed(0)
    cfg = ModelConfig(
        backbone_widths=(8, 16), backbone_depths=(1, 1), channels=16, num_queries=8,
        num_layers=1, topk=3, seg_head=True, instances="segmentation", subcell=subcell,
    )  # fmt: skip
    det = MapDetector(cfg, PerceptionRange.from_name("60x30"))
    prob = np.clip(_ridge(2, 0.3), 1e-4, 1 - 1e-4)
    det.seg = _FixedSeg(torch.as_tensor(np.log(prob / (1 - prob)), dtype=torch.float32))
    return det


def test_the_detector_places_lines_as_its_config_says() -> None:
    """``model.subcell`` is the detector's (a checkpoint's fusion is trained on its lines); a
    ``VectoriseParams.subcell`` given by the caller wins; the embeddings follow the points."""
    bev = torch.randn(1, 16, 50, 25)
    with torch.no_grad():
        plain, q_plain = _detector(()).segment_instances(bev)
        fine, q_fine = _detector((2,)).segment_instances(bev)
        forced, _ = _detector((2,)).segment_instances(bev, VectoriseParams(subcell=()))
    mid = slice(5, 15)
    off = [np.abs(x.points[0, mid, 1] - 0.3).mean() for x in (fine, plain)]
    assert off[0] < off[1]
    assert np.array_equal(forced.points, plain.points)
    assert not torch.equal(q_plain, q_fine)  # sampled along the moved points
    with pytest.raises(ValueError, match="model.subcell"):
        ModelConfig(subcell=(0,))  # crossings are no lines


def test_the_config_reads_it() -> None:
    from icmapper.settings import from_table

    assert from_table(ModelConfig, {"subcell": [1, 2]}, "model").subcell == (1, 2)
    assert from_table(ModelConfig, {"subcell": []}, "model").subcell == ()
    with pytest.raises(ValueError, match="model.subcell must hold ints"):
        from_table(ModelConfig, {"subcell": ["boundary"]}, "model")
    with pytest.raises(ValueError, match="model.subcell"):
        from_table(ModelConfig, {"subcell": [0]}, "model")
