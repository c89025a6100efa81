"""Learned association of detected instances with tracked instances (IC-Mapper §3.3).

H = MLP(MLP(Q_D ⊙ Q_T) + FFN(L2(P_D, P_T))) for every (detected, tracked) pair; the score is
sigmoid(H). L2(P_D, P_T) is the per-point Euclidean distance of the two point sets, taken for the
tracked points in both directions (2P features), so the affinity does not depend on the direction.
The inference side (threshold, one-to-one assignment, IDs, buffer) lives in the online mapper.
"""

from __future__ import annotations

import torch
from torch import nn

from icmapper.models.decoder import mlp


class AssociationHead(nn.Module):
    """forward(q_det (B, D, C), p_det (B, D, P, 2), q_trk (B, T, C), p_trk (B, T, P, 2)) -> logits
    (B, D, T). Points are normalised ([0, 1] of the range) and both sets are in the current ego
    frame. ``scores`` returns sigmoid(logits)."""

    def __init__(self, channels: int, num_points: int = 20) -> None:
        super().__init__()
        self.feat_mlp = mlp(channels, channels, channels)
        self.dist_ffn = mlp(2 * num_points, channels, channels)
        self.out_mlp = mlp(channels, channels, 1)

    def forward(
        self,
        q_det: torch.Tensor,
        p_det: torch.Tensor,
        q_trk: torch.Tensor,
        p_trk: torch.Tensor,
    ) -> torch.Tensor:
        prod = q_det[:, :, None] * q_trk[:, None]  # (B, D, T, C)
        diff_f = p_det[:, :, None] - p_trk[:, None]  # (B, D, T, P, 2)
        diff_r = p_det[:, :, None] - p_trk.flip(2)[:, None]  # (B, D, T, P, 2)
        dist = torch.cat([diff_f.norm(dim=-1), diff_r.norm(dim=-1)], dim=-1)  # (B, D, T, 2P)
        h = self.feat_mlp(prod) + self.dist_ffn(dist)  # (B, D, T, C)
        return self.out_mlp(h).squeeze(-1)  # (B, D, T)

    @torch.no_grad()
    def scores(
        self,
        q_det: torch.Tensor,
        p_det: torch.Tensor,
        q_trk: torch.Tensor,
        p_trk: torch.Tensor,
    ) -> torch.Tensor:
        """Association scores in [0, 1]: (D, C), (D, P, 2), (T, C), (T, P, 2) -> (D, T) for one
        frame (unbatched), or batched as ``forward``."""
        unbatched = q_det.dim() == 2
        if unbatched:
            q_det, p_det, q_trk, p_trk = q_det[None], p_det[None], q_trk[None], p_trk[None]
        s = torch.sigmoid(self.forward(q_det, p_det, q_trk, p_trk))
        return s[0] if unbatched else s
