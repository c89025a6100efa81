"""Spatial fusion of a detected instance with its history in the global map (IC-Mapper §3.4).

Queries are point embeddings of the detected points, keys/values point embeddings of the history
points of the same ID sampled from the global map (the patch expanded by ``margin`` metres). Each
of the ``num_layers`` layers does self-attention over the instance's points, cross-attention to its
history, an FFN, and a shared regression head whose refined points feed the next layer. Instances
without history pass through unchanged. Points are normalised by the expanded range internally;
the API takes and returns ego-frame metres.
"""

from __future__ import annotations

import torch
from torch import nn

from icmapper.models.decoder import mlp


class PointEmbed(nn.Module):
    """(N, P, 2) normalised points -> (N, P, C): MLP of the coordinates + index embedding."""

    def __init__(self, channels: int, num_points: int) -> None:
        super().__init__()
        self.coord = mlp(2, channels, channels)
        self.index = nn.Parameter(torch.randn(num_points, channels) * 0.02)

    def forward(self, points: torch.Tensor) -> torch.Tensor:
        return self.coord(points) + self.index  # (N, P, C)


class FusionLayer(nn.Module):
    """Self-attention over points, cross-attention to the history, FFN."""

    def __init__(self, channels: int, heads: int) -> None:
        super().__init__()
        self.self_attn = nn.MultiheadAttention(channels, heads, batch_first=True)
        self.cross_attn = nn.MultiheadAttention(channels, heads, batch_first=True)
        self.norms = nn.ModuleList([nn.LayerNorm(channels) for _ in range(3)])
        self.ffn = mlp(channels, 2 * channels, channels)

    def forward(self, h: torch.Tensor, pos: torch.Tensor, kv: torch.Tensor) -> torch.Tensor:
        """h, pos (N, P, C); kv (N, S, C) -> (N, P, C)."""
        q = h + pos
        h = self.norms[0](h + self.self_attn(q, q, h, need_weights=False)[0])
        h = self.norms[1](h + self.cross_attn(h + pos, kv, kv, need_weights=False)[0])
        return self.norms[2](h + self.ffn(h))


class FusionModule(nn.Module):
    """forward(det_points (N, P, 2) ego metres, det_classes (N,), hist_points (N, S, 2) ego metres,
    has_history (N,) bool) -> list (one per layer) of fused points (N, P, 2) ego metres.

    Rows without history are returned unchanged by every layer.
    """

    def __init__(
        self,
        channels: int,
        num_points: int,
        half_x: float,
        half_y: float,
        margin: float = 20.0,
        num_layers: int = 3,
        heads: int = 4,
        num_classes: int = 3,
        history_points: int = 20,
    ) -> None:
        super().__init__()
        self.num_points = num_points
        self.margin = float(margin)  # metres around the range of the sampled history
        self.history_points = history_points  # points per history instance
        self.scale = (half_x + margin, half_y + margin)
        self.embed_det = PointEmbed(channels, num_points)
        self.embed_hist = PointEmbed(channels, history_points)
        self.cls_embed = nn.Embedding(num_classes, channels)
        self.layers = nn.ModuleList([FusionLayer(channels, heads) for _ in range(num_layers)])
        self.reg = mlp(channels, channels, 2)  # shared regression head
        with torch.no_grad():  # start near the identity (small, not zero: gradients flow)
            self.reg[-1].weight.mul_(0.01)
            nn.init.zeros_(self.reg[-1].bias)

    def forward(
        self,
        det_points: torch.Tensor,
        det_classes: torch.Tensor,
        hist_points: torch.Tensor,
        has_history: torch.Tensor,
    ) -> list[torch.Tensor]:
        if det_points.dim() != 3 or det_points.shape[1:] != (self.num_points, 2):
            raise ValueError(
                f"det_points must be (N, {self.num_points}, 2), got {tuple(det_points.shape)}"
            )
        if hist_points.dim() != 3 or hist_points.shape[0] != det_points.shape[0]:
            raise ValueError(f"hist_points must be (N, S, 2), got {hist_points.shape}")
        scale = torch.tensor(self.scale, dtype=det_points.dtype, device=det_points.device)
        p = det_points / scale  # (N, P, 2) roughly in [-1, 1]
        kv = self.embed_hist(hist_points / scale)  # (N, S, C)
        h = self.embed_det(p) + self.cls_embed(det_classes)[:, None]  # (N, P, C)
        keep = has_history[:, None, None]  # (N, 1, 1)
        outputs = []
        for layer in self.layers:
            pos = self.embed_det(p.detach())  # (N, P, C)
            h = layer(h, pos, kv)  # (N, P, C)
            p = p + self.reg(h)  # (N, P, 2)
            fused = torch.where(keep, p * scale, det_points)  # (N, P, 2) metres
            outputs.append(fused)
        return outputs
