"""Query propagation (StreamMapNet): the top-k queries of the previous frame carried to the current.

``QueryPropagation`` (U_MLP): updates a query with an MLP conditioned on the ego motion (the
flattened 3x4 transform previous ego -> current ego) and moves its points into the current ego
frame geometrically. ``select_topk`` picks the k highest-scoring queries of a frame.
"""

from __future__ import annotations

import torch
from torch import nn

from icmapper.models.decoder import mlp


def transform_points(points_m: torch.Tensor, transform: torch.Tensor) -> torch.Tensor:
    """Planar points (B, ..., 2) metres through (B, 4, 4) transforms -> (B, ..., 2)."""
    b = points_m.shape[0]
    flat = points_m.reshape(b, -1, 2)  # (B, M, 2)
    r = transform[:, :2, :2].to(flat.dtype)  # (B, 2, 2)
    t = transform[:, :2, 3].to(flat.dtype)  # (B, 2)
    out = torch.einsum("bij,bmj->bmi", r, flat) + t[:, None]  # (B, M, 2)
    return out.reshape(points_m.shape)


def select_topk(scores: torch.Tensor, k: int) -> torch.Tensor:
    """Indices (B, k) of the k highest scores of (B, Q) (ties by lower index: stable)."""
    return torch.sort(scores, dim=1, descending=True, stable=True).indices[:, :k]


class QueryPropagation(nn.Module):
    """U_MLP.

    forward(queries (B, k, C), points01 (B, k, P, 2) in [0, 1] of the previous frame,
    prev_to_cur (B, 4, 4)) -> (queries (B, k, C), points01 (B, k, P, 2) in the current frame).
    """

    def __init__(self, channels: int, half_x: float, half_y: float) -> None:
        super().__init__()
        self.half = (half_x, half_y)
        self.pose_mlp = mlp(12, channels, channels)
        self.update = mlp(2 * channels, 2 * channels, channels)
        self.norm = nn.LayerNorm(channels)

    def forward(
        self, queries: torch.Tensor, points01: torch.Tensor, prev_to_cur: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        pose = prev_to_cur[:, :3, :].reshape(-1, 12).to(queries.dtype)  # (B, 12)
        pose_feat = self.pose_mlp(pose)[:, None].expand_as(queries)  # (B, k, C)
        q = self.norm(queries + self.update(torch.cat([queries, pose_feat], dim=-1)))  # (B, k, C)
        half = torch.tensor(self.half, dtype=points01.dtype, device=points01.device)
        pts_m = (points01 * 2 - 1) * half  # (B, k, P, 2)
        pts_m = transform_points(pts_m, prev_to_cur)  # (B, k, P, 2)
        pts01 = ((pts_m / half + 1) / 2).clamp(0.0, 1.0)  # (B, k, P, 2)
        return q, pts01
