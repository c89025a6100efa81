"""Dense BEV segmentation, an auxiliary training target (MapTRv2): the head, the rasterised
ground truth and the loss.

The head predicts, for every BEV cell and class, whether a map element covers the cell centre.
Targets (``rasterise``): a divider or boundary covers the cells whose centre lies within
``line_radius`` metres of its polyline; a crossing covers the cells whose centre lies inside its
closed contour or within ``line_radius`` of it (so thin or small crossings still mark a cell).
The loss is a per-cell binary cross-entropy plus a soft Dice term per class (MapTRv2 uses both).
It gives the BEV features a direct, dense signal where the set-prediction loss only reaches them
through the decoder's few sampled points.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from icmapper.models.bev import bev_cell_centres
from icmapper.models.config import ModelConfig

#: Class index of crossings (closed contours); the other classes are open polylines.
CROSSING = 0


class SegHead(nn.Module):
    """forward(bev (B, C, X, Y)) -> logits (B, K, X, Y): a 3x3 convolution, ReLU, 1x1 to K."""

    def __init__(self, channels: int, num_classes: int) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(channels, channels, 3, padding=1),
            nn.ReLU(),
            nn.Conv2d(channels, num_classes, 1),
        )
        nn.init.constant_(self.net[-1].bias, -2.0)  # most cells are empty

    def forward(self, bev: torch.Tensor) -> torch.Tensor:
        return self.net(bev)


def _point_segment_distance(p: torch.Tensor, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Distances of points p (M, 2) to the segments a->b (M, S, 2) of each point -> (M, S)."""
    ab = b - a  # (M, S, 2)
    denom = (ab * ab).sum(-1).clamp(min=1e-12)  # (M, S)
    d = p[:, None] - a  # (M, S, 2)
    t = ((d * ab).sum(-1) / denom).clamp(0, 1)  # (M, S)
    return (d - t[..., None] * ab).norm(dim=-1)


def _inside(p: torch.Tensor, rings: torch.Tensor) -> torch.Tensor:
    """Even-odd point-in-polygon: p (M, 2), rings (M, R, 2) implicitly closed, one per point
    -> (M,) bool."""
    a, b = rings, rings.roll(-1, 1)  # (M, R, 2) edges a -> b
    ya, yb = a[..., 1], b[..., 1]  # (M, R)
    py, px = p[:, 1:2], p[:, 0:1]  # (M, 1)
    crosses = (ya > py) != (yb > py)  # (M, R) the edge straddles the horizontal line through p
    dy = torch.where(yb == ya, torch.ones_like(yb), yb - ya)
    x_at = a[..., 0] + (py - ya) / dy * (b[..., 0] - a[..., 0])  # (M, R)
    return ((crosses & (px < x_at)).sum(-1) % 2) == 1


def target_line_radius(bev_x: int, bev_y: int, half_x: float, half_y: float) -> float:
    """The targets' line radius on a grid of (X, Y) cells over the range: 0.75 of the larger
    cell side (metres). ``rasterise`` draws lines this wide; the vectoriser shrinks crossing
    outlines by it."""
    return 0.75 * max(2 * half_x / bev_x, 2 * half_y / bev_y)


def configured_line_radius(cfg: ModelConfig, half_x: float, half_y: float) -> float:
    """The targets' line radius of a model: ``cfg.line_radius``, or when 0 the grid's
    ``target_line_radius`` (metres)."""
    return cfg.line_radius or target_line_radius(cfg.bev_x, cfg.bev_y, half_x, half_y)


def rasterise(
    points: torch.Tensor,
    classes: torch.Tensor,
    bev_x: int,
    bev_y: int,
    half_x: float,
    half_y: float,
    num_classes: int = 3,
    line_radius: float | None = None,
) -> torch.Tensor:
    """Target masks of one frame.

    points (G, P, 2) ego metres; classes (G,) -> (K, X, Y) float32 in {0, 1}, X/Y as the BEV
    (``bev_cell_centres``). ``line_radius`` defaults to ``target_line_radius`` of the grid.
    """
    if points.dim() != 3 or points.shape[-1] != 2 or classes.shape != points.shape[:1]:
        raise ValueError(
            f"points must be (G, P, 2) with classes (G,), got {tuple(points.shape)} and "
            f"{tuple(classes.shape)}"
        )
    radius = (
        target_line_radius(bev_x, bev_y, half_x, half_y) if line_radius is None else line_radius
    )
    centres = bev_cell_centres(bev_x, bev_y, half_x, half_y).to(points.device).reshape(-1, 2)
    cls = classes.long()
    if bool(((cls < 0) | (cls >= num_classes)).any()):
        bad = int(cls[(cls < 0) | (cls >= num_classes)][0])
        raise ValueError(f"class {bad} out of range for {num_classes} classes")
    out = torch.zeros(num_classes, bev_x * bev_y, dtype=torch.float32, device=points.device)
    if points.shape[0] == 0:
        return out.reshape(num_classes, bev_x, bev_y)
    pts = points.float()  # (G, P, 2)
    closed = cls == CROSSING  # (G,)
    # only the (instance, cell) pairs inside the instance's box grown by the radius can be hit
    lo, hi = pts.amin(1) - radius, pts.amax(1) + radius  # (G, 2)
    cand = ((centres[None] >= lo[:, None]) & (centres[None] <= hi[:, None])).all(-1)  # (G, N)
    gi, ni = cand.nonzero(as_tuple=True)  # (M,) each
    p, line = centres[ni], pts[gi]  # (M, 2), (M, P, 2)
    # segments a -> b: consecutive points, and the closing edge of a crossing's contour (the
    # closing edge of an open polyline is left out by an infinite distance)
    dist = _point_segment_distance(p, line, line.roll(-1, 1))  # (M, P)
    dist[:, -1] = torch.where(closed[gi], dist[:, -1], torch.inf)
    hit = dist.min(dim=1).values <= radius  # (M,)
    hit = hit | (closed[gi] & _inside(p, line))
    out[cls[gi[hit]], ni[hit]] = 1.0
    return out.reshape(num_classes, bev_x, bev_y)


def seg_loss(logits: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """BCE (mean over cells) + soft Dice (mean over classes and samples).

    logits, targets (B, K, X, Y) -> scalar.
    """
    logits = logits.float()
    bce = F.binary_cross_entropy_with_logits(logits, targets)
    p = logits.sigmoid().flatten(2)  # (B, K, N)
    t = targets.flatten(2)
    inter = (p * t).sum(-1)
    dice = 1 - (2 * inter + 1) / (p.sum(-1) + t.sum(-1) + 1)  # (B, K)
    return bce + dice.mean()
