"""DETR-style map decoder: queries that each regress a fixed number of points.

Each layer: self-attention among queries; the query samples the BEV at its current points (bilinear)
and aggregates them with learned per-point weights; an FFN; then a class head (logits per layer) and
a regression head (shared by all layers or one per layer) that refines the points in inverse-sigmoid
space. Points are normalised to [0, 1] of the perception range inside the decoder.

One-to-many matching (MapTRv2's hybrid matching): with ``aux_queries`` A > 0 the decoder holds A
extra queries that run beside the Q main ones in training only, in their own self-attention group
(a mask keeps the groups apart, so the main queries behave as without them); their outputs
(``DecoderOutput.aux_logits`` / ``aux_points``) are matched to the ground truth repeated several
times (``losses.DetectionCriterion`` with repeated targets), giving the decoder many more positive
samples per frame. Inference runs the Q main queries only.

Per-point refinement (``point_refine``, after MapTR's point-level queries): the regression head sees
only the query vector, which pools its P points into one feature, so a point cannot be placed from
the evidence at its own location. With ``point_refine`` every layer also samples a 3x3
neighbourhood of BEV cells around each point (a fixed-offset deformable attention), and a per-point
head turns that local feature (plus the query and the point's index) into a correction of that
point alone, added to the query-level regression.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from icmapper.models.bev import sample_bev


def inverse_sigmoid(x: torch.Tensor, eps: float = 1e-5) -> torch.Tensor:
    """logit(x) with x clamped to [eps, 1 - eps]."""
    x = x.clamp(eps, 1 - eps)
    return torch.log(x / (1 - x))


def mlp(c_in: int, c_hidden: int, c_out: int, layers: int = 2) -> nn.Sequential:
    """A ReLU MLP with ``layers`` linear layers."""
    mods: list[nn.Module] = []
    c = c_in
    for _ in range(layers - 1):
        mods += [nn.Linear(c, c_hidden), nn.ReLU()]
        c = c_hidden
    mods.append(nn.Linear(c, c_out))
    return nn.Sequential(*mods)


@dataclass
class DecoderOutput:
    """logits: per layer (B, Q, K); points: per layer (B, Q, P, 2) in [0, 1]; queries (B, Q, C)
    of the last layer; aux_logits / aux_points: the same for the A one-to-many queries (training
    with ``aux_queries`` > 0), else None."""

    logits: list[torch.Tensor]
    points: list[torch.Tensor]
    queries: torch.Tensor
    aux_logits: list[torch.Tensor] | None = None
    aux_points: list[torch.Tensor] | None = None


class DecoderLayer(nn.Module):
    """One decoder layer (self-attention, BEV point sampling, FFN)."""

    def __init__(
        self,
        channels: int,
        num_points: int,
        heads: int,
        neighbourhood: torch.Tensor | None = None,
    ) -> None:
        """``neighbourhood`` (S, 2) offsets in [0, 1] units: sample S points around each point and
        return a per-point feature (``point_refine``); None samples each point once."""
        super().__init__()
        self.self_attn = nn.MultiheadAttention(channels, heads, batch_first=True)
        self.norm1 = nn.LayerNorm(channels)
        self.point_weights = nn.Linear(channels, num_points)
        s = 1 if neighbourhood is None else neighbourhood.shape[0]
        self.value = nn.Linear(s * channels, channels)
        self.neighbourhood: torch.Tensor | None
        self.register_buffer("neighbourhood", neighbourhood, persistent=False)
        self.out = nn.Linear(channels, channels)
        self.norm2 = nn.LayerNorm(channels)
        self.ffn = mlp(channels, 2 * channels, channels)
        self.norm3 = nn.LayerNorm(channels)

    def forward(
        self,
        q: torch.Tensor,
        pos: torch.Tensor,
        bev: torch.Tensor,
        points: torch.Tensor,
        attn_mask: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """q, pos (B, Q, C); bev (B, C, X, Y); points (B, Q, P, 2) in [0, 1]; attn_mask (Q, Q)
        bool, True where a query may not attend -> queries (B, Q, C), point features
        (B, Q, P, C)."""
        qp = q + pos
        att = self.self_attn(qp, qp, q, need_weights=False, attn_mask=attn_mask)[0]
        q = self.norm1(q + att)  # (B, Q, C)
        if self.neighbourhood is None:
            feats = self.value(sample_bev(bev, points))  # (B, Q, P, C)
        else:
            around = points[..., None, :] + self.neighbourhood  # (B, Q, P, S, 2)
            feats = self.value(sample_bev(bev, around).flatten(-2))  # (B, Q, P, S*C) -> C
        w = torch.softmax(self.point_weights(q + pos), dim=-1)  # (B, Q, P)
        agg = torch.einsum("bqp,bqpc->bqc", w, feats)  # (B, Q, C)
        q = self.norm2(q + self.out(agg))
        return self.norm3(q + self.ffn(q)), feats  # (B, Q, C), (B, Q, P, C)


class MapDecoder(nn.Module):
    """forward(bev (B, C, X, Y), prop_queries (B, k, C) | None, prop_points (B, k, P, 2) | None)
    -> DecoderOutput with Q = num_queries queries; propagated queries (and their points, [0, 1])
    replace the first k learned queries."""

    def __init__(
        self,
        channels: int,
        num_queries: int,
        num_layers: int,
        num_points: int = 20,
        num_classes: int = 3,
        heads: int = 4,
        shared_reg: bool = True,
        aux_queries: int = 0,
        point_refine: bool = False,
        grid: tuple[int, int] = (50, 25),
    ) -> None:
        """``grid`` (X, Y): the BEV's cells, the step of ``point_refine``'s neighbourhood."""
        super().__init__()
        self.num_queries, self.num_points, self.num_classes = num_queries, num_points, num_classes
        self.num_layers_ = num_layers
        self.aux_queries = aux_queries
        total = num_queries + aux_queries
        self.query = nn.Parameter(torch.randn(total, channels) * 0.02)  # (Q + A, C)
        self.ref = nn.Parameter(torch.randn(total, num_points, 2) * 0.5)  # logits of points
        hood = None
        if point_refine:  # the 3x3 cells around a point, in [0, 1] units
            step = torch.tensor([1.0 / grid[0], 1.0 / grid[1]])
            d = torch.tensor([-1.0, 0.0, 1.0])
            hood = torch.cartesian_prod(d, d) * step  # (9, 2)
        self.layers = nn.ModuleList(
            [DecoderLayer(channels, num_points, heads, hood) for _ in range(num_layers)]
        )
        self.point_embed = mlp(num_points * 2, channels, channels)
        self.cls_heads = nn.ModuleList(
            [nn.Linear(channels, num_classes) for _ in range(num_layers)]
        )
        n_reg = 1 if shared_reg else num_layers
        self.reg_heads = nn.ModuleList(
            [mlp(channels, channels, num_points * 2) for _ in range(n_reg)]
        )
        with torch.no_grad():  # start close to the reference points (small, not zero: grads flow)
            for head in self.reg_heads:
                head[-1].weight.mul_(0.01)
                nn.init.zeros_(head[-1].bias)
        self.point_heads: nn.ModuleList | None = None
        if point_refine:
            self.point_index = nn.Parameter(torch.randn(num_points, channels) * 0.02)  # (P, C)
            self.point_norm = nn.LayerNorm(channels)
            self.point_heads = nn.ModuleList([mlp(channels, channels, 2) for _ in range(n_reg)])
            with torch.no_grad():
                for head in self.point_heads:
                    head[-1].weight.mul_(0.01)
                    nn.init.zeros_(head[-1].bias)
        for head in self.cls_heads:  # focal-loss prior: p = 0.01
            nn.init.constant_(head.bias, -4.595)

    def reg_head(self, layer: int) -> nn.Module:
        """The regression head of decoder layer ``layer``."""
        return self.reg_heads[min(layer, len(self.reg_heads) - 1)]

    def refine(
        self,
        layer: int,
        q: torch.Tensor,
        points: torch.Tensor,
        point_feats: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Points after the regression head of ``layer``.

        q (B, Q, C), points (B, Q, P, 2) in [0, 1], point_feats (B, Q, P, C) the layer's
        features at ``points`` (``point_refine``; None: the query-level regression only)
        -> (B, Q, P, 2) in [0, 1].
        """
        delta = self.reg_head(layer)(q).reshape(*q.shape[:-1], self.num_points, 2)  # (B, Q, P, 2)
        if self.point_heads is not None and point_feats is not None:
            head = self.point_heads[min(layer, len(self.point_heads) - 1)]
            local = self.point_norm(point_feats) + q[..., None, :] + self.point_index
            delta = delta + head(local)  # (B, Q, P, 2)
        return torch.sigmoid(inverse_sigmoid(points) + delta)

    def forward(
        self,
        bev: torch.Tensor,
        prop_queries: torch.Tensor | None = None,
        prop_points: torch.Tensor | None = None,
    ) -> DecoderOutput:
        b, nq = bev.shape[0], self.num_queries
        aux = self.aux_queries if self.training else 0
        q = self.query[None, : nq + aux].expand(b, -1, -1)  # (B, Q + A, C)
        points = torch.sigmoid(self.ref[: nq + aux])[None].expand(b, -1, -1, -1)  # (B, Q+A, P, 2)
        if prop_queries is not None and prop_points is not None:
            k = prop_queries.shape[1]
            if k > nq:
                raise ValueError(f"{k} propagated queries exceed {nq} queries")
            # the propagated queries take slots 0..k-1, the first Q - k learned queries follow
            q = torch.cat([prop_queries, q[:, : nq - k], q[:, nq:]], dim=1)  # (B, Q + A, C)
            points = torch.cat([prop_points, points[:, : nq - k], points[:, nq:]], dim=1)
        mask = None
        if aux:  # two self-attention groups: main and one-to-many queries do not see each other
            group = torch.arange(nq + aux, device=bev.device) >= nq  # (Q + A,)
            mask = group[:, None] != group[None, :]  # (Q + A, Q + A) True: blocked
        logits, all_points = [], []
        for i, layer in enumerate(self.layers):
            pos = self.point_embed(points.flatten(2))  # (B, Q + A, C)
            base = points if i == 0 else points.detach()  # refine from the detached reference
            q, feats = layer(q, pos, bev, base.detach(), mask)  # (B, Q + A, C), (.., P, C)
            points = self.refine(i, q, base, feats)  # (B, Q + A, P, 2)
            logits.append(self.cls_heads[i](q))  # (B, Q + A, K)
            all_points.append(points)
        if not aux:
            return DecoderOutput(logits, all_points, q)
        return DecoderOutput(
            [x[:, :nq] for x in logits],
            [x[:, :nq] for x in all_points],
            q[:, :nq],
            [x[:, nq:] for x in logits],
            [x[:, nq:] for x in all_points],
        )
