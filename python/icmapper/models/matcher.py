"""Hungarian matching of predicted instances to ground truth with point-order-invariant costs.

A ground-truth polyline has 2 equivalent point orders (both directions); a closed crossing has every
cyclic shift in both directions (2 x P orders). The point cost of a (prediction, GT) pair is the
mean L1 distance to the best of those orders; the class cost is the focal cost. The matcher returns
index pairs and the chosen order of each matched GT.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.optimize import linear_sum_assignment
from torch import nn

#: Class ids whose instances are closed contours (ped_crossing).
CLOSED_CLASSES = (0,)


def expand_point_orders(
    points: torch.Tensor, classes: torch.Tensor, closed_classes: tuple[int, ...] = CLOSED_CLASSES
) -> tuple[torch.Tensor, torch.Tensor]:
    """Every equivalent point order of each GT instance.

    points (G, P, 2), classes (G,) -> orders (G, 2P, P, 2), valid (G, 2P) bool. Open instances have
    2 valid orders (forward, reversed); closed ones all 2P (P cyclic shifts x 2 directions).
    """
    g, p, _ = points.shape
    idx = (torch.arange(p)[None, :] + torch.arange(p)[:, None]) % p  # (P shifts, P)
    fwd = points[:, idx]  # (G, P, P, 2) cyclic shifts
    rev = points.flip(1)[:, idx]  # (G, P, P, 2) shifts of the reversed ring
    closed_orders = torch.cat([fwd, rev], dim=1)  # (G, 2P, P, 2)
    open_orders = torch.cat([points[:, None], points.flip(1)[:, None]], dim=1)  # (G, 2, P, 2)
    open_orders = torch.cat([open_orders, open_orders[:, :1].expand(-1, 2 * p - 2, -1, -1)], dim=1)
    is_closed = torch.zeros(g, dtype=torch.bool, device=points.device)
    for c in closed_classes:
        is_closed |= classes == c
    orders = torch.where(is_closed[:, None, None, None], closed_orders, open_orders)
    valid = torch.zeros(g, 2 * p, dtype=torch.bool, device=points.device)
    valid[:, :2] = True
    valid[is_closed] = True
    return orders, valid


def point_cost(
    pred: torch.Tensor, orders: torch.Tensor, valid: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean L1 point distance to the best order.

    pred (Q, P, 2), orders (G, O, P, 2), valid (G, O) -> cost (Q, G), best order index (Q, G).
    """
    q, g, o = pred.shape[0], orders.shape[0], orders.shape[1]
    d = torch.cdist(pred.reshape(q, -1), orders.reshape(g * o, -1), p=1)  # (Q, G*O)
    d = d.reshape(q, g, o) / pred[0].numel()  # (Q, G, O) mean abs difference per coordinate
    d = d.masked_fill(~valid[None], float("inf"))
    cost, best = d.min(dim=-1)  # (Q, G)
    return cost, best


def focal_class_cost(
    logits: torch.Tensor, gt_classes: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0
) -> torch.Tensor:
    """Focal classification cost (Deformable DETR): logits (Q, K), gt_classes (G,) -> (Q, G)."""
    prob = logits.float().sigmoid()  # (Q, K)
    neg = (1 - alpha) * prob**gamma * -(1 - prob + 1e-8).log()  # (Q, K)
    pos = alpha * (1 - prob) ** gamma * -(prob + 1e-8).log()  # (Q, K)
    return (pos - neg)[:, gt_classes]  # (Q, G)


class HungarianMatcher(nn.Module):
    """forward(logits (Q, K), points (Q, P, 2), gt_classes (G,), gt_points (G, P, 2)) ->
    (pred_idx (M,), gt_idx (M,), order (M,)) with M = min(Q, G); points in the same (normalised)
    units; ``order`` indexes ``expand_point_orders``."""

    def __init__(self, cls_weight: float = 2.0, pts_weight: float = 5.0) -> None:
        super().__init__()
        self.cls_weight, self.pts_weight = cls_weight, pts_weight

    def cost_matrix(
        self,
        logits: torch.Tensor,
        points: torch.Tensor,
        gt_classes: torch.Tensor,
        gt_points: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Total cost (Q, G) and best order (Q, G)."""
        orders, valid = expand_point_orders(gt_points.float(), gt_classes)
        pc, best = point_cost(points.float(), orders, valid)  # (Q, G)
        cost = self.cls_weight * focal_class_cost(logits, gt_classes) + self.pts_weight * pc
        return cost, best

    @torch.no_grad()
    def forward(
        self,
        logits: torch.Tensor,
        points: torch.Tensor,
        gt_classes: torch.Tensor,
        gt_points: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        dev = logits.device
        if gt_classes.numel() == 0:
            empty = torch.zeros(0, dtype=torch.int64, device=dev)
            return empty, empty, empty
        cost, best = self.cost_matrix(logits, points, gt_classes, gt_points)
        cost_np = cost.cpu().numpy()  # (Q, G); checked here: one device sync, not two
        if not np.isfinite(cost_np).all():
            raise ValueError("matching cost contains NaN or inf (NaN predictions or targets?)")
        rows, cols = linear_sum_assignment(cost_np)
        pred_idx = torch.as_tensor(rows, dtype=torch.int64, device=dev)
        gt_idx = torch.as_tensor(cols, dtype=torch.int64, device=dev)
        return pred_idx, gt_idx, best[pred_idx, gt_idx]
